// The page's side of the session worker (decoder.worker.ts): joins through
// it, and feeds it the frames of the Watch stream one at a time, newest first
// (FrameMailbox: a frame that arrives while another is being worked on
// replaces the one waiting, a keyframe waits until taken). Finished buffers
// come back to `applied`; the page hands the set it replaced back (recycle).
import { Code, ConnectError } from '@connectrpc/connect';

import type { Frame } from './client';
import { isChunked, isKeyframe } from './frame';
import { FrameMailbox } from './mailbox';
import type { Buffers, CallError, FromWorker, ToWorker } from './pipeline-protocol';

export type Joined = Extract<FromWorker, { type: 'joined' }>;
export type Applied = Extract<FromWorker, { type: 'applied' }>;
export type Failed = Extract<FromWorker, { type: 'frameFailed' }>;
export type DrawableOverlays = Extract<FromWorker, { type: 'overlays' }>;

// A frame and the Watch stream it came on (streams are numbered from 1).
export interface Arrival { frame: Frame; stream: number }

export interface PipelineEvents {
  progress(stage: 'download' | 'build', loaded: number, total: number | null): void;
  applied(result: Applied, arrival: Arrival): void;
  failed(result: Failed, arrival: Arrival): void;
  // Superseded in the mailbox before the worker saw them.
  skipped(count: number): void;
  // The stretch colours of the frame drawn, after the overlay was turned on.
  colors(colors: Float32Array, stretchMax: number): void;
}

// A ConnectError again, from what the worker could post.
function rebuild(error: CallError): Error {
  if (error.code === null) return new Error(error.message);
  return new ConnectError(error.rawMessage, error.code as Code, undefined, undefined,
    error.fetchFailed ? new TypeError(error.message) : undefined);
}

export class FramePipeline {
  private readonly worker = new Worker(new URL('./decoder.worker.ts', import.meta.url), { type: 'module' });
  private readonly mailbox = new FrameMailbox<Arrival>(({ frame }) => isChunked(frame) && isKeyframe(frame));
  private inFlight: { id: number; arrival: Arrival } | null = null;
  private nextId = 1;
  private joinWaiter: { resolve(j: Joined): void; reject(e: Error): void } | null = null;
  private readonly overlayWaiters = new Map<number, { resolve(o: DrawableOverlays): void; reject(e: Error): void }>();

  constructor(private readonly events: PipelineEvents) {
    this.worker.onmessage = (event: MessageEvent<FromWorker>) => this.received(event.data);
    this.worker.onerror = (event) => {
      event.preventDefault();
      const error = new Error(`the session worker failed: ${event.message || 'it could not start'}`);
      this.joinWaiter?.reject(error);
      this.joinWaiter = null;
    };
  }

  join(serverUrl: string, sessionId: string, token: string): Promise<Joined> {
    return new Promise((resolve, reject) => {
      this.joinWaiter = { resolve, reject };
      this.send({ type: 'join', serverUrl, sessionId, token });
    });
  }

  // A frame off the Watch stream; returns at once.
  put(arrival: Arrival): void {
    const superseded = this.mailbox.put(arrival);
    if (superseded > 0) this.events.skipped(superseded);
    this.pump();
  }

  get hasKeyframe(): boolean {
    return this.mailbox.hasKeyframe;
  }

  // Frames relative to a lost keyframe: all of them.
  clear(): void {
    this.mailbox.clear();
  }

  // Buffers the page no longer draws from.
  recycle(buffers: Buffers): void {
    const transfer: Transferable[] = [buffers.positions.buffer, buffers.normals.buffer];
    if (buffers.colors) transfer.push(buffers.colors.buffer);
    this.send({ type: 'recycle', buffers }, transfer);
  }

  // GetOverlays, called and made drawable in the worker.
  overlays(): Promise<DrawableOverlays> {
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      this.overlayWaiters.set(id, { resolve, reject });
      this.send({ type: 'overlays', id });
    });
  }

  setStretch(on: boolean): void {
    this.send({ type: 'stretch', on });
  }

  // Whether a frame is being worked on or waits.
  get busy(): boolean {
    return this.inFlight !== null;
  }

  private pump(): void {
    if (this.inFlight !== null) return;
    const arrival = this.mailbox.take();
    if (arrival === null) return;
    const id = this.nextId++;
    this.inFlight = { id, arrival };
    const { frame } = arrival;
    // Copies: the message's bytes are views into the response's buffer.
    if (isChunked(frame)) {
      const chunks = frame.chunks.map((c) => ({
        firstVertex: c.firstVertex, vertexCount: c.vertexCount, runs: Uint32Array.from(c.runs), deltas: c.deltas.slice(),
      }));
      this.send({
        type: 'frame', id,
        chunked: { version: frame.version, keyframeVersion: frame.keyframeVersion, vertexCount: frame.vertexCount, chunks },
      }, chunks.flatMap((c) => [c.deltas.buffer, c.runs.buffer]));
    } else {
      const deltas = frame.deltas.slice();
      this.send({ type: 'frame', id, single: { version: frame.version, vertexCount: frame.vertexCount, deltas } },
        [deltas.buffer]);
    }
  }

  private received(message: FromWorker): void {
    switch (message.type) {
      case 'progress':
        this.events.progress(message.stage, message.loaded, message.total);
        break;
      case 'joined':
        this.joinWaiter?.resolve(message);
        this.joinWaiter = null;
        break;
      case 'overlays':
      case 'overlaysFailed': {
        const waiter = this.overlayWaiters.get(message.id);
        this.overlayWaiters.delete(message.id);
        if (message.type === 'overlays') waiter?.resolve(message);
        else waiter?.reject(rebuild(message.error));
        break;
      }
      case 'colors':
        this.events.colors(message.colors, message.stretchMax);
        break;
      case 'joinFailed':
        this.joinWaiter?.reject(rebuild(message.error));
        this.joinWaiter = null;
        break;
      case 'applied':
      case 'frameFailed': {
        const done = this.inFlight;
        if (done === null || done.id !== message.id) return;
        this.inFlight = null;
        if (message.type === 'applied') this.events.applied(message, done.arrival);
        else this.events.failed(message, done.arrival);
        this.pump();
        break;
      }
    }
  }

  private send(message: ToWorker, transfer: Transferable[] = []): void {
    this.worker.postMessage(message, transfer);
  }
}
