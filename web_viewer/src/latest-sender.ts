// One call in flight, the newest value wins: values pushed while a call runs
// replace each other, and the last one is sent when the call ends. Dragging a
// handle pushes a value per pointer move; the server sees as many as it can take.
export class LatestSender<T> {
  private pending: { value: T } | null = null;
  private busy = false;

  // `send` reports its own errors; a rejection only ends that call.
  constructor(private readonly send: (value: T) => Promise<void>) {}

  push(value: T): void {
    this.pending = { value };
    if (!this.busy) void this.drain();
  }

  get idle(): boolean {
    return !this.busy && this.pending === null;
  }

  private async drain(): Promise<void> {
    this.busy = true;
    while (this.pending !== null) {
      const { value } = this.pending;
      this.pending = null;
      try {
        await this.send(value);
      } catch {
        // reported by `send`
      }
    }
    this.busy = false;
  }
}
