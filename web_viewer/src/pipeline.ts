// The page's side of the session worker (decoder.worker.ts): joins through
// it and has it read the Watch stream (the worker applies every frame,
// skipping to the newest when it falls behind; the page gets what its panel
// shows of each), and receives the state to draw whenever the page has a
// buffer set free; the page hands the set it replaced back (recycle), which
// lets the worker send the next one.
import { Code, ConnectError } from '@connectrpc/connect';

import type { Frame } from './client';
import type { Buffers, CallError, FromWorker, HistoryLines, LoadStage, ToWorker } from './pipeline-protocol';

export type Joined = Extract<FromWorker, { type: 'joined' }>;
export type Applied = Extract<FromWorker, { type: 'applied' }>;
export type Ready = Extract<FromWorker, { type: 'ready' }>;
export type LevelReady = Extract<FromWorker, { type: 'level' }>;
export type LevelArrived = Extract<FromWorker, { type: 'levelArrived' }>;
export type LevelRead = Extract<FromWorker, { type: 'levelRead' }>;
export type Failed = Extract<FromWorker, { type: 'frameFailed' }>;
export type DrawableOverlays = Extract<FromWorker, { type: 'overlays' }>;

// A frame (its delta bytes emptied; `bytes` counts them) and the Watch stream it came on (numbered from 1).
export interface Arrival { frame: Frame; stream: number; bytes: number }

// How a Watch stream ended: OK (error null), with an error, or stopped by the page.
export interface StreamEnd { error: Error | null; aborted: boolean }

export interface PipelineEvents {
  opened(stream: number): void;
  arrived(arrival: Arrival): void;
  progress(stage: LoadStage, loaded: number, total: number | null): void;
  // A frame applied in the worker (not drawn yet).
  applied(result: Applied): void;
  // The state to draw.
  ready(result: Ready): void;
  // A level announced on a stream (read off it, before its frames are applied).
  levelArrived(arrival: LevelArrived): void;
  levelRead(read: LevelRead): void;
  // A new level to draw, with its first frame.
  level(result: LevelReady): void;
  failed(result: Failed): void;
  // Superseded in the worker's mailbox before it applied them.
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
  private nextId = 1;
  private joinWaiter: { resolve(j: Joined): void; reject(e: Error): void } | null = null;
  private readonly streamWaiters = new Map<number, (end: StreamEnd) => void>();
  private readonly overlayWaiters = new Map<number, { resolve(o: DrawableOverlays): void; reject(e: Error): void }>();
  private readonly historyWaiters = new Map<number, { resolve(h: HistoryLines): void; reject(e: Error): void }>();

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

  // Follows the session on Watch stream `stream` from after `afterVersion`
  // (the worker reads it), at a level of detail of at most `maxVertices`
  // (0: full detail, no switching); resolves when that stream ends.
  watch(stream: number, afterVersion: bigint, maxVertices = 0): Promise<StreamEnd> {
    return new Promise((resolve) => {
      this.streamWaiters.set(stream, resolve);
      this.send({ type: 'watch', stream, afterVersion, maxVertices });
    });
  }

  stopWatch(stream: number): void {
    this.send({ type: 'stopWatch', stream });
  }

  // Frames relative to a lost keyframe: all those waiting.
  clear(): void {
    this.send({ type: 'clear' });
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

  // GetHistory of the newest `newest` entries, called, parsed and summarised in the worker.
  history(newest: number): Promise<HistoryLines> {
    const id = this.nextId++;
    return new Promise((resolve, reject) => {
      this.historyWaiters.set(id, { resolve, reject });
      this.send({ type: 'history', id, newest });
    });
  }

  setStretch(on: boolean): void {
    this.send({ type: 'stretch', on });
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
      case 'history':
      case 'historyFailed': {
        const waiter = this.historyWaiters.get(message.id);
        this.historyWaiters.delete(message.id);
        if (message.type === 'history') waiter?.resolve(message.history);
        else waiter?.reject(rebuild(message.error));
        break;
      }
      case 'streamOpened':
        this.events.opened(message.stream);
        break;
      case 'frameArrived':
        this.events.arrived({ frame: message.frame, stream: message.stream, bytes: message.bytes });
        break;
      case 'streamEnded': {
        const waiter = this.streamWaiters.get(message.stream);
        this.streamWaiters.delete(message.stream);
        waiter?.({ error: message.error ? rebuild(message.error) : null, aborted: message.aborted });
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
        if (message.skipped > 0) this.events.skipped(message.skipped);
        else this.events.applied(message);
        break;
      case 'ready':
        this.events.ready(message);
        break;
      case 'levelArrived':
        this.events.levelArrived(message);
        break;
      case 'levelRead':
        this.events.levelRead(message);
        break;
      case 'level':
        this.events.level(message);
        break;
      case 'frameFailed':
        this.events.failed(message);
        break;
    }
  }

  private send(message: ToWorker, transfer: Transferable[] = []): void {
    this.worker.postMessage(message, transfer);
  }
}
