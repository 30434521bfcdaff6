// Who is connected: the session's line of ListSessions (one small unary call
// for the whole server, no token), polled every few seconds.
import type { SessionEntry } from './client';

export const PRESENCE_INTERVAL_MS = 3000;

export function presenceText(entry: SessionEntry | undefined): string {
  if (!entry) return 'The session is not loaded on the server.';
  const plural = (n: number, one: string, many: string) => `${n} ${n === 1 ? one : many}`;
  return `${plural(entry.watchers, 'watcher', 'watchers')} (this page included), ` +
    `${plural(entry.drivers, 'driving stream', 'driving streams')}`;
}

// Calls `show` with the text after every answer; errors are shown too, the
// polling goes on (the server may come back).
export function pollPresence(entry: () => Promise<SessionEntry | undefined>, show: (text: string) => void,
                             describe: (error: unknown) => string): void {
  const poll = () => {
    entry().then((e) => show(presenceText(e)), (error) => show(describe(error)))
      .finally(() => window.setTimeout(poll, PRESENCE_INTERVAL_MS));
  };
  poll();
}
