// Encodes deltas the way filigree-server does (core/codec/delta_codec.cpp):
// a Draco point cloud, one float32×3 attribute, explicit quantization over
// [min, min + range] on every axis, sequential encoding unless told otherwise.
import draco3d from 'draco3d';

interface EncoderModule {
  PointCloud: new () => object;
  PointCloudBuilder: new () => { AddFloatAttribute(cloud: object, type: number, count: number, size: number, data: Float32Array): number };
  ExpertEncoder: new (cloud: object) => {
    SetAttributeExplicitQuantization(id: number, bits: number, size: number, origin: number[], range: number): number;
    SetEncodingMethod(method: number): void;
    EncodeToDracoBuffer(deduplicate: boolean, out: object): number;
  };
  DracoInt8Array: new () => { GetValue(i: number): number };
  GENERIC: number;
  destroy(object: unknown): void;
}

// Draco's point cloud encoding methods (draco/compression/config/compression_shared.h).
export const SEQUENTIAL = 0;
export const KD_TREE = 1;

let encoder: Promise<EncoderModule> | undefined;

export async function encodeDeltas(deltas: Float32Array, bits: number, method = SEQUENTIAL): Promise<Uint8Array> {
  const M = await (encoder ??= draco3d.createEncoderModule({}) as Promise<EncoderModule>);
  const count = deltas.length / 3;
  let min = Infinity;
  let max = -Infinity;
  for (const v of deltas) { min = Math.min(min, v); max = Math.max(max, v); }
  const range = Math.max(max - min, 1e-9);

  const cloud = new M.PointCloud();
  const builder = new M.PointCloudBuilder();
  const out = new M.DracoInt8Array();
  try {
    const id = builder.AddFloatAttribute(cloud, M.GENERIC, count, 3, deltas);
    const expert = new M.ExpertEncoder(cloud);
    try {
      expert.SetAttributeExplicitQuantization(id, bits, 3, [min, min, min], range);
      expert.SetEncodingMethod(method);
      // No deduplication: it would merge equal points and break point i = vertex i.
      const length = expert.EncodeToDracoBuffer(false, out);
      if (length <= 0) throw new Error('Draco encoding failed');
      const bytes = new Uint8Array(length);
      for (let i = 0; i < length; ++i) bytes[i] = out.GetValue(i) & 0xff;
      return bytes;
    } finally {
      M.destroy(expert);
    }
  } finally {
    M.destroy(out);
    M.destroy(builder);
    M.destroy(cloud);
  }
}

// The largest error quantization to `bits` over the deltas' own range allows
// (half a step), plus float32 rounding.
export function quantizationBound(deltas: Float32Array, bits: number): number {
  let min = Infinity;
  let max = -Infinity;
  for (const v of deltas) { min = Math.min(min, v); max = Math.max(max, v); }
  return (max - min) / (2 ** bits - 1) / 2 + 1e-6 * Math.max(Math.abs(min), Math.abs(max), 1);
}
