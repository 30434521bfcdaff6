// The main thread's side of decoder.worker.ts: a few workers decoding the
// Draco buffers of a frame, the chunks of one frame in parallel. decode() and
// decodeChunks() resolve with the decoded values, or reject with a FrameError
// carrying the worker's message.
import { chunkName, FrameError, type DeltaChunkData } from './frame';
import type { DecodeItem, DecodeReply, DecodeRequest } from './decoder.worker';

export interface Decoded { deltas: Float32Array; decodeMs: number }
// values[c]: the present vertices' deltas of chunk c; decodeMs: the longest
// any worker took for its share.
export interface DecodedChunks { values: Float32Array[]; decodeMs: number }

// One core is left to the page (rendering, applying frames); more than a few
// workers gain little on chunks of 16384 vertices and cost a Draco module each.
const MAX_WORKERS = 4;

// Spreads weighted items over `bins`: heaviest first, each to the bin with the
// least weight so far. Returns the item indices of each non-empty bin.
export function balance(weights: readonly number[], bins: number): number[][] {
  const order = weights.map((_, i) => i).sort((a, b) => weights[b] - weights[a]);
  const load = new Array<number>(Math.max(1, Math.min(bins, weights.length))).fill(0);
  const out: number[][] = load.map(() => []);
  for (const i of order) {
    const bin = load.indexOf(Math.min(...load));
    out[bin].push(i);
    load[bin] += weights[i];
  }
  return out.filter((items) => items.length > 0);
}

class DecodeWorker {
  private readonly worker = new Worker(new URL('./decoder.worker.ts', import.meta.url), { type: 'module' });
  private readonly pending = new Map<number, { resolve(r: DecodedChunks): void; reject(e: Error): void }>();
  private nextId = 1;

  constructor() {
    this.worker.onmessage = (event: MessageEvent<DecodeReply>) => {
      const reply = event.data;
      const waiter = this.pending.get(reply.id);
      this.pending.delete(reply.id);
      if (!waiter) return;
      if ('error' in reply) waiter.reject(new FrameError(reply.error));
      else waiter.resolve({ values: reply.values, decodeMs: reply.decodeMs });
    };
    // A worker that fails to load (script or module error) fails every request.
    this.worker.onerror = (event) => {
      event.preventDefault();
      const error = new Error(`the frame decoder failed: ${event.message || 'the worker could not start'}`);
      for (const waiter of this.pending.values()) waiter.reject(error);
      this.pending.clear();
    };
  }

  run(items: DecodeItem[]): Promise<DecodedChunks> {
    const id = this.nextId++;
    const request: DecodeRequest = { id, items };
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject });
      this.worker.postMessage(request, items.map((item) => item.bytes.buffer));
    });
  }
}

export class DeltaDecoder {
  private readonly workers: DecodeWorker[] = [];
  private readonly size = Math.max(1, Math.min(MAX_WORKERS, (navigator.hardwareConcurrency || 2) - 1));

  constructor() {
    this.worker(0);  // the first one loads Draco before the first frame arrives
  }

  // Workers start when first needed: a page that only ever gets one chunk per frame runs one.
  private worker(i: number): DecodeWorker {
    while (this.workers.length <= i) this.workers.push(new DecodeWorker());
    return this.workers[i];
  }

  // Frame.deltas of a single-format frame.
  async decode(deltas: Uint8Array, vertexCount: number): Promise<Decoded> {
    // A copy: the message's bytes may be a view into a larger buffer that
    // must not be transferred away.
    const item = { bytes: deltas.slice(), count: vertexCount, what: 'the frame' };
    const { values, decodeMs } = await this.worker(0).run([item]);
    return { deltas: values[0], decodeMs };
  }

  // The chunks of a chunked frame; present[c]: chunk c's present vertices
  // (KeyedDeltas.check). Chunks without bytes (every delta 0) are not sent.
  async decodeChunks(chunks: readonly DeltaChunkData[], present: readonly number[]): Promise<DecodedChunks> {
    const values: (Float32Array | null)[] =
      chunks.map((chunk, c) => (chunk.deltas.length === 0 ? new Float32Array(3 * present[c]) : null));
    const encoded = chunks.flatMap((chunk, c) => (chunk.deltas.length === 0 ? [] : [c]));
    const shares = balance(encoded.map((c) => chunks[c].deltas.length), this.size);
    const results = await Promise.all(shares.map((share, w) => this.worker(w).run(share.map((k) => {
      const c = encoded[k];
      return { bytes: chunks[c].deltas.slice(), count: present[c], what: chunkName(c, chunks[c]) };
    }))));
    let decodeMs = 0;
    shares.forEach((share, w) => {
      share.forEach((k, j) => { values[encoded[k]] = results[w].values[j]; });
      decodeMs = Math.max(decodeMs, results[w].decodeMs);
    });
    return { values: values as Float32Array[], decodeMs };
  }
}
