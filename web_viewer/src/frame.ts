// Frame.deltas on the wire (proto/filigree/v1/filigree.proto, Frame): for
// every session vertex in order, posed − rest, as a Draco point cloud with
// sequential encoding (decoded point i is vertex i) and one float32×3
// attribute. Pure functions, so the worker and the Node unit tests share them.

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
export function checkDracoHeader(bytes: Uint8Array): void {
  const magic = String.fromCharCode(...bytes.subarray(0, 5));
  if (bytes.length < 9 || magic !== 'DRACO') throw new FrameError('frame deltas are not a Draco buffer');
  if (bytes[7] !== 0) throw new FrameError(`frame deltas are Draco geometry type ${bytes[7]}, not a point cloud`);
  if (bytes[8] !== 0) throw new FrameError(`frame deltas use Draco encoding method ${bytes[8]}, not sequential`);
}

// Decodes Frame.deltas into 3·vertexCount floats (x y z per vertex). An empty
// buffer means every delta is 0.
export function decodeDeltas(draco: DracoDecoderModule, bytes: Uint8Array, vertexCount: number): Float32Array {
  const length = 3 * vertexCount;
  if (bytes.length === 0) return new Float32Array(length);
  checkDracoHeader(bytes);

  const decoder = new draco.Decoder();
  const cloud = new draco.PointCloud();
  let pointer = 0;
  try {
    const data = new Int8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    const status = decoder.DecodeArrayToPointCloud(data, data.byteLength, cloud);
    if (!status.ok()) throw new FrameError(`Draco could not decode the frame: ${status.error_msg()}`);
    if (cloud.num_points() !== vertexCount) {
      throw new FrameError(`the frame has ${cloud.num_points()} points for ${vertexCount} vertices`);
    }
    if (cloud.num_attributes() !== 1) throw new FrameError(`the frame has ${cloud.num_attributes()} attributes, not 1`);
    const attribute = decoder.GetAttribute(cloud, 0);
    if (attribute.num_components() !== 3) {
      throw new FrameError(`the frame attribute has ${attribute.num_components()} components, not 3`);
    }
    // One bulk copy out of the WebAssembly heap: reading value by value
    // (DracoFloat32Array.GetValue) costs a JS→wasm call per coordinate.
    const byteLength = 4 * length;
    pointer = draco._malloc(byteLength);
    if (!decoder.GetAttributeDataArrayForAllPoints(cloud, attribute, draco.DT_FLOAT32, byteLength, pointer)) {
      throw new FrameError('Draco could not read the frame attribute as float32');
    }
    // HEAPF32 is read after the calls: a heap growth replaces the buffer.
    const deltas = draco.HEAPF32.slice(pointer / 4, pointer / 4 + length);
    for (let i = 0; i < length; ++i) {
      if (!Number.isFinite(deltas[i])) throw new FrameError(`the frame has a non-finite delta at vertex ${Math.floor(i / 3)}`);
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
