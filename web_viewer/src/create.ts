// CreateSession from the page: one POST whose body holds every request
// message (begin, then the file in chunks) as gRPC-Web data frames, and the
// streamed answer (progress, then created, then the trailers) read as it
// arrives. connect-web cannot send a client stream, hence by hand.
import { create, fromBinary, toBinary } from '@bufbuild/protobuf';
import { Code, ConnectError } from '@connectrpc/connect';

import {
  CreateSessionRequestSchema, CreateSessionResponseSchema, ListSessionsRequestSchema, ListSessionsResponseSchema,
  type ListSessionsResponse_Entry,
} from './gen/filigree/v1/filigree_pb';
import { frame, frameHeader, FrameReader, parseTrailers, TRAILER_FLAG } from './grpc-web';

// 512 KiB: a chunk's message stays under the smallest message limit a server
// may have (--max-message-mib 1).
export const CHUNK_BYTES = 512 << 10;

export interface Created { sessionId: string; editorToken: string; viewerToken: string; cached: boolean; vertexCount: number }

// 'sending': the body is on its way (fetch cannot tell how far); then the server's stages.
// secondsLeft: the server's estimate of the stage's time left (0: none yet).
export type Progress = { stage: 'sending'; bytes: number } | { stage: string; fraction: number; secondsLeft: number };

// The request body: begin, then the file's bytes in chunks, each a data
// frame. A Blob of slices: the file is not copied into memory here.
export function requestBody(file: Blob, format: string, clientName: string, chunkBytes = CHUNK_BYTES): Blob {
  const begin = toBinary(CreateSessionRequestSchema, create(CreateSessionRequestSchema, {
    kind: { case: 'begin', value: { format, totalBytes: BigInt(file.size), clientName } },
  }));
  const parts: BlobPart[] = [frame(begin) as BlobPart];
  for (let at = 0; at < file.size; at += chunkBytes) {
    const size = Math.min(chunkBytes, file.size - at);
    // CreateSessionRequest{chunk}: field 2, length-delimited: tag 0x12, varint length, the bytes.
    const tag = [0x12, ...varint(size)];
    parts.push(frameHeader(tag.length + size) as BlobPart, new Uint8Array(tag) as BlobPart, file.slice(at, at + size));
  }
  return new Blob(parts);
}

function varint(value: number): number[] {
  const out: number[] = [];
  while (value >= 0x80) {
    out.push((value & 0x7f) | 0x80);
    value = Math.floor(value / 128);
  }
  out.push(value);
  return out;
}

const grpcWebHeaders = (apiKey: string): Record<string, string> => ({
  'content-type': 'application/grpc-web+proto', 'x-grpc-web': '1', accept: 'application/grpc-web+proto',
  ...(apiKey ? { 'x-filigree-api-key': apiKey } : {}),
});

// Calls the gRPC-Web method and hands each data frame to `onMessage`;
// resolves after trailers with status OK, throws a ConnectError otherwise.
async function call(serverUrl: string, method: string, body: BodyInit, apiKey: string,
  onMessage: (payload: Uint8Array) => void, signal?: AbortSignal): Promise<void> {
  let response: Response;
  try {
    response = await fetch(`${serverUrl}/filigree.v1.Filigree/${method}`, {
      method: 'POST', headers: grpcWebHeaders(apiKey), body, signal,
    });
  } catch (error) {
    if (signal?.aborted) throw error;
    throw new ConnectError(`cannot reach ${serverUrl}`, Code.Unknown, undefined, undefined, error);
  }
  // A "trailers-only" answer: the status is in the headers.
  const headerStatus = response.headers.get('grpc-status');
  if (headerStatus !== null && headerStatus !== '0') {
    const { status, message } = parseTrailers(`grpc-status: ${headerStatus}\ngrpc-message: ${response.headers.get('grpc-message') ?? ''}`);
    throw new ConnectError(message, status as Code);
  }
  if (!response.ok || response.body === null) {
    throw new ConnectError(`HTTP ${response.status} ${response.statusText}`, response.status === 404 ? Code.Unimplemented : Code.Unavailable);
  }
  const reader = response.body.getReader();
  const frames = new FrameReader();
  let trailers: ReturnType<typeof parseTrailers> | null = headerStatus === '0' ? { status: 0, message: '' } : null;
  for (;;) {
    const { done, value } = await reader.read();
    if (done) break;
    for (const { flag, payload } of frames.push(value)) {
      if (flag & TRAILER_FLAG) trailers = parseTrailers(new TextDecoder().decode(payload));
      else onMessage(payload);
    }
  }
  if (trailers === null) throw new ConnectError('the answer ended without a status (the connection was cut)', Code.Unavailable);
  if (trailers.status !== 0) throw new ConnectError(trailers.message, trailers.status as Code);
}

// Uploads `file` as a new session; `onProgress` hears the stages.
export async function createSession(serverUrl: string, file: Blob, format: string, options: {
  apiKey?: string; clientName?: string; onProgress?: (progress: Progress) => void; signal?: AbortSignal;
} = {}): Promise<Created> {
  const body = requestBody(file, format, options.clientName ?? 'web');
  options.onProgress?.({ stage: 'sending', bytes: file.size });
  let created: Created | null = null;
  await call(serverUrl, 'CreateSession', body, options.apiKey ?? '', (payload) => {
    const message = fromBinary(CreateSessionResponseSchema, payload);
    if (message.kind.case === 'progress') {
      options.onProgress?.({
        stage: message.kind.value.stage, fraction: message.kind.value.fraction, secondsLeft: message.kind.value.secondsLeft,
      });
    } else if (message.kind.case === 'created') {
      const c = message.kind.value;
      created = {
        // info.rest may be a summary (inParts: a mesh too large for one
        // message); only its vertex count is read here, the page joins for the mesh.
        sessionId: c.info?.sessionId ?? '', editorToken: c.editorToken, viewerToken: c.viewerToken, cached: c.cached,
        vertexCount: c.info?.rest?.vertexCount ?? 0,
      };
    }
  }, options.signal);
  if (created === null) throw new ConnectError('the server answered without a session', Code.Internal);
  return created;
}

// The sessions this visitor may see (with an API key on a server with keys).
export async function listSessions(serverUrl: string, apiKey: string): Promise<ListSessionsResponse_Entry[]> {
  const sessions: ListSessionsResponse_Entry[] = [];
  const request = frame(toBinary(ListSessionsRequestSchema, create(ListSessionsRequestSchema, {})));
  await call(serverUrl, 'ListSessions', request as BodyInit, apiKey, (payload) => {
    sessions.push(...fromBinary(ListSessionsResponseSchema, payload).sessions);
  });
  return sessions;
}
