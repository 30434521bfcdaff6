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

// One DeltaChunk as the server makes it (core/codec/frame_encoder.h).
export interface EncodedChunk { firstVertex: number; vertexCount: number; runs: number[]; deltas: Uint8Array }

// Alternating (skip, take, …) counts of the present vertices of a range;
// empty when all of them are present.
export function runsOf(present: boolean[]): number[] {
  if (present.every((p) => p)) return [];
  const runs: number[] = [];
  let i = 0;
  while (i < present.length) {
    const start = i;
    while (i < present.length && !present[i]) ++i;
    const skip = i - start;
    while (i < present.length && present[i]) ++i;
    if (i - start - skip === 0) break;  // a trailing skip is left out
    runs.push(skip, i - start - skip);
  }
  return runs;
}

// Encodes the chunks of a frame over fixed ranges of `chunkVertices`: for each
// range, the vertices `present` names (all when it is omitted: a keyframe),
// each chunk quantized over its own values; a range with none is left out, and
// a chunk whose present deltas are all 0 has no bytes.
export async function encodeChunks(deltas: Float32Array, chunkVertices: number, bits: number,
  present?: (vertex: number) => boolean): Promise<EncodedChunk[]> {
  const n = deltas.length / 3;
  const chunks: EncodedChunk[] = [];
  for (let first = 0; first < n; first += chunkVertices) {
    const count = Math.min(chunkVertices, n - first);
    const mask = Array.from({ length: count }, (_, i) => present?.(first + i) ?? true);
    if (!mask.includes(true)) continue;
    const values: number[] = [];
    mask.forEach((p, i) => { if (p) values.push(...deltas.subarray(3 * (first + i), 3 * (first + i + 1))); });
    const bytes = values.every((v) => v === 0) ? new Uint8Array(0) : await encodeDeltas(Float32Array.from(values), bits);
    chunks.push({ firstVertex: first, vertexCount: count, runs: runsOf(mask), deltas: bytes });
  }
  return chunks;
}

interface MeshEncoderModule {
  Mesh: new () => object;
  MeshBuilder: new () => {
    AddFacesToMesh(mesh: object, count: number, faces: Uint32Array): boolean;
    AddUInt32Attribute(mesh: object, type: number, count: number, size: number, data: Uint32Array): number;
    AddFloatAttribute(mesh: object, type: number, count: number, size: number, data: Float32Array): number;
  };
  ExpertEncoder: new (mesh: object) => {
    SetEncodingMethod(method: number): void;
    EncodeToDracoBuffer(deduplicate: boolean, out: object): number;
  };
  DracoInt8Array: new () => { GetValue(i: number): number };
  POSITION: number;
  MESH_SEQUENTIAL_ENCODING: number;
  MESH_EDGEBREAKER_ENCODING: number;
  destroy(object: unknown): void;
}

// A level of detail's mesh as the server encodes it (core/codec/level_mesh_codec.cpp):
// a Draco mesh, Edgebreaker (which reorders points and faces), one POSITION
// attribute of 1 UINT32 component, each point's original id.
export async function encodeLevelMesh(ids: Uint32Array, faces: Uint32Array, method: 'edgebreaker' | 'sequential' = 'edgebreaker'):
  Promise<Uint8Array> {
  const M = await (encoder ??= draco3d.createEncoderModule({}) as Promise<EncoderModule>) as unknown as MeshEncoderModule;
  const mesh = new M.Mesh();
  const builder = new M.MeshBuilder();
  const out = new M.DracoInt8Array();
  try {
    builder.AddFacesToMesh(mesh, faces.length / 3, faces);
    builder.AddUInt32Attribute(mesh, M.POSITION, ids.length, 1, ids);
    const expert = new M.ExpertEncoder(mesh);
    try {
      expert.SetEncodingMethod(method === 'edgebreaker' ? M.MESH_EDGEBREAKER_ENCODING : M.MESH_SEQUENTIAL_ENCODING);
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
    M.destroy(mesh);
  }
}
