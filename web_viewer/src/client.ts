// The Filigree service through gRPC-Web (binary), for one session and token.
import { Code, ConnectError, createClient, type Client, type Interceptor } from '@connectrpc/connect';
import { createGrpcWebTransport } from '@connectrpc/connect-web';

import {
  Filigree, FrameFormat, type Checkpoint, type CheckpointDiff, type DetailLevel, type Frame, type History, type ListSessionsResponse_Entry,
  type Overlays, type Presence, type RestMeshPart, type SessionHandles, type SessionInfo, type SessionState, type SetHandlesResponse,
  type UndoResponse,
} from './gen/filigree/v1/filigree_pb';

export type {
  Checkpoint, CheckpointDiff, DetailLevel, Frame, History, Overlays, Presence, RestMeshPart, SessionHandles, SessionInfo, SessionState,
  UndoResponse,
};
export type SessionEntry = ListSessionsResponse_Entry;

// A handle as this page keeps it: a vertex of the detailed mesh (original
// order) and where it should go.
export interface HandleTarget { vertex: number; x: number; y: number; z: number }

export class SessionClient {
  private readonly client: Client<typeof Filigree>;

  // `fetch`: another fetch (the session worker counts the bytes of the join).
  constructor(readonly serverUrl: string, readonly sessionId: string, token: string, fetch?: typeof globalThis.fetch) {
    // Every call carries the token, and the session id so that a load
    // balancer can route by session (DESIGN §4).
    const credentials: Interceptor = (next) => (request) => {
      request.header.set('x-filigree-token', token);
      request.header.set('x-session-id', sessionId);
      return next(request);
    };
    const transport = createGrpcWebTransport({
      baseUrl: serverUrl, useBinaryFormat: true, interceptors: [credentials], ...(fetch ? { fetch } : {}),
    });
    this.client = createClient(Filigree, transport);
  }

  // The session; its rest mesh may come without its arrays (info.rest.inParts:
  // too large for one message), which restMesh() then streams.
  join(): Promise<SessionInfo> {
    return this.client.joinSession({ sessionId: this.sessionId });
  }

  // The rest mesh in parts (GetRestMesh, server streaming; viewer token):
  // each part continues the arrays where the previous one left them,
  // positions, then faces, then uploaded_ids (rest-parts.ts assembles them).
  restMesh(signal?: AbortSignal): AsyncIterable<RestMeshPart> {
    return this.client.getRestMesh({ sessionId: this.sessionId }, signal ? { signal } : {});
  }

  // The session's frames: the current one at once (if newer than
  // afterVersion), then every new one; ends when the session closes.
  // Chunked (frame.ts): each keyframe comes before the frames relative to it,
  // so afterVersion 0 is how to get the current keyframe again. A server
  // without that format sends single frames, which the page reads too.
  // `onHeader`: the server answered (the stream is open), before any frame.
  // `maxVertices` > 0: at a level of detail (levels.ts), announced by a
  // message with only Frame.level set, and switchable with setDetail.
  watch(afterVersion: bigint, signal: AbortSignal, onHeader?: () => void, maxVertices = 0): AsyncIterable<Frame> {
    return this.client.watch({ sessionId: this.sessionId, afterVersion, frameFormat: FrameFormat.CHUNKED, maxVertices },
      { signal, ...(onHeader ? { onHeader } : {}) });
  }

  // Moves the live stream `streamId` (DetailLevel.stream_id) to the level a
  // budget of `maxVertices` gets; resolves with that level's vertex count.
  // The stream then sends the level and its keyframe (viewer token).
  async setDetail(streamId: bigint, maxVertices: number): Promise<number> {
    const answer = await this.client.setDetail({ sessionId: this.sessionId, streamId, maxVertices });
    return answer.vertexCount;
  }

  // Plays one of the session's clips on the server (editor token): its
  // frames arrive here and on every Watch stream; ends after the clip's last
  // sample (never when looping: abort `signal` to stop).
  playClip(clip: string, loop: boolean, clientName: string, signal: AbortSignal): AsyncIterable<Frame> {
    return this.client.playClip({ sessionId: this.sessionId, clip, loop, clientName, frameFormat: FrameFormat.CHUNKED },
      { signal });
  }

  // Chunked too: state.frame may be relative to state.keyframe (framesOfState).
  getState(): Promise<SessionState> {
    return this.client.getState({ sessionId: this.sessionId, frameFormat: FrameFormat.CHUNKED });
  }

  // `clientName`: the history entry's author (so that its undo is theirs).
  setOptions(threshold: number, wholeMesh: boolean, clientName = ''): Promise<SessionInfo> {
    return this.client.setOptions({ sessionId: this.sessionId, threshold, wholeMesh, clientName });
  }

  // A full pose (3·m floats in base order); resolves with the version the
  // pose was accepted at: the frame that includes it has a larger one.
  // `indices`: a partial pose, positions[3k..] for base vertex indices[k].
  // `gestureId`: every pose of one drag shares it (one history entry, one undo).
  async submitPose(poseId: bigint, positions: number[], clientName: string, indices: number[] = [],
    gestureId = 0n): Promise<bigint> {
    const response = await this.client.submitPose({ sessionId: this.sessionId, poseId, positions, clientName, indices, gestureId });
    return response.acceptedAtVersion;
  }

  // Replaces this client's handles (empty: none); resolves with the version
  // they were accepted at (the frame including them has a larger one) and
  // all participants' handle count after the merge. `gestureId` as submitPose's.
  setHandles(clientName: string, handles: HandleTarget[], gestureId = 0n): Promise<SetHandlesResponse> {
    return this.client.setHandles({ sessionId: this.sessionId, clientName, handles, gestureId });
  }

  // ---- history, checkpoints, presence

  // The newest `newest` history entries (oldest first) and the checkpoints (viewer token).
  getHistory(newest: number): Promise<History> {
    return this.client.getHistory({ sessionId: this.sessionId, newest });
  }

  // Undoes (redo: redoes) `clientName`'s latest change; `force` also
  // overwrites what others changed since (editor token).
  undo(clientName: string, redo: boolean, force = false): Promise<UndoResponse> {
    const request = { sessionId: this.sessionId, clientName, force };
    return redo ? this.client.redo(request) : this.client.undo(request);
  }

  createCheckpoint(name: string, clientName: string): Promise<Checkpoint> {
    return this.client.createCheckpoint({ sessionId: this.sessionId, name, clientName });
  }

  restoreCheckpoint(checkpoint: bigint, clientName: string): Promise<UndoResponse> {
    return this.client.restoreCheckpoint({ sessionId: this.sessionId, checkpoint, clientName });
  }

  diffCheckpoint(checkpoint: bigint): Promise<CheckpointDiff> {
    return this.client.diffCheckpoint({ sessionId: this.sessionId, checkpoint });
  }

  // Who is here: the current presence at once, then every change; this
  // page is listed as `clientName` while the stream is open (viewer token).
  watchPresence(clientName: string, signal: AbortSignal): AsyncIterable<Presence> {
    return this.client.watchPresence({ sessionId: this.sessionId, clientName }, { signal });
  }

  // Where this page points on the mesh (null: nowhere); `vertex` an original id.
  async setPresence(clientName: string, pointer: { x: number; y: number; z: number; vertex: number } | null): Promise<void> {
    await this.client.setPresence({
      sessionId: this.sessionId, clientName, hasPointer: pointer !== null, pointerX: pointer?.x ?? 0, pointerY: pointer?.y ?? 0,
      pointerZ: pointer?.z ?? 0, pointerVertex: pointer?.vertex ?? 0,
    });
  }

  // Every participant's handles by client name, as their last SetHandles
  // left them (this page's own among them); viewer token.
  getHandles(): Promise<SessionHandles> {
    return this.client.getHandles({ sessionId: this.sessionId });
  }

  // The regions and the cut mesh of the latest frame; ready is false until
  // the server has built them (ask again after the next frame).
  getOverlays(): Promise<Overlays> {
    return this.client.getOverlays({ sessionId: this.sessionId });
  }

  // This session's line of ListSessions (undefined once it is gone).
  async entry(): Promise<SessionEntry | undefined> {
    const { sessions } = await this.client.listSessions({});
    return sessions.find((s) => s.sessionId === this.sessionId);
  }
}

// A sentence a person can act on, for any error of a call above.
export function describeError(error: unknown, sessionId: string, serverUrl: string): string {
  if (!(error instanceof ConnectError)) return error instanceof Error ? error.message : String(error);
  // fetch() itself failed: nothing answered, or the browser refused the
  // answer (CORS for a server=… other than this page's origin).
  if (error.code === Code.Unknown && error.cause instanceof TypeError) {
    return `Cannot reach the server ${serverUrl}: it is down, the address is wrong, or it does not accept ` +
      `requests from this page's origin (${error.cause.message}).`;
  }
  const detail = error.rawMessage ? ` (server: ${error.rawMessage})` : '';
  switch (error.code) {
    case Code.Unauthenticated:
      return `No token was accepted: add &token=… (the session's viewer or editor token) to the address.${detail}`;
    case Code.PermissionDenied:
      return `The token was refused for session ${sessionId}: it is wrong, or this needs the editor token.${detail}`;
    case Code.NotFound:
      // The server gives one answer for "no such session" and "not yours" (DESIGN §3.2).
      return `Session ${sessionId} does not exist on ${serverUrl} (unknown or closed), or the token is not one of its tokens.${detail}`;
    case Code.Unavailable:
      return `The server ${serverUrl} is unavailable (unreachable, or shutting down).${detail}`;
    case Code.InvalidArgument:
      return `The server refused the request: ${error.rawMessage}`;
    case Code.ResourceExhausted:
      return `Over a server limit: ${error.rawMessage}`;
    default:
      return `${Code[error.code]}: ${error.rawMessage || 'no message'} (${serverUrl})`;
  }
}

export function isCode(error: unknown, code: Code): boolean {
  return error instanceof ConnectError && error.code === code;
}
export { Code };
