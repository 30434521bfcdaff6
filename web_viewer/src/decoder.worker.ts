// The session worker: everything heavy the page does with a session, off the
// main thread (DESIGN §3.6). It joins the session (so the main thread never
// parses the mesh: tens of MB on a 1M-vertex session), builds the first
// normals and the framing, and then, frame by frame, decodes the Draco
// buffers, applies them to the keyframe state (KeyedDeltas) and the rest
// mesh, computes vertex normals and, while that overlay is on, the stretch
// colours. Finished buffers go to the page by transfer, two sets taking turns
// (pipeline-protocol.ts, Buffers); the page only uploads and draws them.
//
// Every frame is applied as it comes (a frame that arrives while another is
// being applied supersedes the one waiting: FrameMailbox), whatever the page
// is doing; the page gets the newest applied state whenever it has a buffer
// set free, so a page slowed down by drawing skips frames it cannot draw but
// the worker does not fall behind the stream.
//
// A stream at a level of detail (levels.ts) announces its level before the
// level's frames: the worker decodes the level's mesh, gathers its rest
// positions and applies the level's frames to them; once the level's first
// frame is applied it hands the page the whole new geometry at once (a
// 'level' message: positions, normals, faces, stand-in, original ids), so the
// page swaps it in within one short task and never shows the level at rest.
import createDecoderModule from 'draco3d/draco_decoder_nodejs.js';
import wasmUrl from 'draco3d/draco_decoder.wasm?url';

import { ConnectError } from '@connectrpc/connect';

import { SessionClient, type DetailLevel, type Frame } from './client';
import { frameBytes } from './stats';
import {
  applyDeltaRanges, applyDeltas, decodeChunk, decodeDeltas, FrameError, isChunked, isKeyframe, KeyedDeltas, largestDelta,
  type ChunkedFrameData, type DracoDecoderModule,
} from './frame';
import { coarseIndex, frameMesh, vertexNormals } from './geometry';
import { colourRegions, cutForDrawing, edgeSet, regionBoundaryEdges, regionVertexColours } from './overlay-build';
import { decodeLevelMesh, facesOnLevel, gather1, gather3, levelIndices, type DracoMeshModule } from './levels';
import { FrameMailbox } from './mailbox';
import { RestAssembler } from './rest-parts';
import type { Buffers, CallError, FromWorker, HistoryLines, ToWorker } from './pipeline-protocol';
import { STRETCH_RED, stretchColor, TriangleStretch } from './stretch';

// Loaded at once: the first frame should not wait for it.
const draco: Promise<DracoDecoderModule> = fetch(wasmUrl)
  .then((response) => {
    if (!response.ok) throw new Error(`cannot load the Draco decoder (${wasmUrl}: HTTP ${response.status})`);
    return response.arrayBuffer();
  })
  .then((wasmBinary) => createDecoderModule({ wasmBinary }) as Promise<DracoDecoderModule>);
// A load failure is reported with the first frame, not as an unhandled rejection.
draco.catch(() => {});

const post = (message: FromWorker, transfer: Transferable[] = []) => self.postMessage(message, { transfer });

// A mesh the frames can be at: the full mesh, or a level of detail (its
// vertices' original ids, ascending; rest positions gathered from the full
// mesh's).
interface Level {
  vertexCount: number;
  ids: Uint32Array | null;       // null: the full mesh
  rest: Float32Array;
  faces: Uint32Array;
  bytes: Uint8Array | null;      // DetailLevel.mesh, to know the same level again
  coarse?: Uint32Array | null;   // the stand-in (geometry.ts), once computed
  edges?: Set<number>;           // for the cut overlay, once computed
}
const emptyLevel = (): Level => ({ vertexCount: 0, ids: null, rest: new Float32Array(0), faces: new Uint32Array(0), bytes: null });
let full = emptyLevel();
let level = full;   // the one the frames are at (the last DetailLevel read)
let shown = full;   // the one the page draws
let baseIds = new Uint32Array(0);  // the base mesh's original ids
// The session's mesh as the frames are at it (level's arrays), and the deformation state.
let rest: Float32Array = new Float32Array(0);
let faces: Uint32Array = new Uint32Array(0);
let keyed = new KeyedDeltas(0);
// rest + the latest deltas: what the next buffers start from.
let positions = new Float32Array(0);
// False after a single-format frame: the next chunked one rewrites every vertex.
let positionsFollowKeyed = true;
const spare: Buffers[] = [];     // buffer sets handed back by the page
let stretchOn = false;
let stretch: TriangleStretch | null = null;
let stretchValues = new Float32Array(0);
let vertexStretch = new Float32Array(0);
let stretchMax = 0;
let client: SessionClient | null = null;

// ------------------------------------------------------------------ join

// A fetch that reports how many bytes of the answer have arrived.
function countingFetch(report: (loaded: number, total: number | null) => void): typeof fetch {
  // Typed loosely: @types/node and the DOM declare fetch twice, with Request types that do not match.
  return (async (input: string, init?: RequestInit) => {
    const response = await fetch(input, init);
    if (!response.body) return response;
    const length = Number(response.headers.get('content-length'));
    const total = Number.isFinite(length) && length > 0 ? length : null;
    let loaded = 0;
    let lastReport = 0;
    const counted = response.body.pipeThrough(new TransformStream<Uint8Array, Uint8Array>({
      transform(chunk, controller) {
        loaded += chunk.byteLength;
        const now = performance.now();
        if (now - lastReport > 100) {
          lastReport = now;
          report(loaded, total);
        }
        controller.enqueue(chunk);
      },
    }));
    return new Response(counted, { status: response.status, statusText: response.statusText, headers: response.headers });
  }) as unknown as typeof fetch;
}

function callError(error: unknown): CallError {
  if (error instanceof ConnectError) {
    return { code: error.code, rawMessage: error.rawMessage, message: error.message, fetchFailed: error.cause instanceof TypeError };
  }
  return { code: null, rawMessage: '', message: error instanceof Error ? error.message : String(error), fetchFailed: false };
}

// The rest mesh of a session whose SessionInfo left it out (rest.inParts),
// read from GetRestMesh part by part, the progress posted as values received
// of values in all. Parts that do not add up to the announced counts fail
// (RestPartsError), the stream too (a ConnectError).
async function restInParts(source: SessionClient, vertexCount: number, faceCount: number): Promise<RestAssembler> {
  const assembler = new RestAssembler(vertexCount, faceCount);
  post({ type: 'progress', stage: 'receive', loaded: 0, total: assembler.total });
  for await (const part of source.restMesh()) {
    assembler.push(part);  // a throw here ends the loop, which cancels the call
    post({ type: 'progress', stage: 'receive', loaded: assembler.received, total: assembler.total });
  }
  assembler.finish();
  return assembler;
}

async function join(serverUrl: string, sessionId: string, token: string): Promise<void> {
  const started = performance.now();
  const joining = new SessionClient(serverUrl, sessionId, token,
    countingFetch((loaded, total) => post({ type: 'progress', stage: 'download', loaded, total })));
  client = new SessionClient(serverUrl, sessionId, token);
  let info;
  try {
    info = await joining.join();
  } catch (error) {
    post({ type: 'joinFailed', error: callError(error) });
    return;
  }
  const restMesh = info.rest!;
  let restParts = 0;
  if (restMesh.inParts) {
    // Too large for one message: the arrays come from GetRestMesh.
    try {
      const assembled = await restInParts(client, restMesh.vertexCount, restMesh.faceCount);
      rest = assembled.positions;
      faces = assembled.faces;
      restParts = assembled.parts;
    } catch (error) {
      post({ type: 'joinFailed', error: callError(error) });
      return;
    }
  } else {
    rest = Float32Array.from(restMesh.positions);
    faces = Uint32Array.from(restMesh.faces);
  }
  const joined = performance.now();
  post({ type: 'progress', stage: 'build', loaded: 0, total: null });
  const n = rest.length / 3;
  restMesh.positions = [];
  restMesh.faces = [];
  restMesh.uploadedIds = [];
  keyed = new KeyedDeltas(n);
  positions = rest.slice();
  const normals = new Float32Array(3 * n);
  vertexNormals(rest, faces, normals);
  const framing = frameMesh(rest, normals);
  // The second set, for the first frame.
  spare.push({ positions: new Float32Array(3 * n), normals: new Float32Array(3 * n), colors: null });
  const base = info.base!;
  const basePositions = Float32Array.from(base.positions);
  const baseFaces = Uint32Array.from(base.faces);
  const originalIds = Uint32Array.from(base.originalIds);
  base.positions = [];
  base.faces = [];
  base.originalIds = [];
  const facesForPage = faces.slice();
  const coarseFaces = coarseIndex(rest, faces);
  full = { vertexCount: n, ids: null, rest, faces, bytes: null, coarse: coarseFaces };
  level = shown = full;
  baseIds = originalIds.slice();
  post({
    type: 'joined', info, faces: facesForPage, coarseFaces, buffers: { positions: rest.slice(), normals, colors: null }, framing,
    basePositions, baseFaces, originalIds, restParts, joinMs: joined - started, buildMs: performance.now() - joined,
  }, [facesForPage.buffer, normals.buffer, basePositions.buffer, baseFaces.buffer, originalIds.buffer,
    ...(coarseFaces ? [coarseFaces.buffer] : [])]);
}

// ------------------------------------------------------------------ frames

function takeBuffers(): Buffers | null {
  const set = spare.pop();
  if (!set) return null;
  const n3 = rest.length;
  if (stretchOn && (set.colors === null || set.colors.length !== n3)) set.colors = new Float32Array(n3);
  if (!stretchOn) set.colors = null;
  return set;
}

// A message off the Watch stream, read here: a frame in the chunked or the
// single format, or the start of a level of detail.
interface FrameIn {
  stream: number;
  chunked?: ChunkedFrameData & { levelVertices: number; maxError: number };
  single?: { version: bigint; vertexCount: number; deltas: Uint8Array; levelVertices: number; maxError: number };
  level?: DetailLevel;
}
const isKeyframeIn = (m: FrameIn) => m.chunked !== undefined && isKeyframe(m.chunked);
// The frames not applied yet, in order. Frames come in bursts (the page's
// thread reads the stream between its own tasks), and each is applied while
// the worker keeps up; once more than MAX_WAITING wait (it is behind), only
// the newest and the keyframe it needs are kept (a sparse frame is whole
// against its keyframe, so the ones between can go: FrameMailbox).
const MAX_WAITING = 8;
let waiting: FrameIn[] = [];
let working = false;
// The latest applied frame, not yet handed to the page (it had no buffer set free).
let pending: {
  version: bigint; kind: 'single' | 'keyframe' | 'sparse'; decodeMs: number; applyMs: number; displacement: number;
  maxError: number;
} | null = null;

function put(message: FrameIn): void {
  waiting.push(message);
  if (waiting.length > MAX_WAITING) {
    // The newest level message waiting starts over (frames before it are of
    // the state it resets); of the frames after it, the newest and its keyframe.
    let start = waiting.length - 1;
    while (start >= 0 && !waiting[start].level) --start;
    let superseded = Math.max(0, start);
    const box = new FrameMailbox<FrameIn>(isKeyframeIn);
    for (const m of waiting.slice(start + 1)) superseded += box.put(m);
    waiting = [...(start >= 0 ? [waiting[start]] : []), box.take(), box.take()].filter((m): m is FrameIn => m !== null);
    post({ type: 'applied', version: -1n, decodeMs: 0, applyMs: 0, maxError: 0, skipped: superseded });
  }
  if (!working) void work();
}

// Applies the frames as they come, yielding between them so that newer ones
// can supersede the one waiting.
async function work(): Promise<void> {
  working = true;
  for (let next = waiting.shift(); next !== undefined; next = waiting.shift()) {
    if (next.level) await applyLevel(next.stream, next.level);
    else await applyFrame(next);
    await new Promise((resolve) => setTimeout(resolve, 0));
  }
  working = false;
}

// Whether DetailLevel `d` is level `l` (the same vertex count and mesh).
function isLevel(l: Level, d: DetailLevel): boolean {
  if (l.vertexCount !== d.vertexCount) return false;
  if (l.bytes === null) return d.mesh.length === 0;
  if (l.bytes.length !== d.mesh.length) return false;
  for (let i = 0; i < l.bytes.length; ++i) if (l.bytes[i] !== d.mesh[i]) return false;
  return true;
}

// The start of a level (the stream's first message, or after a SetDetail):
// its frames follow, from a fresh keyframe state. A level already held
// (the one drawn, the full mesh) is not decoded again.
async function applyLevel(stream: number, d: DetailLevel): Promise<void> {
  let next: Level;
  let decodeMs = 0;
  try {
    if (isLevel(level, d)) next = level;
    else if (isLevel(shown, d)) next = shown;
    else if (isLevel(full, d)) next = full;
    else {
      if (d.mesh.length === 0 || d.vertexCount >= full.vertexCount) {
        throw new FrameError(`a level of ${d.vertexCount} vertices without its mesh, on a mesh of ${full.vertexCount}`);
      }
      const module = await draco;
      const t0 = performance.now();
      const { ids, faces: levelFaces } = decodeLevelMesh(module as unknown as DracoMeshModule, d.mesh, d.vertexCount,
        d.faceCount, full.vertexCount);
      next = { vertexCount: d.vertexCount, ids, rest: gather3(full.rest, ids), faces: levelFaces, bytes: d.mesh.slice() };
      decodeMs = performance.now() - t0;
    }
  } catch (error) {
    // The level's frames cannot be applied to anything held: ask for the stream again.
    const text = error instanceof Error ? error.message : String(error);
    post({ type: 'frameFailed', stream, version: 0n, message: text, resync: !waiting.some((m) => m.level) });
    return;
  }
  keyed = new KeyedDeltas(next.vertexCount);
  if (next !== level) {
    level = next;
    rest = next.rest;
    faces = next.faces;
    // Rewritten whole by the level's first frame, a keyframe: nothing is handed on before it.
    positions = next.rest.slice();
    positionsFollowKeyed = true;
    pending = null;
    stretch = null;
  }
  post({ type: 'levelRead', stream, vertexCount: next.vertexCount, decodeMs });
}

async function applyFrame(message: FrameIn): Promise<void> {
  const { chunked, single, stream } = message;
  const frame = chunked ?? single!;
  let decodeMs: number;
  let applyMs: number;
  let kind: 'single' | 'keyframe' | 'sparse';
  let displacement: number;
  try {
    const levelVertices = level === full ? 0 : level.vertexCount;
    if (frame.levelVertices !== levelVertices) {
      throw new FrameError(`a frame of level ${frame.levelVertices || 'full'} for the level of ${level.vertexCount} vertices`);
    }
    if (frame.vertexCount !== rest.length / 3) {
      throw new FrameError(`a frame of ${frame.vertexCount} vertices for a mesh of ${rest.length / 3}`);
    }
    const module = await draco;
    if (chunked) {
      const present = keyed.check(chunked);  // before decoding: a frame that cannot apply costs nothing
      const t0 = performance.now();
      const values = chunked.chunks.map((chunk, c) => (chunk.deltas.length === 0
        ? new Float32Array(3 * present[c]) : decodeChunk(module, chunk, present[c], c)));
      const t1 = performance.now();
      const changed = keyed.apply(chunked, values);
      if (positionsFollowKeyed) applyDeltaRanges(rest, keyed.deltas, positions, changed);
      else applyDeltas(rest, keyed.deltas, positions);
      positionsFollowKeyed = true;
      displacement = largestDelta(keyed.deltas);
      decodeMs = t1 - t0;
      applyMs = performance.now() - t1;
      kind = isKeyframe(chunked) ? 'keyframe' : 'sparse';
    } else {
      const s = single!;
      const t0 = performance.now();
      const deltas = decodeDeltas(module, s.deltas, s.vertexCount);
      const t1 = performance.now();
      applyDeltas(rest, deltas, positions);
      positionsFollowKeyed = false;
      displacement = largestDelta(deltas);
      decodeMs = t1 - t0;
      applyMs = performance.now() - t1;
      kind = 'single';
    }
  } catch (error) {
    const text = error instanceof Error ? error.message : String(error);
    // The frames after a keyframe that failed, or after one that never came,
    // cannot be read, unless a newer keyframe waits.
    const resync = chunked !== undefined && !waiting.some((m) => isKeyframeIn(m) || m.level !== undefined)
      && (isKeyframe(chunked) || chunked.keyframeVersion !== keyed.keyframeVersion
        || chunked.levelVertices !== (level === full ? 0 : level.vertexCount));
    post({ type: 'frameFailed', stream, version: frame.version, message: text, resync });
    return;
  }
  post({ type: 'applied', version: frame.version, decodeMs, applyMs, maxError: frame.maxError, skipped: 0 });
  pending = { version: frame.version, kind, decodeMs, applyMs, displacement, maxError: frame.maxError };
  output();
}

// Hands the latest applied state to the page if it has a buffer set free:
// positions, normals and, while shown, the stretch colours.
function output(): void {
  if (pending === null) return;
  if (level !== shown) {
    swapLevel();
    return;
  }
  const out = takeBuffers();
  if (out === null) return;  // the page holds both sets: once it hands one back
  const p = pending;
  pending = null;
  out.positions.set(positions);
  const t2 = performance.now();
  vertexNormals(positions, faces, out.normals);
  const t3 = performance.now();
  if (out.colors) stretchColors(out.colors);
  const stretchMs = performance.now() - t3;
  const transfer: Transferable[] = [out.positions.buffer, out.normals.buffer];
  if (out.colors) transfer.push(out.colors.buffer);
  post({
    type: 'ready', version: p.version, buffers: out, kind: p.kind, decodeMs: p.decodeMs, applyMs: p.applyMs,
    normalsMs: t3 - t2, stretchMs, displacement: p.displacement, stretchMax: out.colors ? stretchMax : 0, maxError: p.maxError,
  }, transfer);
}

// The first applied frame of a level the page does not draw: the level's
// whole geometry for the page, in buffers of the level's size (the page's
// sets of the old size are dropped when they come back), and a second set.
function swapLevel(): void {
  const p = pending!;
  pending = null;
  const n3 = rest.length;
  const t0 = performance.now();
  const out: Buffers = { positions: positions.slice(), normals: new Float32Array(n3), colors: stretchOn ? new Float32Array(n3) : null };
  vertexNormals(positions, faces, out.normals);
  const t1 = performance.now();
  if (out.colors) stretchColors(out.colors);
  const stretchMs = performance.now() - t1;
  if (level.coarse === undefined) level.coarse = coarseIndex(rest, faces);
  const isFull = level === full;
  // The full mesh's faces and stand-in the page holds since the join.
  const levelFaces = isFull ? null : faces.slice();
  const coarse = isFull || !level.coarse ? null : level.coarse.slice();
  const ids = level.ids ? level.ids.slice() : null;
  const baseIndex = levelIndices(level.ids, baseIds);
  shown = level;
  spare.length = 0;
  spare.push({ positions: new Float32Array(n3), normals: new Float32Array(n3), colors: null });
  const transfer: Transferable[] = [out.positions.buffer, out.normals.buffer, baseIndex.buffer];
  if (out.colors) transfer.push(out.colors.buffer);
  for (const array of [levelFaces, coarse, ids]) if (array) transfer.push(array.buffer);
  post({
    type: 'level', version: p.version, vertexCount: level.vertexCount, fullVertexCount: full.vertexCount, buffers: out,
    faces: levelFaces, coarseFaces: coarse, ids, baseIndex, kind: p.kind, decodeMs: p.decodeMs, applyMs: p.applyMs,
    normalsMs: t1 - t0, stretchMs, buildMs: performance.now() - t0, displacement: p.displacement,
    stretchMax: out.colors ? stretchMax : 0, maxError: p.maxError,
  }, transfer);
}

// ------------------------------------------------------------------ the Watch stream

// Read here, so that the page's thread never parses a frame (a 1M-vertex
// keyframe is megabytes): the page gets what its panel shows of each frame.
let watching: { stream: number; abort: AbortController } | null = null;

async function watch(stream: number, afterVersion: bigint, maxVertices: number): Promise<void> {
  watching?.abort.abort();
  const abort = new AbortController();
  watching = { stream, abort };
  let opened = false;
  const open = () => {
    if (opened) return;
    opened = true;
    post({ type: 'streamOpened', stream });
  };
  let error: CallError | null = null;
  let first = true;
  try {
    for await (const frame of client!.watch(afterVersion, abort.signal, open, maxVertices)) {
      open();
      if (first && maxVertices > 0 && !frame.level) {
        // A budget asked, a frame first: this server has no levels of detail.
        post({ type: 'levelArrived', stream, streamId: null, vertexCount: full.vertexCount });
      }
      first = false;
      arrived(stream, frame);
    }
  } catch (e) {
    error = callError(e);
  }
  if (watching?.stream === stream) watching = null;
  post({ type: 'streamEnded', stream, error, aborted: abort.signal.aborted });
}

function arrived(stream: number, frame: Frame): void {
  if (frame.level) {
    put({ stream, level: frame.level });
    post({ type: 'levelArrived', stream, streamId: frame.level.streamId, vertexCount: frame.level.vertexCount });
    return;
  }
  const bytes = frameBytes(frame);
  put(isChunked(frame) ? { stream, chunked: frame } : { stream, single: frame });
  // The panel's copy without the delta bytes.
  const light: Frame = { ...frame, deltas: new Uint8Array(0), chunks: frame.chunks.map((c) => ({ ...c, deltas: new Uint8Array(0) })) };
  post({ type: 'frameArrived', stream, frame: light, bytes });
}

// ------------------------------------------------------------------ stretch

// The ramp of stretch.ts in linear RGB (what a colour attribute holds), 256 steps.
const RAMP = (() => {
  const linear = (c: number) => (c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4);
  const table = new Float32Array(3 * 256);
  for (let i = 0; i < 256; ++i) {
    const rgb = stretchColor(1 + (i / 255) * STRETCH_RED);
    for (let k = 0; k < 3; ++k) table[3 * i + k] = linear(rgb[k]);
  }
  return table;
})();

// Per vertex, the largest |L2 − 1| of the triangles around it, as a colour.
function stretchColors(out: Float32Array): void {
  if (stretch === null) {
    stretch = new TriangleStretch(rest, faces);
    stretchValues = new Float32Array(stretch.triangleCount);
    vertexStretch = new Float32Array(rest.length / 3);
  }
  stretch.l2(positions, stretchValues);
  vertexStretch.fill(0);
  let max = 0;
  for (let f = 0; f < stretchValues.length; ++f) {
    const d = Math.abs(stretchValues[f] - 1);
    if (d > max) max = d;
    for (let k = 0; k < 3; ++k) {
      const v = faces[3 * f + k];
      if (d > vertexStretch[v]) vertexStretch[v] = d;
    }
  }
  stretchMax = max;
  for (let v = 0; v < vertexStretch.length; ++v) {
    const step = 3 * Math.min(255, Math.round((vertexStretch[v] / STRETCH_RED) * 255));
    out[3 * v] = RAMP[step];
    out[3 * v + 1] = RAMP[step + 1];
    out[3 * v + 2] = RAMP[step + 2];
  }
}

// ------------------------------------------------------------------ overlays

// The cut (coarse edges over a tint of what is refined) and the regions
// (palette colours, outlines) of the latest frame, for drawing.
async function overlays(id: number): Promise<void> {
  let answer;
  try {
    answer = await client!.getOverlays();
  } catch (error) {
    post({ type: 'overlaysFailed', id, error: callError(error) });
    return;
  }
  // Over the mesh the page draws: at a level, its vertices' regions and the
  // cut's triangles whose corners it holds.
  const on = shown;
  const n = on.vertexCount;
  const regionColors = new Float32Array(3 * n);
  let regionEdges: Uint32Array = new Uint32Array(0);
  let cutEdges: Uint32Array = new Uint32Array(0);
  const refined = new Float32Array(3 * n);
  let refinedTriangles = 0;
  if (answer.ready && answer.regionOf.length === full.vertexCount) {
    const regionOf = on.ids ? gather1(answer.regionOf, on.ids, new Uint32Array(n)) : answer.regionOf;
    regionVertexColours(regionOf, colourRegions(regionOf, on.faces), regionColors);
    regionEdges = regionBoundaryEdges(regionOf, on.faces);
  }
  if (answer.ready) {
    on.edges ??= edgeSet(on.faces, n);
    const cut = cutForDrawing(on.ids ? facesOnLevel(on.ids, answer.cutFaces) : answer.cutFaces, on.edges, n);
    cutEdges = cut.coarse;
    refinedTriangles = cut.refinedTriangles;
    // Refined: a cyan tint; elsewhere the mesh's own colour (linear RGB of 0xc9bfae and of 0x5fd3f0).
    for (let v = 0; v < n; ++v) {
      const [r, g, b] = cut.refined[v] ? [0.117, 0.651, 0.871] : [0.584, 0.521, 0.423];
      refined[3 * v] = r;
      refined[3 * v + 1] = g;
      refined[3 * v + 2] = b;
    }
  }
  post({
    type: 'overlays', id, ready: answer.ready, version: answer.version, vertexCount: n, regionCount: answer.regionCount,
    cutTriangles: Math.floor(answer.cutFaces.length / 3), refinedTriangles, regionColors, regionEdges, cutEdges, refined,
  }, [regionColors.buffer, regionEdges.buffer, cutEdges.buffer, refined.buffer]);
}

// ------------------------------------------------------------------ history

// GetHistory, parsed here (each entry lists the base vertices it changed:
// up to every base vertex, for each of `newest` entries) and summarised for
// the panel, newest first.
async function history(id: number, newest: number): Promise<void> {
  let answer;
  try {
    answer = await client!.getHistory(newest);
  } catch (error) {
    post({ type: 'historyFailed', id, error: callError(error) });
    return;
  }
  const lines: HistoryLines = {
    entries: answer.entries.map((e) => ({
      seq: Number(e.seq), kind: e.kind, author: e.author, startTime: e.startTime, endTime: e.endTime, vertices: e.baseVertices.length,
      target: Number(e.target), undone: e.undone, gestureId: e.gestureId, version: e.version,
    })).reverse(),
    checkpoints: answer.checkpoints.map((c) => ({
      id: c.id, name: c.name, author: c.author, time: c.time, version: c.version, afterEntry: Number(c.afterEntry),
    })).reverse(),
    firstSeq: Number(answer.firstSeq),
    bytes: Number(answer.bytes),
  };
  post({ type: 'history', id, history: lines });
}

// ------------------------------------------------------------------ messages

self.onmessage = (event: MessageEvent<ToWorker>) => {
  const message = event.data;
  switch (message.type) {
    case 'join':
      void join(message.serverUrl, message.sessionId, message.token);
      break;
    case 'watch':
      void watch(message.stream, message.afterVersion, message.maxVertices);
      break;
    case 'stopWatch':
      if (watching?.stream === message.stream) watching.abort.abort();
      break;
    case 'clear':
      waiting = [];
      break;
    case 'recycle':
      // Sets of a level no longer drawn are dropped.
      if (message.buffers.positions.length === shown.rest.length && spare.length < 2) spare.push(message.buffers);
      output();
      break;
    case 'overlays':
      void overlays(message.id);
      break;
    case 'history':
      void history(message.id, message.newest);
      break;
    case 'stretch':
      stretchOn = message.on;
      if (stretchOn && rest.length > 0 && level === shown) {
        const colors = new Float32Array(rest.length);
        stretchColors(colors);
        post({ type: 'colors', colors, stretchMax }, [colors.buffer]);
      }
      break;
  }
};
