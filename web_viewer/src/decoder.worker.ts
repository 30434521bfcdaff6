// Decodes frame buffers off the main thread, so that rendering and orbiting
// stay smooth while a large frame decodes. Stateless: the keyframe state is
// the page's (KeyedDeltas, main.ts), so the chunks of one frame can go to
// several of these workers at once. Protocol: DecodeRequest in, DecodeReply
// out, matched by id; buffers are transferred, not copied.
import createDecoderModule from 'draco3d/draco_decoder_nodejs.js';
import wasmUrl from 'draco3d/draco_decoder.wasm?url';

import { decodeDeltas, type DracoDecoderModule } from './frame';

// One Draco buffer: Frame.deltas (count = the frame's vertices) or a
// DeltaChunk's (count = its present vertices); `what` names it in errors.
export interface DecodeItem { bytes: Uint8Array; count: number; what: string }
export interface DecodeRequest { id: number; items: DecodeItem[] }
export type DecodeReply =
  | { id: number; values: Float32Array[]; decodeMs: number }
  | { id: number; error: string };

// Loaded once, on the first message's way in; a failure is reported per request.
let draco: Promise<DracoDecoderModule> | undefined;
function loadDraco(): Promise<DracoDecoderModule> {
  draco ??= fetch(wasmUrl)
    .then((response) => {
      if (!response.ok) throw new Error(`cannot load the Draco decoder (${wasmUrl}: HTTP ${response.status})`);
      return response.arrayBuffer();
    })
    .then((wasmBinary) => createDecoderModule({ wasmBinary }) as Promise<DracoDecoderModule>);
  return draco;
}

// Typed through the DOM lib (the project compiles against one lib set);
// postMessage with a transfer list has the same shape in a worker.
self.onmessage = async (event: MessageEvent<DecodeRequest>) => {
  const { id, items } = event.data;
  let reply: DecodeReply;
  try {
    const module = await loadDraco();
    const start = performance.now();
    const values = items.map((item) => decodeDeltas(module, item.bytes, item.count, item.what));
    reply = { id, values, decodeMs: performance.now() - start };
  } catch (error) {
    reply = { id, error: error instanceof Error ? error.message : String(error) };
  }
  self.postMessage(reply, { transfer: 'values' in reply ? reply.values.map((v) => v.buffer) : [] });
};
