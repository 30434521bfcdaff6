// The viewer page: join the session named in the address, show its mesh,
// follow its frames, and the panel around it.
import { ChangeLog } from './changes';
import { Code, describeError, isCode, SessionClient, type Frame, type SessionInfo } from './client';
import { DeltaDecoder } from './decoder';
import { applyDeltas, FrameError } from './frame';
import { FRAME_EVENT, hook } from './hook';
import { BaseWireframe, pendingOverlays, type Overlay } from './overlays';
import { byId, fail, setNote, setStatus, showError, showOverlayToggles, showSession, showStats } from './panel';
import { readParams, type ViewerParams } from './params';
import { MeshView } from './scene';
import { StatsTracker, statsRows } from './stats';

const CLIENT_NAME = 'web-viewer';
const RECONNECT_MIN_MS = 500;
const RECONNECT_MAX_MS = 10_000;

// One session on this page: its mesh, its frame stream, its controls.
class Viewer {
  private readonly client: SessionClient;
  private readonly decoder = new DeltaDecoder();
  private readonly stats = new StatsTracker();
  private readonly changes = new ChangeLog(byId<HTMLOListElement>('changes'));
  private readonly abort = new AbortController();
  private view!: MeshView;
  private rest!: Float32Array;
  private baseRest: number[] = [];
  private overlays: Overlay[] = [];
  private lastVersion = 0n;
  private waiting: Frame | null = null;  // the newest frame not yet applied
  private applying = false;
  private nextPoseId = 1n;

  constructor(private readonly params: ViewerParams) {
    this.client = new SessionClient(params.serverUrl, params.sessionId, params.token);
  }

  async start(): Promise<void> {
    hook.state = 'joining';
    hook.sessionId = this.params.sessionId;
    setStatus(`Joining session ${this.params.sessionId}…`);
    let info: SessionInfo;
    try {
      info = await this.client.join();
    } catch (error) {
      fail(describeError(error, this.params.sessionId, this.params.serverUrl));
      return;
    }
    this.show(info);
    await this.follow();
  }

  private show(info: SessionInfo): void {
    const rest = info.rest!;
    this.rest = Float32Array.from(rest.positions);
    this.view = new MeshView(byId('view'), this.rest, Uint32Array.from(rest.faces));
    const base = info.base!;
    this.baseRest = base.positions;
    const wireframe = new BaseWireframe(base.positions, base.faces, Uint32Array.from(base.originalIds));
    this.view.add(wireframe.object);
    this.overlays = [wireframe, ...pendingOverlays()];
    showOverlayToggles(this.overlays, () => this.view.invalidate());

    hook.vertexCount = rest.vertexCount;
    hook.baseVertexCount = base.positions.length / 3;
    Object.defineProperties(hook, {
      framesRendered: { get: () => this.view.framesRendered, enumerable: true },
      roundTripMs: { get: () => this.stats.snapshot(performance.now()).roundTripMs, enumerable: true },
    });
    hook.capture = () => this.view.capture();
    showSession(info, this.params.serverUrl);
    this.setupOptions(info);
    byId('round-trip').addEventListener('click', () => void this.timeRoundTrip());
    window.setInterval(() => showStats(statsRows(this.stats.snapshot(performance.now()))), 250);
    byId('live').hidden = false;
  }

  // Watch until the session closes; reconnect (from the last version seen)
  // while the server is unavailable, stop on any other error.
  private async follow(): Promise<void> {
    let backoff = RECONNECT_MIN_MS;
    for (;;) {
      try {
        hook.state = 'live';
        setStatus('Live.');
        for await (const frame of this.client.watch(this.lastVersion, this.abort.signal)) {
          backoff = RECONNECT_MIN_MS;
          this.onFrame(frame);
        }
        hook.state = 'closed';
        setStatus('The session was closed.');
        return;
      } catch (error) {
        if (!isCode(error, Code.Unavailable)) {
          fail(describeError(error, this.params.sessionId, this.params.serverUrl));
          return;
        }
        hook.state = 'reconnecting';
        setStatus(`Server unavailable, reconnecting in ${(backoff / 1000).toFixed(1)} s…`);
        await new Promise((resolve) => window.setTimeout(resolve, backoff));
        backoff = Math.min(2 * backoff, RECONNECT_MAX_MS);
      }
    }
  }

  // Reads the stream as fast as it delivers: a frame that arrives while
  // another is being decoded replaces the one waiting (a mailbox of one, like
  // the server's), so a slow page skips frames instead of falling behind.
  private onFrame(frame: Frame): void {
    this.stats.frameArrived(frame, performance.now());
    ++hook.framesReceived;
    this.lastVersion = frame.version;
    this.changes.add(frame);
    if (this.waiting !== null) {
      ++hook.framesSkipped;
      this.stats.frameSkipped();
    }
    this.waiting = frame;
    if (!this.applying) void this.applyWaiting();
  }

  private async applyWaiting(): Promise<void> {
    this.applying = true;
    while (this.waiting !== null) {
      const frame = this.waiting;
      this.waiting = null;
      await this.apply(frame);
    }
    this.applying = false;
  }

  private async apply(frame: Frame): Promise<void> {
    try {
      if (frame.vertexCount !== hook.vertexCount) {
        throw new FrameError(`a frame of ${frame.vertexCount} vertices for a mesh of ${hook.vertexCount}`);
      }
      if (frame.deltas.length === 0) {
        this.view.positions.set(this.rest);  // every delta is 0: the rest mesh
      } else {
        const { deltas, decodeMs } = await this.decoder.decode(frame.deltas, frame.vertexCount);
        applyDeltas(this.rest, deltas, this.view.positions);
        this.stats.frameDecoded(decodeMs);
      }
    } catch (error) {
      // One bad frame is reported; the next good one repairs the view.
      showError(`Frame ${frame.version} could not be shown: ${error instanceof Error ? error.message : error}`);
      return;
    }
    this.view.positionsChanged();
    for (const overlay of this.overlays) overlay.update(this.view.positions);
    hook.version = Number(frame.version);
    hook.displacement = frame.deltas.length === 0 ? 0
      : Math.max(Math.abs(frame.deltaMin), Math.abs(frame.deltaMin + frame.deltaRange));
    ++hook.framesApplied;
    window.dispatchEvent(new Event(FRAME_EVENT));
  }

  private setupOptions(info: SessionInfo): void {
    const threshold = byId<HTMLInputElement>('threshold');
    const wholeMesh = byId<HTMLInputElement>('whole-mesh');
    threshold.value = String(info.options?.threshold ?? 0);
    wholeMesh.checked = info.options?.wholeMesh ?? false;
    byId<HTMLFormElement>('options').addEventListener('submit', async (event) => {
      event.preventDefault();
      const value = threshold.valueAsNumber;
      if (!Number.isFinite(value) || value < 0) {
        setNote('options-status', 'T is a number ≥ 0.', true);
        return;
      }
      setNote('options-status', 'Applying…');
      try {
        const updated = await this.client.setOptions(value, wholeMesh.checked);
        const t = updated.options?.wholeMesh ? '∞ (whole mesh)' : String(updated.options?.threshold ?? value);
        setNote('options-status', `T is now ${t}.`);
      } catch (error) {
        setNote('options-status', isCode(error, Code.PermissionDenied)
          ? 'Changing the threshold needs the editor token; this page was opened with another token.'
          : describeError(error, this.params.sessionId, this.params.serverUrl), true);
      }
    });
  }

  // Submits the current merged pose unchanged (so nothing moves) and times
  // the frame that includes it: SubmitPose → first frame of a larger version.
  private async timeRoundTrip(): Promise<void> {
    try {
      const state = await this.client.getState();
      // Before anything was driven the merged pose may be empty: the rest base.
      const pose = state.pose.length > 0 ? state.pose : this.baseRest;
      setNote('round-trip-status', 'Waiting for the frame…');
      const accepted = this.stats.poseSent(performance.now());
      accepted(await this.client.submitPose(this.nextPoseId++, pose, CLIENT_NAME));
      setNote('round-trip-status', 'Pose accepted; the time shows under “own pose → frame”.');
    } catch (error) {
      setNote('round-trip-status', isCode(error, Code.PermissionDenied)
        ? 'Submitting a pose needs the editor token; this page was opened with another token.'
        : describeError(error, this.params.sessionId, this.params.serverUrl), true);
    }
  }
}

function main(): void {
  const result = readParams(window.location.search, window.location.origin);
  if (result.kind === 'usage') {
    hook.state = 'usage';
    setStatus('No session named.');
    byId('usage').hidden = false;
    return;
  }
  if (result.kind === 'error') {
    fail(result.message);
    byId('usage').hidden = false;
    return;
  }
  new Viewer(result.params).start().catch((error: unknown) => {
    fail(error instanceof Error ? `${error.name}: ${error.message}` : String(error));
  });
}

main();
