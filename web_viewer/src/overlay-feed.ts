// Polls GetOverlays while an overlay that needs it is shown: once per
// received frame, at most one call in flight and one call per MIN_INTERVAL_MS.
// The server builds overlays only while someone asks (at least every 5 s), so
// an answer may be `ready: false`: the next frame brings the next ask.
import { PacedCalls } from './paced-calls';

// What an answer needs for the polling: the generated Overlays, or what the worker made of it.
interface Overlays { ready: boolean; version: bigint }

export { MIN_INTERVAL_MS } from './paced-calls';

export class OverlayFeed<O extends Overlays = Overlays> {
  private readonly paced: PacedCalls;
  private newest = -1n;       // version of the newest overlays handed on

  constructor(fetch: () => Promise<O>,
              ready: (overlays: O) => void,
              failed: (error: unknown) => void,
              now: () => number = () => performance.now()) {
    this.paced = new PacedCalls(() => fetch()
      .then((overlays) => {
        if (overlays.ready && overlays.version >= this.newest) {
          this.newest = overlays.version;
          ready(overlays);
        }
      })
      .catch(failed), now);
    this.paced.enabled = false;
  }

  // On when any server overlay is shown; turning on asks at once.
  setWanted(wanted: boolean): void {
    if (wanted && !this.paced.enabled) this.paced.request();
    this.paced.enabled = wanted;
  }

  frameArrived(): void {
    this.paced.request();
  }
}
