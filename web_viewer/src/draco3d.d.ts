// draco3d's Emscripten decoder factory, imported by path so that the encoder
// (which this viewer never uses) stays out of the bundle. It runs in browsers,
// workers and Node alike; `wasmBinary` spares it from fetching the .wasm.
// What it resolves with is typed where it is used (frame.ts, DracoDecoderModule).
declare module 'draco3d/draco_decoder_nodejs.js' {
  const createDecoderModule: (options: { wasmBinary?: ArrayBuffer }) => Promise<unknown>;
  export default createDecoderModule;
}
