// The viewer page: join the session named in the address, show its mesh,
// follow its frames, and the panel around it.
import type * as THREE from 'three';

import { ChangeLog } from './changes';
import { Code, describeError, isCode, SessionClient, type Frame, type Overlays, type SessionInfo } from './client';
import { DeltaDecoder } from './decoder';
import { applyDeltaRanges, applyDeltas, FrameError, isChunked, isKeyframe, KeyedDeltas, largestDelta } from './frame';
import { HandleEditor } from './handles';
import { FRAME_EVENT, hook } from './hook';
import { FrameMailbox } from './mailbox';
import { CutWireframe } from './overlay-cut';
import { OverlayFeed } from './overlay-feed';
import { RegionsOverlay } from './overlay-regions';
import { StretchOverlay } from './overlay-stretch';
import { BaseWireframe, type Overlay } from './overlays';
import { byId, fail, setNote, setStatus, showError, showOverlayToggles, showSession, showStats } from './panel';
import { readParams, type ViewerParams } from './params';
import { pollPresence } from './presence';
import { MeshView } from './scene';
import { StatsTracker, statsRows } from './stats';

// This page's name for SetHandles and SubmitPose (others see it in their
// change lists): unique per page, so that two pages' handles do not replace
// each other.
const CLIENT_NAME = `web-${Array.from(crypto.getRandomValues(new Uint8Array(3)), (b) => b.toString(16).padStart(2, '0')).join('')}`;
const RECONNECT_MIN_MS = 500;
const RECONNECT_MAX_MS = 10_000;

// A frame and the Watch stream it came on (streams are numbered from 1).
interface Arrival { frame: Frame; stream: number }

// One session on this page: its mesh, its frame stream, its controls.
class Viewer {
  private readonly client: SessionClient;
  private readonly decoder = new DeltaDecoder();
  private readonly stats = new StatsTracker();
  private readonly changes = new ChangeLog(byId<HTMLOListElement>('changes'));
  private view!: MeshView;
  private rest!: Float32Array;
  private baseRest: number[] = [];
  private overlays: Overlay[] = [];
  private readonly shown = new Set<Overlay>();
  private cut!: CutWireframe;
  private regions!: RegionsOverlay;
  private stretch!: StretchOverlay;
  private feed!: OverlayFeed;
  private handles!: HandleEditor;
  private lastVersion = 0n;
  // The frames not yet applied: the newest one, and the keyframe it needs.
  private readonly mailbox = new FrameMailbox<Arrival>(({ frame }) => isChunked(frame) && isKeyframe(frame));
  private applying = false;
  private keyed!: KeyedDeltas;  // the chunked stream's keyframe and current deltas
  // view.positions = rest + keyed.deltas. False after a single-format frame:
  // the next chunked one then rewrites every vertex, not only what it changed.
  private positionsFollowKeyed = true;
  private stream = { number: 0, abort: new AbortController() };  // the current Watch
  private resyncAsked = false;
  private resyncDelayMs = 0;
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
    this.keyed = new KeyedDeltas(rest.vertexCount);
    const faces = Uint32Array.from(rest.faces);
    this.view = new MeshView(byId('view'), this.rest, faces);
    const base = info.base!;
    this.baseRest = base.positions;
    this.setupOverlays(base.positions, base.faces, Uint32Array.from(base.originalIds), faces);
    this.handles = new HandleEditor(this.view, this.client, CLIENT_NAME, {
      status: (text, bad) => setNote('handles-status', text, bad),
      counts: (own, everyone) => {
        hook.handleCount = own;
        hook.handlesInSession = everyone;
        byId('handle-count').textContent = `${own === 0 ? 'No' : own} handle${own === 1 ? '' : 's'} of this page` +
          (everyone === null ? '.' : `; ${everyone} in the session.`);
      },
      describe: (error) => this.describe(error),
    });
    byId('clear-handles').addEventListener('click', () => this.handles.clear());

    hook.clientName = CLIENT_NAME;
    hook.vertexCount = rest.vertexCount;
    hook.baseVertexCount = base.positions.length / 3;
    Object.defineProperties(hook, {
      framesRendered: { get: () => this.view.framesRendered, enumerable: true },
      roundTripMs: { get: () => this.stats.snapshot(performance.now()).roundTripMs, enumerable: true },
      handlesAnswered: { get: () => this.handles.answered, enumerable: true },
      handlesAcceptedAt: { get: () => Number(this.handles.acceptedAt), enumerable: true },
      handlesSending: { get: () => this.handles.sending, enumerable: true },
    });
    hook.capture = () => this.view.capture();
    hook.screenPointOfVertex = (i) => this.view.vertexOnScreen(i);
    hook.nearestVertexToCamera = () => this.view.nearestVertexToCamera();
    hook.vertexAt = (x, y) => this.handles.vertexAt(x, y);
    showSession(info, this.params.serverUrl, CLIENT_NAME);
    this.setupOptions(info);
    this.setupClips(info);
    byId('round-trip').addEventListener('click', () => void this.timeRoundTrip());
    window.setInterval(() => showStats(statsRows(this.stats.snapshot(performance.now()))), 250);
    byId('live').hidden = false;
  }

  // The base wireframe and the stretch map come from the frames; the cut and
  // the regions from GetOverlays, polled while one of them is shown.
  private setupOverlays(basePositions: number[], baseFaces: number[], originalIds: Uint32Array, faces: Uint32Array): void {
    const wireframe = new BaseWireframe(basePositions, baseFaces, originalIds);
    this.cut = new CutWireframe(this.view.positions);
    this.regions = new RegionsOverlay(this.view.geometry);
    this.stretch = new StretchOverlay(this.rest, faces, this.view.positions,
      this.view.geometry.getAttribute('normal') as THREE.BufferAttribute);
    for (const overlay of [this.regions, this.stretch, this.cut, wireframe]) this.view.add(overlay.object);
    this.overlays = [wireframe, this.cut, this.regions, this.stretch];
    this.feed = new OverlayFeed(() => this.client.getOverlays(), (overlays) => this.showServerOverlays(overlays),
      (error) => setNote('overlays-status', this.describe(error), true));
    showOverlayToggles(this.overlays, (overlay, visible) => {
      if (visible) this.shown.add(overlay);
      else this.shown.delete(overlay);
      this.feed.setWanted([...this.shown].some((o) => o.fromServer));
      hook.stretchMax = this.shown.has(this.stretch) ? this.stretch.maxDeviation : 0;
      this.view.invalidate();
    });
  }

  private showServerOverlays(overlays: Overlays): void {
    this.cut.setFaces(overlays.cutFaces);
    this.regions.setRegions(overlays.regionOf);
    hook.regionCount = overlays.regionCount;
    hook.overlaysVersion = Number(overlays.version);
    hook.cutTriangles = this.cut.triangleCount;
    setNote('overlays-status', `Frame ${overlays.version}: ${overlays.regionCount} ` +
      `region${overlays.regionCount === 1 ? '' : 's'}, a cut mesh of ${this.cut.triangleCount} triangles.`);
    this.view.invalidate();
  }

  private describe(error: unknown): string {
    return describeError(error, this.params.sessionId, this.params.serverUrl);
  }

  // Watch until the session closes; reconnect (from the last version seen)
  // while the server is unavailable, stop on any other error. After a lost
  // keyframe (resync) the stream is reopened from version 0: the server sends
  // the current frame again, its keyframe first.
  private async follow(): Promise<void> {
    let backoff = RECONNECT_MIN_MS;
    for (;;) {
      const stream = { number: this.stream.number + 1, abort: new AbortController() };
      this.stream = stream;
      const afterVersion = this.resyncAsked ? 0n : this.lastVersion;
      this.resyncAsked = false;
      try {
        hook.state = 'live';
        setStatus('Live.');
        for await (const frame of this.client.watch(afterVersion, stream.abort.signal)) {
          backoff = RECONNECT_MIN_MS;
          this.onFrame({ frame, stream: stream.number });
        }
        hook.state = 'closed';
        setStatus('The session was closed.');
        return;
      } catch (error) {
        if (stream.abort.signal.aborted) {
          // resync(): again at once the first time, then backing off, in
          // case the server's keyframe itself cannot be decoded here.
          ++hook.resyncs;
          const delay = this.resyncDelayMs;
          this.resyncDelayMs = Math.min(Math.max(2 * delay, RECONNECT_MIN_MS), RECONNECT_MAX_MS);
          setStatus('Asking the server for a keyframe again…');
          if (delay > 0) await new Promise((resolve) => window.setTimeout(resolve, delay));
          continue;
        }
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

  // The keyframe the next frames are relative to was lost (it could not be
  // decoded, or never came): reopen the Watch, unless a newer keyframe waits.
  private resync(): void {
    if (this.resyncAsked || this.mailbox.hasKeyframe) return;
    this.resyncAsked = true;
    this.mailbox.clear();  // relative to the lost keyframe, all of them
    this.stream.abort.abort();
  }

  // Reads the stream as fast as it delivers: a frame that arrives while
  // another is being decoded replaces the one waiting (FrameMailbox: a
  // keyframe waits until applied), so a slow page skips frames instead of
  // falling behind.
  private onFrame(arrival: Arrival): void {
    const { frame } = arrival;
    this.stats.frameArrived(frame, performance.now());
    ++hook.framesReceived;
    this.lastVersion = frame.version;
    this.changes.add(frame);
    this.feed.frameArrived();
    if (hook.framesReceived === 1) {
      // From the first frame on, the count includes this page's own Watch.
      pollPresence(() => this.client.entry(), (text) => { byId('presence').textContent = text; }, (e) => this.describe(e));
    }
    for (let superseded = this.mailbox.put(arrival); superseded > 0; --superseded) {
      ++hook.framesSkipped;
      this.stats.frameSkipped();
    }
    if (!this.applying) void this.applyWaiting();
  }

  private async applyWaiting(): Promise<void> {
    this.applying = true;
    for (let next = this.mailbox.take(); next !== null; next = this.mailbox.take()) await this.apply(next);
    this.applying = false;
  }

  private async apply({ frame, stream }: Arrival): Promise<void> {
    const chunked = isChunked(frame);
    try {
      if (frame.vertexCount !== hook.vertexCount) {
        throw new FrameError(`a frame of ${frame.vertexCount} vertices for a mesh of ${hook.vertexCount}`);
      }
      if (chunked) await this.applyChunked(frame);
      else await this.applySingle(frame);
    } catch (error) {
      // One bad frame is reported; the next good one repairs the view (a
      // sparse frame is whole against its keyframe), unless the next ones
      // need the keyframe that failed or never came: then it is asked again.
      showError(`Frame ${frame.version} could not be shown: ${error instanceof Error ? error.message : error}`);
      if (chunked && stream === this.stream.number &&
        (isKeyframe(frame) || frame.keyframeVersion !== this.keyed.keyframeVersion)) this.resync();
      return;
    }
    this.view.positionsChanged();
    for (const overlay of this.overlays) overlay.update(this.view.positions);
    if (this.shown.has(this.stretch)) hook.stretchMax = this.stretch.maxDeviation;
    hook.version = Number(frame.version);
    hook.frameKind = !chunked ? 'single' : isKeyframe(frame) ? 'keyframe' : 'sparse';
    if (hook.frameKind === 'sparse') ++hook.framesSparse;
    ++hook.framesApplied;
    window.dispatchEvent(new Event(FRAME_EVENT));
  }

  // FRAME_FORMAT_SINGLE (a server without chunked frames): one buffer of every vertex.
  private async applySingle(frame: Frame): Promise<void> {
    if (frame.deltas.length === 0) {
      this.view.positions.set(this.rest);  // every delta is 0: the rest mesh
      hook.displacement = 0;
    } else {
      const { deltas, decodeMs } = await this.decoder.decode(frame.deltas, frame.vertexCount);
      applyDeltas(this.rest, deltas, this.view.positions);
      this.stats.frameDecoded(decodeMs);
      hook.displacement = Math.max(Math.abs(frame.deltaMin), Math.abs(frame.deltaMin + frame.deltaRange));
    }
    this.positionsFollowKeyed = false;
  }

  // FRAME_FORMAT_CHUNKED: the chunks decode in the workers; the keyframe
  // state is here, and only the vertex ranges that changed are rewritten.
  private async applyChunked(frame: Frame): Promise<void> {
    const present = this.keyed.check(frame);  // before decoding: a frame that cannot apply costs nothing
    const { values, decodeMs } = await this.decoder.decodeChunks(frame.chunks, present);
    const changed = this.keyed.apply(frame, values);
    if (this.positionsFollowKeyed) applyDeltaRanges(this.rest, this.keyed.deltas, this.view.positions, changed);
    else applyDeltas(this.rest, this.keyed.deltas, this.view.positions);
    this.positionsFollowKeyed = true;
    this.resyncDelayMs = 0;
    this.stats.frameDecoded(decodeMs);
    // Of the decoded deltas: a sparse frame's quantization ranges say nothing
    // of the vertices it leaves out. One pass, cheaper than the normals' after it.
    hook.displacement = largestDelta(this.keyed.deltas);
  }

  // Clips of a skinned upload: played by the server (PlayClip); the frames
  // show through this page's Watch stream like anyone's, so the clip stream
  // is only drained and counted here.
  private setupClips(info: SessionInfo): void {
    const clips = info.skeleton?.clips ?? [];
    hook.clips = clips.map((c) => c.name);
    if (clips.length === 0) return;
    byId('clips-section').hidden = false;
    const select = byId<HTMLSelectElement>('clip');
    select.replaceChildren(...clips.map((c) => {
      const option = document.createElement('option');
      option.value = c.name;
      option.textContent = `${c.name} (${c.durationSeconds.toFixed(2)} s)`;
      return option;
    }));
    let playing: AbortController | null = null;
    byId('clip-stop').addEventListener('click', () => {
      playing?.abort();
    });
    byId<HTMLFormElement>('clips').addEventListener('submit', async (event) => {
      event.preventDefault();
      playing?.abort();
      const controller = new AbortController();
      playing = controller;
      const name = select.value;
      hook.clipState = 'playing';
      hook.clipFrames = 0;
      setNote('clip-status', `Playing ${name}…`);
      try {
        const stream = this.client.playClip(name, byId<HTMLInputElement>('clip-loop').checked, CLIENT_NAME, controller.signal);
        for await (const _frame of stream) ++hook.clipFrames;
        hook.clipState = 'done';
        setNote('clip-status', `Played ${name} (${hook.clipFrames} frames).`);
      } catch (error) {
        if (controller.signal.aborted) {
          hook.clipState = 'stopped';
          setNote('clip-status', `Stopped ${name}.`);
        } else {
          hook.clipState = 'error';
          setNote('clip-status', isCode(error, Code.PermissionDenied)
            ? 'Playing a clip needs the editor token; this page was opened with another token.'
            : describeError(error, this.params.sessionId, this.params.serverUrl), true);
        }
      } finally {
        if (playing === controller) playing = null;
      }
    });
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
