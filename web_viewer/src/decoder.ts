// The main thread's side of decoder.worker.ts: decode() resolves with the
// deltas of one frame, or rejects with the worker's message.
import type { DecodeReply, DecodeRequest } from './decoder.worker';

export interface Decoded { deltas: Float32Array; decodeMs: number }

export class DeltaDecoder {
  private readonly worker = new Worker(new URL('./decoder.worker.ts', import.meta.url), { type: 'module' });
  private readonly pending = new Map<number, { resolve(d: Decoded): void; reject(e: Error): void }>();
  private nextId = 1;

  constructor() {
    this.worker.onmessage = (event: MessageEvent<DecodeReply>) => {
      const reply = event.data;
      const waiter = this.pending.get(reply.id);
      this.pending.delete(reply.id);
      if (!waiter) return;
      if ('error' in reply) waiter.reject(new Error(reply.error));
      else waiter.resolve({ deltas: reply.deltas, decodeMs: reply.decodeMs });
    };
    // A worker that fails to load (script or module error) fails every request.
    this.worker.onerror = (event) => {
      event.preventDefault();
      const error = new Error(`the frame decoder failed: ${event.message || 'the worker could not start'}`);
      for (const waiter of this.pending.values()) waiter.reject(error);
      this.pending.clear();
    };
  }

  decode(deltas: Uint8Array, vertexCount: number): Promise<Decoded> {
    const id = this.nextId++;
    // A copy: the message's bytes may be a view into a larger buffer that
    // must not be transferred away.
    const bytes = deltas.slice();
    const request: DecodeRequest = { id, bytes, vertexCount };
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject });
      this.worker.postMessage(request, [bytes.buffer]);
    });
  }
}
