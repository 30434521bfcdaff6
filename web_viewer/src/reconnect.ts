// When the page follows a session again after its Watch stream broke or
// ended without being asked to (a server restart, a dropped connection, a
// proxy's timeout): retry with exponential backoff, capped, with jitter;
// stop only on answers that another try cannot change.
import { Code, ConnectError } from '@connectrpc/connect';

export const FIRST_DELAY_MS = 250;
// While the server has been gone less than SHORT_OUTAGE_MS, retries stay at
// most SHORT_CAP_MS apart, so that the page follows again within about that
// long of the server's return (a restart takes seconds); after that, up to LONG_CAP_MS.
export const SHORT_CAP_MS = 1000;
export const LONG_CAP_MS = 15_000;
export const SHORT_OUTAGE_MS = 60_000;

// The delay before retry `attempt` (1, 2, …) after `downMs` without a stream:
// FIRST_DELAY_MS·2^(attempt−1) up to the cap, then between half and all of
// it ("equal jitter"), so that many pages do not come back in step.
export function retryDelay(attempt: number, downMs: number, random: () => number = Math.random): number {
  const cap = downMs < SHORT_OUTAGE_MS ? SHORT_CAP_MS : LONG_CAP_MS;
  const exponential = Math.min(cap, FIRST_DELAY_MS * 2 ** Math.min(attempt - 1, 20));
  return exponential / 2 + random() * (exponential / 2);
}

// The answers after which retrying is pointless: the session is gone, or the
// token is refused. Everything else (unavailable, a refused connection, a
// stream cut short, an internal error, a timeout) is worth another try.
export function isFinal(error: unknown): boolean {
  return error instanceof ConnectError &&
    (error.code === Code.NotFound || error.code === Code.PermissionDenied || error.code === Code.Unauthenticated);
}

// Why the stream stopped, for the status line.
export function lossReason(error: unknown): string {
  if (error === null) return 'the stream ended';
  if (error instanceof ConnectError) {
    if (error.code === Code.Unknown && error.cause instanceof TypeError) return 'the server cannot be reached';
    if (error.code === Code.Unavailable) return 'the server is unavailable';
    return `${Code[error.code]}${error.rawMessage ? `: ${error.rawMessage}` : ''}`;
  }
  return error instanceof Error ? error.message : String(error);
}
