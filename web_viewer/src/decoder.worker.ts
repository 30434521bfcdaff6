// Decodes frames off the main thread, so that rendering and orbiting stay
// smooth while a large frame decodes. Protocol: DecodeRequest in,
// DecodeReply out, matched by id; buffers are transferred, not copied.
import createDecoderModule from 'draco3d/draco_decoder_nodejs.js';
import wasmUrl from 'draco3d/draco_decoder.wasm?url';

import { decodeDeltas, type DracoDecoderModule } from './frame';

export interface DecodeRequest { id: number; bytes: Uint8Array; vertexCount: number }
export type DecodeReply =
  | { id: number; deltas: Float32Array; decodeMs: number }
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
  const { id, bytes, vertexCount } = event.data;
  let reply: DecodeReply;
  try {
    const module = await loadDraco();
    const start = performance.now();
    const deltas = decodeDeltas(module, bytes, vertexCount);
    reply = { id, deltas, decodeMs: performance.now() - start };
  } catch (error) {
    reply = { id, error: error instanceof Error ? error.message : String(error) };
  }
  self.postMessage(reply, { transfer: 'deltas' in reply ? [reply.deltas.buffer] : [] });
};
