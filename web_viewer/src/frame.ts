// Frame deltas on the wire (proto/filigree/v1/filigree.proto, Frame), in both
// formats. FRAME_FORMAT_SINGLE: Frame.deltas, for every session vertex in
// order, posed − rest, as a Draco point cloud with sequential encoding
// (decoded point i is vertex i) and one float32×3 attribute.
// FRAME_FORMAT_CHUNKED: Frame.chunks, vertex ranges each with its own buffer
// of that kind, holding only the range's present vertices; the others keep
// their delta of keyframe Frame.keyframe_version (KeyedDeltas below).
// Pure functions, so the workers, the page, the unit tests and the Node e2e
// client (tests/node_client) share them. This file imports nothing at run
// time: the e2e client transpiles it alone and imports the result.

// The part of a draco3d decoder module used here. Written out because the
// @types/draco3d typings predate draco3d 1.5 (no DecodeArrayToPointCloud).
export interface DracoDecoderModule {
  Decoder: new () => DracoDecoder;
  PointCloud: new () => DracoPointCloud;
  DT_FLOAT32: number;
  HEAPF32: Float32Array;
  _malloc(bytes: number): number;
  _free(pointer: number): void;
  destroy(object: unknown): void;
}

interface DracoDecoder {
  DecodeArrayToPointCloud(data: Int8Array, byteLength: number, cloud: DracoPointCloud): DracoStatus;
  GetAttribute(cloud: DracoPointCloud, id: number): DracoAttribute;
  GetAttributeDataArrayForAllPoints(cloud: DracoPointCloud, attribute: DracoAttribute, type: number,
    byteLength: number, pointer: number): boolean;
}
interface DracoPointCloud { num_points(): number; num_attributes(): number }
interface DracoAttribute { num_components(): number }
interface DracoStatus { ok(): boolean; error_msg(): string }

// A frame this viewer cannot use; the message says why.
export class FrameError extends Error {
  override name = 'FrameError';
}

// Draco header: "DRACO", major, minor version, geometry type (0: point
// cloud), encoding method (0: sequential). Anything else could reorder points
// (kd-tree) and would silently scramble the mesh, so it is refused.
// `what` names the buffer in messages ("the frame", "chunk 2 (vertices …)").
export function checkDracoHeader(bytes: Uint8Array, what = 'the frame'): void {
  const magic = String.fromCharCode(...bytes.subarray(0, 5));
  if (bytes.length < 9 || magic !== 'DRACO') throw new FrameError(`the deltas of ${what} are not a Draco buffer`);
  if (bytes[7] !== 0) throw new FrameError(`${what} is Draco geometry type ${bytes[7]}, not a point cloud`);
  if (bytes[8] !== 0) throw new FrameError(`${what} uses Draco encoding method ${bytes[8]}, not sequential`);
}

// Decodes Frame.deltas (or a DeltaChunk's) into 3·vertexCount floats (x y z
// per vertex). An empty buffer means every delta is 0.
export function decodeDeltas(draco: DracoDecoderModule, bytes: Uint8Array, vertexCount: number,
  what = 'the frame'): Float32Array {
  const length = 3 * vertexCount;
  if (bytes.length === 0) return new Float32Array(length);
  checkDracoHeader(bytes, what);

  const decoder = new draco.Decoder();
  const cloud = new draco.PointCloud();
  let pointer = 0;
  try {
    const data = new Int8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    const status = decoder.DecodeArrayToPointCloud(data, data.byteLength, cloud);
    if (!status.ok()) throw new FrameError(`Draco could not decode ${what}: ${status.error_msg()}`);
    if (cloud.num_points() !== vertexCount) {
      throw new FrameError(`${what} has ${cloud.num_points()} points for ${vertexCount} vertices`);
    }
    if (cloud.num_attributes() !== 1) throw new FrameError(`${what} has ${cloud.num_attributes()} attributes, not 1`);
    const attribute = decoder.GetAttribute(cloud, 0);
    if (attribute.num_components() !== 3) {
      throw new FrameError(`the attribute of ${what} has ${attribute.num_components()} components, not 3`);
    }
    // One bulk copy out of the WebAssembly heap: reading value by value
    // (DracoFloat32Array.GetValue) costs a JS→wasm call per coordinate.
    const byteLength = 4 * length;
    pointer = draco._malloc(byteLength);
    if (!decoder.GetAttributeDataArrayForAllPoints(cloud, attribute, draco.DT_FLOAT32, byteLength, pointer)) {
      throw new FrameError(`Draco could not read the attribute of ${what} as float32`);
    }
    // HEAPF32 is read after the calls: a heap growth replaces the buffer.
    const deltas = draco.HEAPF32.slice(pointer / 4, pointer / 4 + length);
    for (let i = 0; i < length; ++i) {
      if (!Number.isFinite(deltas[i])) throw new FrameError(`${what} has a non-finite delta at point ${Math.floor(i / 3)}`);
    }
    return deltas;
  } finally {
    if (pointer !== 0) draco._free(pointer);
    draco.destroy(cloud);
    draco.destroy(decoder);
  }
}

// positions = rest + deltas, written into `positions` (the live position
// attribute's array, so the geometry is updated in place, never re-created).
export function applyDeltas(rest: Float32Array, deltas: Float32Array, positions: Float32Array): void {
  if (rest.length !== deltas.length || positions.length !== rest.length) {
    throw new FrameError(`a frame of ${deltas.length / 3} vertices for a mesh of ${rest.length / 3}`);
  }
  for (let i = 0; i < rest.length; ++i) positions[i] = rest[i] + deltas[i];
}

// ---------------------------------------------------------------- chunked frames

// A DeltaChunk as read here (the generated type, or a grpc-js message mapped
// to these names): the range [firstVertex, firstVertex + vertexCount), which
// of its vertices are present, and their deltas.
export interface DeltaChunkData {
  firstVertex: number;
  vertexCount: number;
  runs: ArrayLike<number>;  // skip, take, skip, take, … from firstVertex; empty: every vertex of the range
  deltas: Uint8Array;       // Draco point cloud of the present vertices; empty: every one is 0
}

// What of a Frame chunked decoding reads.
export interface ChunkedFrameData {
  version: bigint;
  keyframeVersion: bigint;  // == version: a keyframe, listing every vertex
  vertexCount: number;
  chunks: readonly DeltaChunkData[];
}

// A vertex range [first, first + count).
export interface VertexRange { first: number; count: number }

// Whether a frame is in FRAME_FORMAT_CHUNKED. A server without that format
// answers a request for it with single frames (no chunks, keyframe 0). The one
// frame both readings fit, no chunks relative to keyframe 0, is the rest mesh
// either way (keyframe 0 is version 0, the rest), so it is read as single.
export function isChunked(frame: { chunks: readonly unknown[]; keyframeVersion: bigint }): boolean {
  return frame.chunks.length > 0 || frame.keyframeVersion !== 0n;
}

export function isKeyframe(frame: { version: bigint; keyframeVersion: bigint }): boolean {
  return frame.version === frame.keyframeVersion;
}

// "chunk 2 (vertices 32768+16384)", for messages.
export function chunkName(index: number, chunk: DeltaChunkData): string {
  return `chunk ${index} (vertices ${chunk.firstVertex}+${chunk.vertexCount})`;
}

// Checks a frame's chunks against a mesh of `vertexCount` vertices: ranges in
// increasing order, disjoint and inside the mesh, runs (an even number of
// counts) within their range. Returns the number of present vertices of each
// chunk: the points its Draco buffer must hold.
export function presentCounts(chunks: readonly DeltaChunkData[], vertexCount: number): number[] {
  const present: number[] = [];
  let next = 0;
  chunks.forEach((chunk, c) => {
    const first = chunk.firstVertex;
    const count = chunk.vertexCount;
    if (first < next) throw new FrameError(`${chunkName(c, chunk)} overlaps or precedes the previous chunk`);
    if (first + count > vertexCount) {
      throw new FrameError(`${chunkName(c, chunk)} reaches past the mesh's ${vertexCount} vertices`);
    }
    next = first + count;
    const runs = chunk.runs;
    if (runs.length === 0) {
      present.push(count);
      return;
    }
    // A trailing skip would say nothing: the C++ client (core KeyedDeltas) refuses it too.
    if (runs.length % 2 !== 0) throw new FrameError(`${chunkName(c, chunk)} has an odd number of runs (${runs.length})`);
    let covered = 0;
    let taken = 0;
    for (let r = 0; r < runs.length; r += 2) {
      covered += runs[r] + runs[r + 1];
      taken += runs[r + 1];
    }
    if (covered > count) throw new FrameError(`${chunkName(c, chunk)} has runs covering ${covered} vertices`);
    present.push(taken);
  });
  return present;
}

// Decodes chunk `index` of a frame: 3 floats per present vertex, in vertex
// order. `present` is its entry of presentCounts: a buffer with another
// number of points is refused.
export function decodeChunk(draco: DracoDecoderModule, chunk: DeltaChunkData, present: number, index: number): Float32Array {
  return decodeDeltas(draco, chunk.deltas, present, chunkName(index, chunk));
}

// The deltas of a chunked stream, updated in place frame by frame: those of
// the latest keyframe and those of the latest frame. A keyframe replaces the
// keyframe; a sparse frame is the keyframe plus its present vertices, so only
// the chunk ranges the previous sparse frame wrote are restored, never all n
// vertices per frame. Before any keyframe it holds keyframe 0, the rest mesh
// (all deltas 0), as the C++ client does (core/codec/keyed_deltas.h).
//
// Decoding is apart (decodeChunk, possibly in workers); check() and apply()
// throw FrameError and change nothing for a frame that cannot be applied.
export class KeyedDeltas {
  readonly vertexCount: number;
  private keyframe: Float32Array;
  private current = new Float32Array(0);  // allocated at the first sparse frame
  private held = 0n;
  private showingKeyframe = true;       // deltas is the keyframe itself
  private currentFromKeyframe = false;  // current equals keyframe outside `dirty`
  private dirty: VertexRange[] = [];    // ranges the last sparse frame wrote into current

  constructor(vertexCount: number) {
    this.vertexCount = vertexCount;
    this.keyframe = new Float32Array(3 * vertexCount);
  }

  // The version of the keyframe held.
  get keyframeVersion(): bigint {
    return this.held;
  }

  // The latest frame's deltas, 3 per vertex. Changed in place by apply().
  get deltas(): Float32Array {
    return this.showingKeyframe ? this.keyframe : this.current;
  }

  // Checks that `frame` can be applied to what is held: its vertex count,
  // chunks and runs, a keyframe listing every vertex (in whole chunks, as
  // core KeyedDeltas requires), a sparse frame relative to the keyframe held.
  // Returns presentCounts(frame.chunks).
  check(frame: ChunkedFrameData): number[] {
    const n = this.vertexCount;
    if (frame.vertexCount !== n) throw new FrameError(`a frame of ${frame.vertexCount} vertices for a mesh of ${n}`);
    const present = presentCounts(frame.chunks, n);
    if (isKeyframe(frame)) {
      // Ranges are in order and disjoint (checked): whole chunks adding up to n cover every vertex.
      let listed = 0;
      let whole = true;
      for (const chunk of frame.chunks) {
        listed += chunk.vertexCount;
        whole &&= chunk.runs.length === 0;
      }
      if (!whole || listed !== n) {
        throw new FrameError(`keyframe ${frame.version} does not list every one of the ${n} vertices in whole chunks`);
      }
    } else if (frame.keyframeVersion !== this.held) {
      // Decoding it against another keyframe would show a wrong mesh without a word.
      throw new FrameError(`the frame is relative to keyframe ${frame.keyframeVersion}, ` +
        `but the keyframe held is ${this.held}`);
    }
    return present;
  }

  // Applies a frame whose chunks were decoded (values[c]: decodeChunk of chunk
  // c). Returns the vertex ranges whose deltas changed, in increasing order and
  // disjoint: the positions to rewrite (applyDeltaRanges).
  apply(frame: ChunkedFrameData, values: readonly Float32Array[]): VertexRange[] {
    const present = this.check(frame);
    const chunks = frame.chunks;
    if (values.length !== chunks.length) {
      throw new FrameError(`${values.length} decoded chunks for a frame of ${chunks.length}`);
    }
    chunks.forEach((chunk, c) => {
      if (values[c].length !== 3 * present[c]) {
        throw new FrameError(`${chunkName(c, chunk)} has ${present[c]} present vertices, ` +
          `and ${values[c].length / 3} were decoded`);
      }
    });
    // Nothing throws past this point.

    if (isKeyframe(frame)) {
      chunks.forEach((chunk, c) => this.keyframe.set(values[c], 3 * chunk.firstVertex));
      this.held = frame.version;
      this.showingKeyframe = true;
      this.currentFromKeyframe = false;
      this.dirty = [];
      return this.vertexCount > 0 ? [{ first: 0, count: this.vertexCount }] : [];
    }

    // current = the keyframe, restoring only what the previous sparse frame wrote.
    let restored: VertexRange[] = [];
    if (!this.currentFromKeyframe) {
      // Once per keyframe. What was shown is the keyframe itself: no change yet.
      if (this.current.length !== this.keyframe.length) this.current = new Float32Array(this.keyframe.length);
      this.current.set(this.keyframe);
      this.currentFromKeyframe = true;
    } else {
      for (const { first, count } of this.dirty) {
        this.current.set(this.keyframe.subarray(3 * first, 3 * (first + count)), 3 * first);
      }
      restored = this.dirty;
    }
    const written: VertexRange[] = [];
    chunks.forEach((chunk, c) => {
      const v = values[c];
      const runs = chunk.runs;
      if (runs.length === 0) {
        this.current.set(v, 3 * chunk.firstVertex);
      } else {
        let at = chunk.firstVertex;
        let from = 0;
        for (let r = 0; r < runs.length; r += 2) {
          at += runs[r];
          const take = 3 * runs[r + 1];
          this.current.set(v.subarray(from, from + take), 3 * at);
          from += take;
          at += runs[r + 1];
        }
      }
      if (chunk.vertexCount > 0) written.push({ first: chunk.firstVertex, count: chunk.vertexCount });
    });
    this.dirty = written;
    this.showingKeyframe = false;
    return unionOfRanges(restored, written);
  }
}

// The union of two lists of ranges, each in increasing order and disjoint.
export function unionOfRanges(a: readonly VertexRange[], b: readonly VertexRange[]): VertexRange[] {
  const out: VertexRange[] = [];
  let i = 0;
  let j = 0;
  while (i < a.length || j < b.length) {
    const next = j >= b.length || (i < a.length && a[i].first <= b[j].first) ? a[i++] : b[j++];
    const last = out[out.length - 1];
    if (last !== undefined && next.first <= last.first + last.count) {
      last.count = Math.max(last.count, next.first + next.count - last.first);
    } else {
      out.push({ first: next.first, count: next.count });
    }
  }
  return out;
}

// Decodes and applies a chunked frame on this thread (the Node clients and
// tests; the page decodes in workers). Returns what KeyedDeltas.apply does.
export function decodeAndApply(draco: DracoDecoderModule, keyed: KeyedDeltas, frame: ChunkedFrameData): VertexRange[] {
  const present = keyed.check(frame);
  return keyed.apply(frame, frame.chunks.map((chunk, c) => decodeChunk(draco, chunk, present[c], c)));
}

// positions = rest + deltas over `ranges` only: after KeyedDeltas.apply, the
// live position array follows the frame without a pass over every vertex.
export function applyDeltaRanges(rest: Float32Array, deltas: Float32Array, positions: Float32Array,
  ranges: readonly VertexRange[]): void {
  if (rest.length !== deltas.length || positions.length !== rest.length) {
    throw new FrameError(`a frame of ${deltas.length / 3} vertices for a mesh of ${rest.length / 3}`);
  }
  for (const { first, count } of ranges) {
    for (let i = 3 * first, end = 3 * (first + count); i < end; ++i) positions[i] = rest[i] + deltas[i];
  }
}

// The largest |delta| coordinate (the page's hook.displacement).
export function largestDelta(deltas: Float32Array): number {
  let max = 0;
  for (let i = 0; i < deltas.length; ++i) {
    const a = Math.abs(deltas[i]);
    if (a > max) max = a;
  }
  return max;
}

// The frames of a SessionState (GetState) in the order to apply them: its
// keyframe first when the current frame is relative to one (chunked format).
export function framesOfState<F>(state: { frame?: F | null; keyframe?: F | null }): F[] {
  return [state.keyframe, state.frame].filter((f): f is F => f !== undefined && f !== null);
}
