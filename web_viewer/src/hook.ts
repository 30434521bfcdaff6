// window.__filigree: what the page is doing, for the browser tests
// (test/browser.test.mjs) and for a person at the console. After each applied
// frame the page dispatches FRAME_EVENT on window, so a test can look at a
// given frame (capture()) before the next one replaces it.
export const FRAME_EVENT = 'filigree:frame';

export interface TestHook {
  state: 'starting' | 'usage' | 'joining' | 'live' | 'reconnecting' | 'closed' | 'error';
  error: string | null;     // the last error shown in the page
  sessionId: string | null;
  vertexCount: number;      // of the detailed mesh drawn (a level of detail's, at one)
  baseVertexCount: number;
  // Levels of detail (detail-control.ts): the mesh's vertex count, the level
  // drawn (== fullVertexCount at full detail) and the original ids of its
  // vertices (null at full detail); what the page asks for (mode, budget;
  // the budget is fullVertexCount for full detail) and why it changed.
  fullVertexCount: number;
  levelVertices: number;
  levelIds(): number[] | null;
  detailMode: 'auto' | 'full' | 'fixed' | '';
  detailBudget: number;
  detailTarget: number;     // the level that budget gets (as the server rounds it)
  detailLog: { at: number; budget: number; reason: string }[];
  levelsArrived: number;    // level messages read off the streams (a stream's first, and after each SetDetail)
  levelSwaps: number;       // geometries swapped for another level
  levelSwapMs: number;      // this thread's time for the last swap
  levelSwapMsMax: number;   // and the longest
  levelDecodeMs: number;    // the worker's decode of the last level's mesh (0: one it held)
  framesAtLevel: number;    // states swapped in since the last level swap (that one included)
  lastNewFrameAt: number;   // performance.now() when the newest version arrived (Auto's idle clock)
  streamId: string;         // DetailLevel.stream_id of the current stream ('' before one)
  watchStreams: number;     // Watch streams opened (a SetDetail switches without a new one)
  setDetailCalls: number;
  setDetailAnswers: number;
  maxError: number;         // Frame.max_error of the last frame drawn
  version: number;          // of the last applied frame
  framesReceived: number;
  framesApplied: number;
  framesSkipped: number;    // superseded by a newer frame before they were decoded
  framesRendered: number;
  roundTripMs: number | null;
  displacement: number;     // largest |delta| coordinate of the last applied frame (single: its quantization range; chunked: decoded)
  frameKind: 'single' | 'keyframe' | 'sparse' | '';  // of the last applied frame ('' before the first)
  framesSparse: number;     // applied frames relative to a keyframe (chunked format)
  resyncs: number;          // Watch streams reopened to get a keyframe again (one failed or never came)
  clientName: string;       // this page's name in SetHandles, SubmitPose and the change list
  handleCount: number;      // this page's handles
  handlesAnswered: number;  // SetHandles calls the server accepted
  handlesAcceptedAt: number;  // the version the last one was accepted at: the frame with its handles is newer
  handlesSending: boolean;  // a SetHandles call is running or waiting
  handlesInSession: number | null;  // everyone's handles, after the last accepted call
  // The other participants drawn (participants.ts): name, colour (#rrggbb) and handle count, by name.
  participants: { name: string; colour: string; handles: number }[];
  participantsAnswers: number;      // GetHandles answers shown
  participantsVersion: number;      // the version of the last one
  participantsFetching: boolean;    // a GetHandles call is running or due
  // The other participants' spheres in the scene: colour drawn, vertex, page point (null: behind the camera).
  otherHandles(): { name: string; colour: string; vertex: number; visible: boolean; x: number | null; y: number | null }[];
  // The colour a client name gets (the same on every page).
  participantColour(name: string): string;
  // The edit history (history.ts), newest first, as the last GetHistory answer had it.
  history: { seq: number; kind: string; author: string; undone: boolean; vertices: number; gestureId: string; text: string }[];
  checkpoints: { id: number; name: string; author: string }[];
  historyCalls: number;             // GetHistory calls made
  historyAnswers: number;           // and answered
  historyMostInFlight: number;      // the most ever running at once
  historyFetching: boolean;         // a GetHistory call is running or due
  // Undo and redo answers shown (outcome: UndoResponse.Outcome; text: what the page said; conflicts: their authors).
  undos: { redo: boolean; outcome: number; text: string; message: string; conflicts: string[]; forced: boolean }[];
  undosPending: number;             // presses not answered yet
  // Who is here (presence-layer.ts), as the last WatchPresence message had it.
  presence: { name: string; colour: string; role: string; you: boolean; touching: number; handles: number; pointerVertex: number | null }[];
  presenceMessages: number;
  presenceStreams: number;          // WatchPresence streams opened
  presenceFirst: string[];          // the names in the current stream's first message
  // Dots drawn per other participant (their touched base vertices), and their pointers on the page.
  touchMarkers(): Record<string, number>;
  otherPointers(): { name: string; colour: string; vertex: number; x: number | null; y: number | null; visible: boolean }[];
  pointerCalls: number;             // SetPresence calls answered
  pointerVertex: number | null;     // the vertex this page's pointer was last sent at (null: none)
  regionCount: number | null;       // of the last ready GetOverlays (null: none yet)
  overlaysVersion: number;          // the frame those overlays describe
  cutTriangles: number;             // triangles of that cut mesh
  stretchMax: number;       // largest |L2 − 1| of the last stretch map (0 while it is off)
  clips: string[];          // the session's animation clips (skinned uploads)
  clipState: 'idle' | 'playing' | 'done' | 'stopped' | 'error';
  clipFrames: number;       // frames of the clip stream received
  capture(): string | null; // the canvas as a PNG data URL, null before the mesh exists
  // Page coordinates where vertex i is drawn now (null before the mesh exists).
  screenPointOfVertex(i: number): { x: number; y: number } | null;
  // The vertex nearest to the camera: always in view and pickable.
  nearestVertexToCamera(): number;
  // The vertex a press at the page point would take as a handle (null: none).
  vertexAt(x: number, y: number): number | null;
  // Where vertex i is now (world space; null before the mesh exists).
  vertexPosition(i: number): number[] | null;
  // The drawn mesh's bounding rectangle as fractions of the canvas (null before the mesh exists).
  screenExtent(): { width: number; height: number; left: number; top: number } | null;
  // The camera's view direction and up (world space).
  viewDirection(): { look: number[]; up: number[] } | null;
  // The panel's statistics (stats.ts, StatsSnapshot; versions as numbers).
  statsSnapshot(): Record<string, unknown> | null;
  loadStage: 'download' | 'receive' | 'build' | 'done' | '';
  loadStages: string[];     // every stage shown while loading, in order ('receive': the mesh came in parts)
  receiveFraction: number;  // of the mesh's values received in parts, when last shown
  restParts: number;        // GetRestMesh parts the mesh came in (0: in JoinSession's answer)
  triangleCount: number;    // of the detailed mesh drawn
  meshRadius: number;       // of the rest mesh's bounding sphere (the pull radius slider is a share of it)
  joinMs: number;           // JoinSession in the worker, to the last byte (and GetRestMesh, for a mesh in parts)
  buildMs: number;          // the first normals and the framing, in the worker
  upAxis: 'y' | 'z' | '';   // as the page framed the mesh
  fits: number;             // Fit button or F key presses
  canEdit: boolean | null;  // the token is the editor's (null: not known yet)
  editMode: 'pull' | 'handles' | '';
  pulledVertices: number;   // base vertices the last pull moved
  editToDrawnMs: number | null;  // own edit → the frame including it drawn
  reconnects: number;       // Watch streams opened again after one was lost
  lastLoss: string;         // why the last stream was lost
  newestVersion: number;    // of the frames arrived
  drawnVersion: number;     // of the last frame drawn
  framesDrawn: number;      // draws that showed a newer version than the one before
  pageMsTotal: number;      // this thread's own time for frames (receiving, swapping in), summed
  drawMsTotal: number;      // renderer.render time (uploads and draw calls), summed over draws
  draws: number;            // every draw (frames, orbits, overlays)
  coarseTriangles: number;  // of the stand-in drawn while busy (0: none, the mesh is small)
  coarseDraws: number;      // draws of the stand-in
  lastDrawFull: boolean;    // the last draw was full detail of a mesh that has a stand-in
  pixelRatio: number;       // drawing resolution now (lowered while draws are slow to show)
  drawShowMs: number;       // how long a draw takes to be shown (smoothed)
  // The front door (no session in the address):
  frontState: '' | 'needs-key' | 'listed' | 'creating' | 'created' | 'error';
  apiKeysNeeded: boolean;   // the server lists and creates only with an API key (/server.json)
  sessionsListed: string[]; // the ids ListSessions gave this visitor
  createStages: string[];   // the upload's stages seen: 'sending', then the server's ('validating', …)
}

declare global {
  interface Window { __filigree: TestHook }
}

export const hook: TestHook = window.__filigree = {
  state: 'starting', error: null, sessionId: null, vertexCount: 0, baseVertexCount: 0, version: 0,
  fullVertexCount: 0, levelVertices: 0, levelIds: () => null, detailMode: '', detailBudget: 0, detailTarget: 0, detailLog: [],
  levelsArrived: 0, levelSwaps: 0, levelSwapMs: 0, levelSwapMsMax: 0, levelDecodeMs: 0, framesAtLevel: 0, lastNewFrameAt: 0, streamId: '',
  watchStreams: 0, setDetailCalls: 0, setDetailAnswers: 0, maxError: 0,
  framesReceived: 0, framesApplied: 0, framesSkipped: 0, framesRendered: 0, roundTripMs: null,
  displacement: 0, frameKind: '', framesSparse: 0, resyncs: 0, clientName: '', handleCount: 0, handlesAnswered: 0, handlesAcceptedAt: 0, handlesSending: false, handlesInSession: null,
  participants: [], participantsAnswers: 0, participantsVersion: 0, participantsFetching: false, otherHandles: () => [],
  participantColour: () => '', history: [], checkpoints: [], historyCalls: 0, historyAnswers: 0, historyMostInFlight: 0,
  historyFetching: false, undos: [], undosPending: 0, presence: [], presenceMessages: 0, presenceStreams: 0, presenceFirst: [],
  touchMarkers: () => ({}), otherPointers: () => [], pointerCalls: 0, pointerVertex: null, regionCount: null,
  overlaysVersion: 0, cutTriangles: 0, stretchMax: 0, clips: [], clipState: 'idle', clipFrames: 0,
  capture: () => null, screenPointOfVertex: () => null, nearestVertexToCamera: () => -1, vertexAt: () => null,
  vertexPosition: () => null, screenExtent: () => null, viewDirection: () => null, statsSnapshot: () => null,
  loadStage: '', loadStages: [], receiveFraction: 0, restParts: 0, triangleCount: 0, meshRadius: 0, joinMs: 0, buildMs: 0, upAxis: '', fits: 0, canEdit: null, editMode: '', pulledVertices: 0,
  editToDrawnMs: null, reconnects: 0, lastLoss: '', newestVersion: 0, drawnVersion: 0,
  framesDrawn: 0, pageMsTotal: 0, drawMsTotal: 0, draws: 0, coarseTriangles: 0, coarseDraws: 0, lastDrawFull: false, pixelRatio: 1, drawShowMs: 0,
  frontState: '', apiKeysNeeded: false, sessionsListed: [], createStages: [],
};
