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
import createDecoderModule from 'draco3d/draco_decoder_nodejs.js';
import wasmUrl from 'draco3d/draco_decoder.wasm?url';

import { ConnectError } from '@connectrpc/connect';

import { SessionClient, type Frame } from './client';
import { frameBytes } from './stats';
import {
  applyDeltaRanges, applyDeltas, decodeChunk, decodeDeltas, FrameError, isChunked, isKeyframe, KeyedDeltas, largestDelta,
  type ChunkedFrameData, type DracoDecoderModule,
} from './frame';
import { coarseIndex, frameMesh, vertexNormals } from './geometry';
import { colourRegions, cutForDrawing, edgeSet, regionBoundaryEdges, regionVertexColours } from './overlay-build';
import { FrameMailbox } from './mailbox';
import { RestAssembler } from './rest-parts';
import type { Buffers, CallError, FromWorker, ToWorker } from './pipeline-protocol';
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

// The session's mesh and the deformation state.
let rest = new Float32Array(0);
let faces = new Uint32Array(0);
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
let fineEdges: Set<number> | null = null;  // of the detailed mesh, for the cut overlay

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

// A frame off the Watch stream, read here: the chunked or the single format.
interface FrameIn { stream: number; chunked?: ChunkedFrameData; single?: { version: bigint; vertexCount: number; deltas: Uint8Array } }
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
let pending: { version: bigint; kind: 'single' | 'keyframe' | 'sparse'; decodeMs: number; applyMs: number; displacement: number } | null = null;

function put(message: FrameIn): void {
  waiting.push(message);
  if (waiting.length > MAX_WAITING) {
    const box = new FrameMailbox<FrameIn>(isKeyframeIn);
    let superseded = 0;
    for (const m of waiting) superseded += box.put(m);
    waiting = [box.take(), box.take()].filter((m): m is FrameIn => m !== null);
    post({ type: 'applied', version: -1n, decodeMs: 0, applyMs: 0, skipped: superseded });
  }
  if (!working) void work();
}

// Applies the frames as they come, yielding between them so that newer ones
// can supersede the one waiting.
async function work(): Promise<void> {
  working = true;
  for (let next = waiting.shift(); next !== undefined; next = waiting.shift()) {
    await applyFrame(next);
    await new Promise((resolve) => setTimeout(resolve, 0));
  }
  working = false;
}

async function applyFrame(message: FrameIn): Promise<void> {
  const { chunked, single, stream } = message;
  const frame = chunked ?? single!;
  let decodeMs: number;
  let applyMs: number;
  let kind: 'single' | 'keyframe' | 'sparse';
  let displacement: number;
  try {
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
    const resync = chunked !== undefined && !waiting.some(isKeyframeIn)
      && (isKeyframe(chunked) || chunked.keyframeVersion !== keyed.keyframeVersion);
    post({ type: 'frameFailed', stream, version: frame.version, message: text, resync });
    return;
  }
  post({ type: 'applied', version: frame.version, decodeMs, applyMs, skipped: 0 });
  pending = { version: frame.version, kind, decodeMs, applyMs, displacement };
  output();
}

// Hands the latest applied state to the page if it has a buffer set free:
// positions, normals and, while shown, the stretch colours.
function output(): void {
  if (pending === null) return;
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
    normalsMs: t3 - t2, stretchMs, displacement: p.displacement, stretchMax: out.colors ? stretchMax : 0,
  }, transfer);
}

// ------------------------------------------------------------------ the Watch stream

// Read here, so that the page's thread never parses a frame (a 1M-vertex
// keyframe is megabytes): the page gets what its panel shows of each frame.
let watching: { stream: number; abort: AbortController } | null = null;

async function watch(stream: number, afterVersion: bigint): Promise<void> {
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
  try {
    for await (const frame of client!.watch(afterVersion, abort.signal, open)) {
      open();
      arrived(stream, frame);
    }
  } catch (e) {
    error = callError(e);
  }
  if (watching?.stream === stream) watching = null;
  post({ type: 'streamEnded', stream, error, aborted: abort.signal.aborted });
}

function arrived(stream: number, frame: Frame): void {
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
  const n = rest.length / 3;
  const regionColors = new Float32Array(3 * n);
  let regionEdges: Uint32Array = new Uint32Array(0);
  let cutEdges: Uint32Array = new Uint32Array(0);
  const refined = new Float32Array(3 * n);
  let refinedTriangles = 0;
  if (answer.ready && answer.regionOf.length === n) {
    regionVertexColours(answer.regionOf, colourRegions(answer.regionOf, faces), regionColors);
    regionEdges = regionBoundaryEdges(answer.regionOf, faces);
  }
  if (answer.ready) {
    fineEdges ??= edgeSet(faces, n);
    const cut = cutForDrawing(answer.cutFaces, fineEdges, n);
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
    type: 'overlays', id, ready: answer.ready, version: answer.version, regionCount: answer.regionCount,
    cutTriangles: Math.floor(answer.cutFaces.length / 3), refinedTriangles, regionColors, regionEdges, cutEdges, refined,
  }, [regionColors.buffer, regionEdges.buffer, cutEdges.buffer, refined.buffer]);
}

// ------------------------------------------------------------------ messages

self.onmessage = (event: MessageEvent<ToWorker>) => {
  const message = event.data;
  switch (message.type) {
    case 'join':
      void join(message.serverUrl, message.sessionId, message.token);
      break;
    case 'watch':
      void watch(message.stream, message.afterVersion);
      break;
    case 'stopWatch':
      if (watching?.stream === message.stream) watching.abort.abort();
      break;
    case 'clear':
      waiting = [];
      break;
    case 'recycle':
      if (message.buffers.positions.length === rest.length) spare.push(message.buffers);
      output();
      break;
    case 'overlays':
      void overlays(message.id);
      break;
    case 'stretch':
      stretchOn = message.on;
      if (stretchOn && rest.length > 0) {
        const colors = new Float32Array(rest.length);
        stretchColors(colors);
        post({ type: 'colors', colors, stretchMax }, [colors.buffer]);
      }
      break;
  }
};
