// Levels of detail (WatchRequest.max_vertices, Frame.level): a stream that
// asks for a budget gets the mesh of a cut through the hierarchy with at most
// that many vertices, every one a vertex of the full mesh. Its first message
// (and the first after each SetDetail) is a Frame with only `level` set
// (DetailLevel: vertex and face counts, the level's mesh, the stream's id);
// the frames after it are the level's: vertex ids in their chunks index the
// level's vertices (0..k−1), Frame.level_vertices is k, and the keyframe
// rules are those of full frames, from a fresh keyframe state. At full detail
// DetailLevel.mesh is empty and the frames are ordinary full frames.
//
// DetailLevel.mesh is a Draco mesh (Edgebreaker) whose one attribute
// (POSITION, 1 component, UINT32) is each point's original id. Draco orders
// points and faces as it likes and may split a vertex into several points
// with the same id: the level's vertices are the distinct ids in ascending
// order (the order of its frames' deltas), and each face's corners are the
// vertices of its points' ids, in the decoded corner order (orientation
// kept). The level's rest positions are the rest mesh's at those ids.
//
// Pure functions for the session worker and the page (and the unit tests).
import { FrameError } from './frame';

// The part of a draco3d decoder module that decodes meshes (frame.ts has the
// point-cloud part).
export interface DracoMeshModule {
  Decoder: new () => DracoMeshDecoder;
  Mesh: new () => DracoMesh;
  DT_UINT32: number;
  POSITION: number;
  HEAPU32: Uint32Array;
  _malloc(bytes: number): number;
  _free(pointer: number): void;
  destroy(object: unknown): void;
}

interface DracoMeshDecoder {
  DecodeArrayToMesh(data: Int8Array, byteLength: number, mesh: DracoMesh): { ok(): boolean; error_msg(): string };
  GetAttributeId(mesh: DracoMesh, type: number): number;
  GetAttribute(mesh: DracoMesh, id: number): { num_components(): number; data_type(): number };
  GetAttributeDataArrayForAllPoints(mesh: DracoMesh, attribute: unknown, type: number, byteLength: number,
    pointer: number): boolean;
  GetTrianglesUInt32Array(mesh: DracoMesh, byteLength: number, pointer: number): boolean;
}
interface DracoMesh { num_points(): number; num_faces(): number; num_attributes(): number }

// A level as decoded: each vertex's original id (ascending) and the faces
// (3 per triangle) over the level's vertices.
export interface LevelMesh { ids: Uint32Array; faces: Uint32Array }

// Decodes DetailLevel.mesh of a level announced with `vertexCount` vertices
// and `faceCount` faces, on a mesh of `fullVertexCount` vertices. Throws
// FrameError for anything else: not a Draco mesh, no UINT32 id attribute, an
// id past the mesh, other counts than announced.
export function decodeLevelMesh(draco: DracoMeshModule, bytes: Uint8Array, vertexCount: number, faceCount: number,
  fullVertexCount: number): LevelMesh {
  const magic = String.fromCharCode(...bytes.subarray(0, 5));
  if (bytes.length < 9 || magic !== 'DRACO') throw new FrameError('the level\'s mesh is not a Draco buffer');
  // Header: "DRACO", major, minor version, geometry type (1: triangular mesh), encoding method.
  if (bytes[7] !== 1) throw new FrameError(`the level's mesh is Draco geometry type ${bytes[7]}, not a mesh`);
  const decoder = new draco.Decoder();
  const mesh = new draco.Mesh();
  let pointer = 0;
  try {
    const data = new Int8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    const status = decoder.DecodeArrayToMesh(data, data.byteLength, mesh);
    if (!status.ok()) throw new FrameError(`Draco could not decode the level's mesh: ${status.error_msg()}`);
    const points = mesh.num_points();
    const f = mesh.num_faces();
    if (f !== faceCount) throw new FrameError(`the level's mesh has ${f} faces, announced ${faceCount}`);
    const id = decoder.GetAttributeId(mesh, draco.POSITION);
    if (id < 0) throw new FrameError('the level\'s mesh has no attribute of original ids');
    const attribute = decoder.GetAttribute(mesh, id);
    if (attribute.num_components() !== 1 || attribute.data_type() !== draco.DT_UINT32) {
      throw new FrameError(`the level's id attribute has ${attribute.num_components()} components of Draco type ` +
        `${attribute.data_type()}, not 1 UINT32`);
    }
    // One buffer for both reads: the points' ids, then the faces (3f point indices).
    const bytesNeeded = 4 * Math.max(points, 3 * f, 1);
    pointer = draco._malloc(bytesNeeded);
    if (!decoder.GetAttributeDataArrayForAllPoints(mesh, attribute, draco.DT_UINT32, 4 * points, pointer)) {
      throw new FrameError('Draco could not read the level\'s ids as UINT32');
    }
    // HEAPU32 is read after the calls: a heap growth replaces the buffer.
    const idOfPoint = draco.HEAPU32.slice(pointer / 4, pointer / 4 + points);
    if (!decoder.GetTrianglesUInt32Array(mesh, 12 * f, pointer)) throw new FrameError('Draco could not read the level\'s faces');
    const corners = draco.HEAPU32.slice(pointer / 4, pointer / 4 + 3 * f);
    const level = levelOfPoints(idOfPoint, corners, fullVertexCount);
    if (level.ids.length !== vertexCount) {
      throw new FrameError(`the level's mesh has ${level.ids.length} vertices, announced ${vertexCount}`);
    }
    return level;
  } finally {
    if (pointer !== 0) draco._free(pointer);
    draco.destroy(mesh);
    draco.destroy(decoder);
  }
}

// The level from Draco's points: its vertices are the distinct ids of
// `idOfPoint`, ascending; `corners` (point indices, 3 a face) become those
// vertices' indices. Throws FrameError for an id at or past
// `fullVertexCount` or a corner past the points.
export function levelOfPoints(idOfPoint: Uint32Array, corners: Uint32Array, fullVertexCount: number): LevelMesh {
  for (let p = 0; p < idOfPoint.length; ++p) {
    if (idOfPoint[p] >= fullVertexCount) {
      throw new FrameError(`a vertex of the level has original id ${idOfPoint[p]}, past the mesh's ${fullVertexCount} vertices`);
    }
  }
  const sorted = idOfPoint.slice().sort();
  let k = 0;
  for (let i = 0; i < sorted.length; ++i) if (i === 0 || sorted[i] !== sorted[i - 1]) sorted[k++] = sorted[i];
  const ids = sorted.slice(0, k);
  const vertexOf = new Uint32Array(idOfPoint.length);
  for (let p = 0; p < idOfPoint.length; ++p) vertexOf[p] = levelIndexOf(ids, idOfPoint[p]);
  const faces = new Uint32Array(corners.length);
  for (let c = 0; c < corners.length; ++c) {
    if (corners[c] >= idOfPoint.length) {
      throw new FrameError(`the level's face ${Math.floor(c / 3)} names point ${corners[c]} of ${idOfPoint.length}`);
    }
    faces[c] = vertexOf[corners[c]];
  }
  return { ids, faces };
}

// out[3i..3i+2] = values[3·ids[i]..]: the full mesh's positions (or any 3
// floats per vertex) at the level's vertices.
export function gather3(values: Float32Array, ids: Uint32Array, out = new Float32Array(3 * ids.length)): Float32Array {
  for (let i = 0; i < ids.length; ++i) {
    const o = 3 * ids[i];
    out[3 * i] = values[o];
    out[3 * i + 1] = values[o + 1];
    out[3 * i + 2] = values[o + 2];
  }
  return out;
}

// out[i] = values[ids[i]]: one value per vertex.
export function gather1<T extends Uint32Array | Int32Array | Uint8Array | Float32Array>(values: ArrayLike<number>,
  ids: Uint32Array, out: T): T {
  for (let i = 0; i < ids.length; ++i) out[i] = values[ids[i]];
  return out;
}

// The level index of original vertex `id` (ids ascending), −1 when the level
// does not hold it. null ids: the full mesh, where the index is the id.
export function levelIndexOf(ids: Uint32Array | null, id: number, fullVertexCount = Infinity): number {
  if (ids === null) return id >= 0 && id < fullVertexCount ? id : -1;
  let lo = 0;
  let hi = ids.length - 1;
  while (lo <= hi) {
    const mid = (lo + hi) >>> 1;
    const v = ids[mid];
    if (v === id) return mid;
    if (v < id) lo = mid + 1;
    else hi = mid - 1;
  }
  return -1;
}

// The level indices of original vertices `originals` (−1 where the level
// lacks one), e.g. the base mesh's vertices for its wireframe.
export function levelIndices(ids: Uint32Array | null, originals: Uint32Array): Int32Array {
  const out = new Int32Array(originals.length);
  for (let i = 0; i < originals.length; ++i) out[i] = levelIndexOf(ids, originals[i]);
  return out;
}

// Triangles over original ids (a cut mesh, GetOverlays.cut_faces) as
// triangles over the level's vertices; those with a corner the level lacks are
// left out.
export function facesOnLevel(ids: Uint32Array, faces: ArrayLike<number>): Uint32Array {
  const out: number[] = [];
  for (let f = 0; f + 2 < faces.length; f += 3) {
    const a = levelIndexOf(ids, faces[f]);
    const b = levelIndexOf(ids, faces[f + 1]);
    const c = levelIndexOf(ids, faces[f + 2]);
    if (a >= 0 && b >= 0 && c >= 0) out.push(a, b, c);
  }
  return Uint32Array.from(out);
}

// The vertex count of the level a budget gets, as the server picks it
// (WatchRequest.max_vertices): budgets round down to a power of two, below
// the base's count they get the base, at or above the mesh's the full mesh.
export function levelVerticesFor(budget: number, baseVertices: number, fullVertices: number): number {
  if (budget >= fullVertices) return fullVertices;
  const power = 2 ** Math.floor(Math.log2(Math.max(1, budget)));
  return Math.min(fullVertices, Math.max(baseVertices, power));
}
