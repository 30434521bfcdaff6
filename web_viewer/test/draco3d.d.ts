// draco3d's Node entry point; the modules it resolves with are typed where
// they are used (src/frame.ts for the decoder, test/encode.ts for the encoder).
declare module 'draco3d' {
  const draco3d: {
    createDecoderModule(options?: object): Promise<unknown>;
    createEncoderModule(options?: object): Promise<unknown>;
  };
  export default draco3d;
}
