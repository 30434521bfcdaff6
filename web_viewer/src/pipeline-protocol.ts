// The messages between the page (pipeline.ts) and its session worker
// (session.worker.ts). Types only.
import type { Frame, SessionInfo } from './client';
import type { Framing } from './geometry';

// What the page draws from: positions and vertex normals (3 floats per
// vertex), and the stretch colours while that overlay is on. Two sets take
// turns (double buffering): the worker fills one while the page holds the
// other; the page hands a set back as soon as a newer one replaced it.
export interface Buffers { positions: Float32Array; normals: Float32Array; colors: Float32Array | null }

export type ToWorker =
  | { type: 'join'; serverUrl: string; sessionId: string; token: string }
  // Open the Watch stream `stream` (numbered by the page, from 1) after
  // `afterVersion`, ending any other; maxVertices: its level of detail
  // (WatchRequest.max_vertices; 0: full detail, no switching).
  | { type: 'watch'; stream: number; afterVersion: bigint; maxVertices: number }
  // End the Watch stream (a resync: it is opened again from version 0).
  | { type: 'stopWatch'; stream: number }
  // Drop the frames waiting (they need a keyframe that was lost).
  | { type: 'clear' }
  | { type: 'recycle'; buffers: Buffers }
  | { type: 'stretch'; on: boolean }
  | { type: 'overlays'; id: number }
  // GetHistory of the newest `newest` entries, summarised (HistoryLines).
  | { type: 'history'; id: number; newest: number };

export type LoadStage = 'download' | 'receive' | 'build';

// A history entry as the panel shows it (proto HistoryEntry without its
// vertex list: the worker parses the answer, whose lists may hold every base
// vertex of every entry).
export interface HistoryLine {
  seq: number; kind: number; author: string; startTime: number; endTime: number; vertices: number; target: number;
  undone: boolean; gestureId: bigint; version: bigint;
}
export interface CheckpointLine { id: bigint; name: string; author: string; time: number; version: bigint; afterEntry: number }
export interface HistoryLines { entries: HistoryLine[]; checkpoints: CheckpointLine[]; firstSeq: number; bytes: number }

// A failed call, as the page rebuilds it (a ConnectError cannot be posted).
export interface CallError { code: number | null; rawMessage: string; message: string; fetchFailed: boolean }

export type FromWorker =
  // download: JoinSession's bytes; receive: the rest mesh's values from
  // GetRestMesh (a mesh too large for one message); build: normals, framing.
  | { type: 'progress'; stage: LoadStage; loaded: number; total: number | null }
  // The session without its big arrays (info.rest emptied), those as typed
  // arrays; restParts: GetRestMesh parts they came in (0: in JoinSession's answer).
  | {
    type: 'joined'; info: SessionInfo; faces: Uint32Array; coarseFaces: Uint32Array | null; buffers: Buffers; framing: Framing;
    basePositions: Float32Array; baseFaces: Uint32Array; originalIds: Uint32Array; restParts: number; joinMs: number;
    buildMs: number;
  }
  | { type: 'joinFailed'; error: CallError }
  // The Watch stream is open (the server answered).
  | { type: 'streamOpened'; stream: number }
  // A frame arrived: what the panel shows of it (its delta bytes emptied; `bytes` counts them).
  | { type: 'frameArrived'; stream: number; frame: Frame; bytes: number }
  // The stream ended: OK (error null), failed, or stopped (aborted) by the page.
  | { type: 'streamEnded'; stream: number; error: CallError | null; aborted: boolean }
  // A frame applied to the worker's state (every frame it gets, unless a newer one superseded it while it was busy).
  | { type: 'applied'; version: bigint; decodeMs: number; applyMs: number; maxError: number; skipped: number }
  // The state to draw, when the page has a buffer set free: the newest applied frame, with normals (and stretch colours).
  | {
    type: 'ready'; version: bigint; buffers: Buffers; kind: 'single' | 'keyframe' | 'sparse';
    decodeMs: number; applyMs: number; normalsMs: number; stretchMs: number; displacement: number; stretchMax: number;
    maxError: number;
  }
  // A level of detail announced on stream `stream` (Frame.level, read off the
  // stream): its id for SetDetail and its vertex count. streamId null: the
  // stream asked for a level and got frames (a server without levels).
  | { type: 'levelArrived'; stream: number; streamId: bigint | null; vertexCount: number }
  // The level's mesh decoded (0 ms: one already held), its frames next.
  | { type: 'levelRead'; stream: number; vertexCount: number; decodeMs: number }
  // A new level to draw, with its first applied frame (as 'ready'): its
  // buffers; faces and coarseFaces over its vertices (null faces: the full
  // mesh's, with its stand-in, as joined); ids: each vertex's original id
  // (null: the full mesh); baseIndex: the level index of each base vertex
  // (−1: not in the level). buildMs: the worker's time for the geometry.
  | {
    type: 'level'; version: bigint; vertexCount: number; fullVertexCount: number; buffers: Buffers;
    faces: Uint32Array | null; coarseFaces: Uint32Array | null; ids: Uint32Array | null; baseIndex: Int32Array;
    kind: 'single' | 'keyframe' | 'sparse'; decodeMs: number; applyMs: number; normalsMs: number; stretchMs: number;
    buildMs: number; displacement: number; stretchMax: number; maxError: number;
  }
  // The stretch colours of the frame held, when the overlay is turned on.
  | { type: 'colors'; colors: Float32Array; stretchMax: number }
  // GetOverlays made drawable (overlay-build.ts); ready false: not built yet, ask after the next frame.
  | {
    type: 'overlays'; id: number; ready: boolean; version: bigint; vertexCount: number; regionCount: number; cutTriangles: number;
    refinedTriangles: number; regionColors: Float32Array; regionEdges: Uint32Array; cutEdges: Uint32Array;
    refined: Float32Array;
  }
  | { type: 'overlaysFailed'; id: number; error: CallError }
  // GetHistory's answer (entries newest first), or why it failed.
  | { type: 'history'; id: number; history: HistoryLines }
  | { type: 'historyFailed'; id: number; error: CallError }
  // resync: the keyframe the stream's next frames need is not held here.
  | { type: 'frameFailed'; stream: number; version: bigint; message: string; resync: boolean };
