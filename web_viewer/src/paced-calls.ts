// One unary call kept current without flooding the server: request() marks
// a call due; calls run one at a time, at most one per `interval` ms, and
// requests that come while one runs (or waits its turn) make one more call
// after it, not one each. Off (enabled = false), nothing is called; turning
// it on again calls if one is due.
export const MIN_INTERVAL_MS = 250;

export class PacedCalls {
  private on = true;
  private due = false;  // requested since the last call started
  private busy = false;
  private lastCall = -Infinity;
  private timer: ReturnType<typeof setTimeout> | undefined;

  // `call` must not reject (it handles its own errors).
  constructor(private readonly call: () => Promise<void>,
              private readonly now: () => number = () => performance.now(),
              private readonly interval = MIN_INTERVAL_MS) {}

  request(): void {
    this.due = true;
    this.kick();
  }

  get enabled(): boolean {
    return this.on;
  }

  set enabled(on: boolean) {
    this.on = on;
    this.kick();
  }

  // No call running and none due.
  get idle(): boolean {
    return !this.busy && !this.due;
  }

  private kick(): void {
    if (!this.on || !this.due || this.busy || this.timer !== undefined) return;
    const wait = this.lastCall + this.interval - this.now();
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
    this.call().finally(() => {
      this.busy = false;
      this.kick();
    });
  }
}
