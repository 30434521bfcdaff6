// Polls GetOverlays while an overlay that needs it is shown: once per
// received frame, at most one call in flight and one call per MIN_INTERVAL_MS.
// The server builds overlays only while someone asks (at least every 5 s), so
// an answer may be `ready: false`: the next frame brings the next ask.
// What an answer needs for the polling: the generated Overlays, or what the worker made of it.
interface Overlays { ready: boolean; version: bigint }

export const MIN_INTERVAL_MS = 250;

export class OverlayFeed<O extends Overlays = Overlays> {
  private wanted = false;
  private due = false;        // a frame arrived since the last call started
  private busy = false;
  private lastCall = -Infinity;
  private timer: ReturnType<typeof setTimeout> | undefined;
  private newest = -1n;       // version of the newest overlays handed on

  constructor(private readonly fetch: () => Promise<O>,
              private readonly ready: (overlays: O) => void,
              private readonly failed: (error: unknown) => void,
              private readonly now: () => number = () => performance.now()) {}

  // On when any server overlay is shown; turning on asks at once.
  setWanted(wanted: boolean): void {
    if (wanted && !this.wanted) this.due = true;
    this.wanted = wanted;
    this.kick();
  }

  frameArrived(): void {
    this.due = true;
    this.kick();
  }

  private kick(): void {
    if (!this.wanted || !this.due || this.busy || this.timer !== undefined) return;
    const wait = this.lastCall + MIN_INTERVAL_MS - this.now();
    if (wait > 0) {
      this.timer = setTimeout(() => {
        this.timer = undefined;
        this.kick();
      }, wait);
      return;
    }
    this.due = false;
    this.busy = true;
    this.lastCall = this.now();
    this.fetch()
      .then((overlays) => {
        if (overlays.ready && overlays.version >= this.newest) {
          this.newest = overlays.version;
          this.ready(overlays);
        }
      })
      .catch(this.failed)
      .finally(() => {
        this.busy = false;
        this.kick();
      });
  }
}
