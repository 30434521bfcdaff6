// The viewer page: join the session named in the address, show its mesh,
// follow its frames, and the panel around it.
//
// The main thread does little per frame (DESIGN §3.6): the session worker
// (decoder.worker.ts through pipeline.ts) joins, decodes, applies deltas and
// computes normals and stretch colours; this thread reads the Watch stream,
// hands frames on (the newest first), swaps finished buffers into the
// geometry and draws on requestAnimationFrame when something changed.
// Streams are at a level of detail (detail-control.ts): the worker hands a
// new level's whole geometry over once, and this thread swaps it in.
import { ChangeLog } from './changes';
import { Code, describeError, isCode, SessionClient, type SessionInfo } from './client';
import { Role } from './gen/filigree/v1/filigree_pb';
import { HandleEditor, type EditMode } from './handles';
import { connectLines } from './connect';
import { DetailControl } from './detail-control';
import { FrontDoor, rememberedTokens, serverJson } from './front';
import { describeEntry, HistoryPanel, kindName } from './history';
import { FRAME_EVENT, hook } from './hook';
import { CutWireframe } from './overlay-cut';
import { OverlayFeed } from './overlay-feed';
import { RegionsOverlay } from './overlay-regions';
import { StretchOverlay } from './overlay-stretch';
import { BaseWireframe, type Overlay } from './overlays';
import { byId, fail, setNote, setStatus, showError, showOverlayToggles, showSession, showStats } from './panel';
import { readParams, tokenOutOfQuery, type ViewerParams } from './params';
import { participantColour, ParticipantsLayer } from './participants';
import {
  FramePipeline, type Applied, type Arrival, type DrawableOverlays, type Failed, type Joined, type LevelReady, type Ready,
} from './pipeline';
import type { LoadStage } from './pipeline-protocol';
import { pollPresence } from './presence';
import { PointerSender, PresenceLayer } from './presence-layer';
import { isFinal, lossReason, retryDelay } from './reconnect';
import { MeshView } from './scene';
import { StatsTracker, statsRows } from './stats';

// This page's name for SetHandles and SubmitPose (others see it in their
// change lists): unique per page, so that two pages' handles do not replace
// each other.
const CLIENT_NAME = `web-${Array.from(crypto.getRandomValues(new Uint8Array(3)), (b) => b.toString(16).padStart(2, '0')).join('')}`;
const RESYNC_MAX_MS = 10_000;

const megabytes = (bytes: number) => `${(bytes / 1e6).toFixed(1)} MB`;

// One session on this page: its mesh, its frame stream, its controls.
class Viewer {
  private readonly client: SessionClient;
  private readonly pipeline: FramePipeline;
  private readonly stats = new StatsTracker();
  private readonly changes = new ChangeLog(byId<HTMLOListElement>('changes'));
  private view!: MeshView;
  private overlays: Overlay[] = [];
  private readonly shown = new Set<Overlay>();
  private wireframe!: BaseWireframe;
  private cut!: CutWireframe;
  private regions!: RegionsOverlay;
  private stretch!: StretchOverlay;
  private feed!: OverlayFeed<DrawableOverlays>;
  private handles: HandleEditor | null = null;
  private participants!: ParticipantsLayer;
  private history!: HistoryPanel;
  private presence!: PresenceLayer;
  private detail!: DetailControl;
  // The full mesh's faces, stand-in and base ids (join): drawn again at full detail.
  private fullFaces: Uint32Array = new Uint32Array(0);
  private fullCoarse: Uint32Array | null = null;
  private baseIds: Uint32Array = new Uint32Array(0);
  private lastVersion = 0n;
  private lastNewFrameAt: number | null = null;  // when the newest version arrived
  private stream = 0;  // the current Watch stream's number
  private streamOpen = false;
  private resyncAsked = false;
  private resyncDelayMs = 0;
  private attempt = 0;                    // reconnect attempts since the stream was last open
  private downSince: number | null = null;
  private nextPoseId = 1n;
  private pendingPageMs = 0;              // this thread's time for frames since the last applied one
  private appliedVersion: bigint | null = null;  // swapped in, drawn at the next animation frame

  constructor(private readonly params: ViewerParams) {
    this.client = new SessionClient(params.serverUrl, params.sessionId, params.token);
    this.pipeline = new FramePipeline({
      opened: (stream) => { if (stream === this.stream) this.opened(); },
      arrived: (arrival) => { if (arrival.stream === this.stream) this.onFrame(arrival); },
      progress: (stage, loaded, total) => this.loading(stage, loaded, total),
      applied: (result) => this.applied(result),
      ready: (result) => this.ready(result),
      levelArrived: ({ stream, streamId, vertexCount }) => this.detail.levelArrived(stream, streamId, vertexCount),
      levelRead: ({ decodeMs }) => { hook.levelDecodeMs = decodeMs; },
      level: (result) => this.levelReady(result),
      failed: (result) => this.failed(result),
      skipped: (count) => {
        hook.framesSkipped += count;
        this.stats.frameSkipped(count);
      },
      colors: (colors, stretchMax) => {
        if (!this.shown.has(this.stretch)) return;
        this.stretch.setColors(colors, stretchMax);
        hook.stretchMax = stretchMax;
        this.view.invalidate();
      },
    });
  }

  async start(): Promise<void> {
    hook.state = 'joining';
    hook.sessionId = this.params.sessionId;
    setStatus(`Joining session ${this.params.sessionId}…`);
    this.loading('download', 0, null);
    let joined: Joined;
    try {
      joined = await this.pipeline.join(this.params.serverUrl, this.params.sessionId, this.params.token);
    } catch (error) {
      byId('loading').hidden = true;
      fail(describeError(error, this.params.sessionId, this.params.serverUrl));
      return;
    }
    this.show(joined);
    byId('loading').hidden = true;
    hook.loadStage = 'done';
    this.applyRole(joined.info.role);
    this.participants.refresh();
    this.history.refresh();
    void this.presence.start();
    void this.showShare();
    await this.follow();
  }

  // Progress while the session's mesh arrives and is built, over the canvas.
  private loading(stage: LoadStage, loaded: number, total: number | null): void {
    hook.loadStage = stage;
    if (!hook.loadStages.includes(stage)) hook.loadStages.push(stage);
    byId('loading').hidden = false;
    const bar = byId<HTMLProgressElement>('loading-progress');
    if (stage === 'receive') {
      // A mesh too large for one message, in parts: the share of its values received.
      const fraction = total ? loaded / total : 0;
      hook.receiveFraction = fraction;
      byId('loading-text').textContent = `Receiving the mesh: ${Math.floor(100 * fraction)} %…`;
      bar.max = 1;
      bar.value = fraction;
    } else if (stage === 'download') {
      byId('loading-text').textContent = loaded === 0 ? 'Asking for the session…'
        : `Downloading the mesh: ${megabytes(loaded)}${total ? ` of ${megabytes(total)}` : ''}…`;
      if (total) {
        bar.max = total;
        bar.value = loaded;
      } else {
        bar.removeAttribute('value');  // indeterminate
      }
    } else {
      byId('loading-text').textContent = 'Building the mesh (normals, framing)…';
      bar.removeAttribute('value');
    }
  }

  private show(joined: Joined): void {
    const { info, buffers, faces, framing } = joined;
    const vertexCount = buffers.positions.length / 3;  // as drawn (info.rest.vertexCount announced it)
    this.view = new MeshView(byId('view'), buffers.positions, buffers.normals, faces, framing, joined.coarseFaces !== null);
    this.view.setCoarse(joined.coarseFaces);
    this.fullFaces = faces;
    this.fullCoarse = joined.coarseFaces;
    this.baseIds = joined.originalIds;
    hook.coarseTriangles = joined.coarseFaces ? joined.coarseFaces.length / 3 : 0;
    this.view.onDrawn = (drawMs, at) => {
      this.stats.frameDrawn(this.appliedVersion, drawMs, at);
      hook.drawMsTotal += drawMs;
      ++hook.draws;
      if (this.appliedVersion !== null && Number(this.appliedVersion) !== hook.drawnVersion) {
        hook.drawnVersion = Number(this.appliedVersion);
        ++hook.framesDrawn;
      }
    };
    this.setupOverlays(joined);

    hook.clientName = CLIENT_NAME;
    hook.vertexCount = vertexCount;
    hook.baseVertexCount = joined.originalIds.length;
    hook.triangleCount = faces.length / 3;
    hook.meshRadius = this.view.radius;
    hook.restParts = joined.restParts;
    hook.upAxis = framing.upAxis;
    hook.joinMs = joined.joinMs;
    hook.buildMs = joined.buildMs;
    Object.defineProperties(hook, {
      framesRendered: { get: () => this.view.framesRendered, enumerable: true },
      coarseDraws: { get: () => this.view.coarseDraws, enumerable: true },
      lastDrawFull: { get: () => this.view.lastDrawFull, enumerable: true },
      pixelRatio: { get: () => this.view.pixelRatio, enumerable: true },
      drawShowMs: { get: () => this.view.drawShowMs, enumerable: true },
      roundTripMs: { get: () => this.stats.snapshot(performance.now()).roundTripMs, enumerable: true },
      editToDrawnMs: { get: () => this.stats.snapshot(performance.now()).editToDrawnMs, enumerable: true },
      handlesAnswered: { get: () => this.handles?.answered ?? 0, enumerable: true },
      handlesAcceptedAt: { get: () => Number(this.handles?.acceptedAt ?? 0n), enumerable: true },
      handlesSending: { get: () => this.handles?.sending ?? false, enumerable: true },
      pulledVertices: { get: () => this.handles?.pulledVertices ?? 0, enumerable: true },
    });
    hook.capture = () => this.view.capture();
    hook.screenPointOfVertex = (i) => this.view.vertexOnScreen(i);
    hook.nearestVertexToCamera = () => this.view.nearestVertexToCamera();
    hook.vertexAt = (x, y) => this.handles?.vertexAt(x, y) ?? null;
    hook.vertexPosition = (i) => {
      const p = this.view.positionOf(i);
      return p === null ? null : [p.x, p.y, p.z];
    };
    hook.screenExtent = () => this.view.screenExtent();
    hook.viewDirection = () => this.view.viewDirection();
    hook.statsSnapshot = () => {
      const s = this.stats.snapshot(performance.now());
      return { ...s, frame: null, drawnVersion: s.drawnVersion === null ? null : Number(s.drawnVersion) };
    };
    showSession(info, this.params.serverUrl, CLIENT_NAME, faces.length / 3, joined.originalIds.length);
    this.detail = new DetailControl(this.client, vertexCount, joined.originalIds.length, this.params.detail, {
      sample: () => {
        const now = performance.now();
        const s = this.stats.snapshot(now);
        return {
          now, lastArrivalAt: this.lastNewFrameAt, arrivedPerSecond: s.framesPerSecond, appliedPerSecond: s.appliedPerSecond,
          drawnPerSecond: s.drawnPerSecond, interacting: this.handles?.interacting ?? false,
        };
      },
      describe: (error) => this.describe(error),
    });
    this.setupEditing(joined);
    this.setupParticipants();
    this.setupHistory();
    this.setupPresence(joined);
    this.setupOptions(info);
    this.setupClips(info);
    this.setupViewControls();
    byId('round-trip').addEventListener('click', () => void this.timeRoundTrip(joined));
    window.setInterval(() => showStats(statsRows(this.stats.snapshot(performance.now()))), 250);
    byId('live').hidden = false;
  }

  // Fit (button, F), the panel (button, P; a drawer on narrow screens, Escape closes it).
  private setupViewControls(): void {
    const fit = () => {
      this.view.fit();
      ++hook.fits;
    };
    byId('fit').addEventListener('click', fit);
    const toggle = byId<HTMLButtonElement>('panel-toggle');
    const narrow = window.matchMedia('(max-width: 700px)');
    const panelShown = () => (narrow.matches ? document.body.classList.contains('panel-open')
      : !document.body.classList.contains('panel-collapsed'));
    const sync = () => toggle.setAttribute('aria-expanded', String(panelShown()));
    const setPanel = (show: boolean) => {
      if (narrow.matches) document.body.classList.toggle('panel-open', show);
      else document.body.classList.toggle('panel-collapsed', !show);
      sync();
    };
    toggle.addEventListener('click', () => setPanel(!panelShown()));
    narrow.addEventListener('change', sync);
    sync();
    window.addEventListener('keydown', (event) => {
      if (event.ctrlKey || event.metaKey || event.altKey) return;
      const target = event.target as HTMLElement;
      if (target.closest('input, select, textarea')) return;  // typing
      if (event.key === 'f' || event.key === 'F') fit();
      else if (event.key === 'p' || event.key === 'P') setPanel(!panelShown());
      else if (event.key === 'Escape' && narrow.matches) setPanel(false);
    });
  }

  // Editor controls only for the editor token: a viewer page shows none.
  // JoinSession says which token this is (ROLE_UNSPECIFIED from an older
  // server: the controls stay, and the server still refuses a viewer's edits).
  private applyRole(role: Role): void {
    const editor = role !== Role.VIEWER;
    hook.canEdit = editor;
    if (!editor) {
      document.body.classList.add('read-only');
      byId('read-only-note').hidden = false;
      this.handles?.detach();
      this.handles = null;
    }
  }

  // Share links (tokens in the fragment): the viewer's always when known,
  // the editor's on an editor's page; and how a program drives this session.
  private async showShare(): Promise<void> {
    const { sessionId, token, serverUrl } = this.params;
    const here = new URL(window.location.href);
    const viewerToken = hook.canEdit === false ? token
      : new URLSearchParams(here.hash.replace(/^#/, '')).get('viewer') ?? rememberedTokens(sessionId)?.viewerToken ?? '';
    const link = (t: string, viewer?: string) => {
      const url = new URL(here.href);
      const fragment = new URLSearchParams(url.hash.replace(/^#/, ''));
      fragment.set('token', t);
      fragment.delete('viewer');
      if (viewer) fragment.set('viewer', viewer);
      url.hash = fragment.toString();
      return url.href;
    };
    byId('share').hidden = false;
    byId('share-viewer-row').hidden = viewerToken === '';
    byId<HTMLInputElement>('share-viewer').value = viewerToken ? link(viewerToken) : '';
    byId<HTMLInputElement>('share-editor').value = hook.canEdit ? link(token, viewerToken || undefined) : '';
    for (const button of document.querySelectorAll<HTMLButtonElement>('#share button[data-copy]')) {
      button.addEventListener('click', () => {
        const input = byId<HTMLInputElement>(button.dataset.copy!);
        input.select();
        void navigator.clipboard?.writeText(input.value).then(() => { button.textContent = 'Copied'; }, () => {});
      });
    }
    if (!hook.canEdit) return;
    const server = await serverJson(serverUrl);
    if (server === null) return;
    const lines = connectLines(server, new URL(serverUrl).hostname, { id: sessionId, editorToken: token });
    byId('session-connect-cli').textContent = `# gRPC at ${lines.address}\n${lines.drive}`;
    byId('session-connect-python').textContent = lines.python;
  }

  private setupEditing(joined: Joined): void {
    this.handles = new HandleEditor(this.view, this.client, CLIENT_NAME, joined.originalIds, {
      status: (text, bad) => setNote('handles-status', text, bad),
      counts: (own, everyone) => {
        hook.handleCount = own;
        hook.handlesInSession = everyone;
        byId('handle-count').textContent = `${own === 0 ? 'No' : own} handle${own === 1 ? '' : 's'} of this page` +
          (everyone === null ? '.' : `; ${everyone} in the session.`);
      },
      describe: (error) => this.describe(error),
      sent: () => this.stats.poseSent(performance.now()),
      started: () => this.detail.nudge(),
    });
    byId('clear-handles').addEventListener('click', () => this.handles?.clear());
    const mode = byId<HTMLSelectElement>('edit-mode');
    const radius = byId<HTMLInputElement>('pull-radius');
    const radiusValue = byId('pull-radius-value');
    const apply = () => {
      if (!this.handles) return;
      this.handles.mode = mode.value as EditMode;
      // The slider is a percentage of the mesh's bounding radius.
      this.handles.radius = (radius.valueAsNumber / 100) * this.view.radius;
      radiusValue.textContent = `${radius.value} % of the mesh`;
      byId('pull-radius-label').hidden = mode.value !== 'pull';
      hook.editMode = this.handles.mode;
    };
    mode.addEventListener('change', apply);
    radius.addEventListener('input', apply);
    apply();
  }

  // Everyone else's handles, in their colours with their names, and the legend.
  private setupParticipants(): void {
    this.participants = new ParticipantsLayer(this.view, this.client, CLIENT_NAME, byId('participants'), {
      shown: (participants, version) => {
        hook.participants = participants.map((p) => ({ name: p.name, colour: p.colour, handles: p.handles.length }));
        hook.participantsAnswers = this.participants.answers;
        hook.participantsVersion = Number(version);
      },
      status: (text, bad) => setNote('participants-status', text, bad),
      describe: (error) => this.describe(error),
    });
    Object.defineProperty(hook, 'participantsFetching', { get: () => this.participants.fetching, enumerable: true });
    hook.otherHandles = () => this.participants.spheresOnPage();
    hook.participantColour = (name) => participantColour(name).css;
  }

  // Undo and redo (buttons; Ctrl+Z, Ctrl+Shift+Z and Ctrl+Y on editor
  // pages), the history list and the checkpoints.
  private setupHistory(): void {
    this.history = new HistoryPanel(this.client, CLIENT_NAME, {
      fetch: (newest) => this.pipeline.history(newest).then((lines) => {
        hook.history = lines.entries.map((e) => ({
          seq: e.seq, kind: kindName(e.kind), author: e.author, undone: e.undone, vertices: e.vertices,
          gestureId: e.gestureId.toString(), text: describeEntry(e, lines.checkpoints),
        }));
        hook.checkpoints = lines.checkpoints.map((c) => ({ id: Number(c.id), name: c.name, author: c.author }));
        return lines;
      }),
      describe: (error) => this.describe(error),
      changed: () => void this.adoptOwnHandles(),
      canEdit: () => hook.canEdit === true,
      meshSize: 2 * this.view.radius,
    }, byId('history'), byId('checkpoints'), byId('undo-status'), byId('history-status'), byId('checkpoint-status'));
    const history = this.history;
    Object.defineProperties(hook, {
      historyCalls: { get: () => history.calls, enumerable: true },
      historyAnswers: { get: () => history.answers, enumerable: true },
      historyMostInFlight: { get: () => history.mostInFlight, enumerable: true },
      historyFetching: { get: () => history.fetching, enumerable: true },
      undos: { get: () => history.undos, enumerable: true },
      undosPending: { get: () => history.pendingUndos, enumerable: true },
    });
    byId('undo').addEventListener('click', () => history.undo(false));
    byId('redo').addEventListener('click', () => history.undo(true));
    window.addEventListener('keydown', (event) => {
      if (!(event.ctrlKey || event.metaKey) || event.altKey) return;
      const key = event.key.toLowerCase();
      if (key !== 'z' && key !== 'y') return;
      if (hook.canEdit !== true) return;
      // A text field keeps its own undo.
      if ((event.target as HTMLElement).closest('input, textarea, [contenteditable]')) return;
      event.preventDefault();
      history.undo(key === 'y' || event.shiftKey);
    });
    const name = byId<HTMLInputElement>('checkpoint-name');
    byId<HTMLFormElement>('checkpoint-form').addEventListener('submit', async (event) => {
      event.preventDefault();
      const text = name.value.trim();
      if (text === '') return;
      if (await history.save(text)) name.value = '';
    });
  }

  // After this page's undo, redo or restore changed the session: its own
  // handles as the server has them now (an undo of a handle change moves them there).
  private async adoptOwnHandles(): Promise<void> {
    this.participants.refresh();
    if (!this.handles) return;
    try {
      const answer = await this.client.getHandles();
      this.handles?.adopt(answer.participants.find((p) => p.clientName === CLIENT_NAME)?.handles ?? []);
    } catch {
      // The legend says what GetHandles answers; the page keeps its own set meanwhile.
    }
  }

  // Who is here (WatchPresence), their dots and pointers, and this page's pointer for them.
  private setupPresence(joined: Joined): void {
    this.presence = new PresenceLayer(this.view, this.client, CLIENT_NAME, joined.originalIds, byId('presence-list'), {
      shown: (participants) => {
        hook.presence = participants.map((p) => ({
          name: p.name, colour: p.colour, role: p.role, you: p.you, touching: p.touchingCount, handles: p.handles,
          pointerVertex: p.pointer?.vertex ?? null,
        }));
        hook.presenceFirst = this.presence.firstNames;
      },
      status: (text, bad) => setNote('presence-status', text, bad),
      describe: (error) => this.describe(error),
    });
    const presence = this.presence;
    Object.defineProperties(hook, {
      presenceMessages: { get: () => presence.messages, enumerable: true },
      presenceStreams: { get: () => presence.streams, enumerable: true },
    });
    hook.touchMarkers = () => presence.markerCounts();
    const show = byId<HTMLInputElement>('show-activity');
    show.addEventListener('change', () => presence.setVisible(show.checked));
    hook.otherPointers = () => presence.pointersOnPage();
    const pointer = new PointerSender(this.view, this.client, CLIENT_NAME,
      (error) => setNote('presence-status', `Your pointer is not shared: ${this.describe(error)}`, true));
    Object.defineProperties(hook, {
      pointerCalls: { get: () => pointer.calls, enumerable: true },
      pointerVertex: { get: () => pointer.lastVertex, enumerable: true },
    });
  }

  // The base wireframe comes from the frames, the stretch map from the
  // worker; the cut and the regions from GetOverlays, polled while one of them is shown.
  private setupOverlays(joined: Joined): void {
    const wireframe = new BaseWireframe(joined.basePositions, joined.baseFaces, joined.originalIds);
    this.wireframe = wireframe;
    this.cut = new CutWireframe(this.view.geometry);
    this.regions = new RegionsOverlay(this.view.geometry);
    this.stretch = new StretchOverlay(this.view.geometry, (on) => this.pipeline.setStretch(on));
    for (const overlay of [this.regions, this.stretch, this.cut, wireframe]) this.view.add(overlay.object);
    this.overlays = [wireframe, this.cut, this.regions, this.stretch];
    this.feed = new OverlayFeed(() => this.pipeline.overlays(), (overlays) => this.showServerOverlays(overlays),
      (error) => setNote('overlays-status', this.describe(error), true));
    showOverlayToggles(this.overlays, (overlay, visible) => {
      if (visible) this.shown.add(overlay);
      else this.shown.delete(overlay);
      this.feed.setWanted([...this.shown].some((o) => o.fromServer));
      if (!this.shown.has(this.stretch)) hook.stretchMax = 0;
      if (overlay === wireframe && visible) wireframe.update(this.view.positions);
      this.view.invalidate();
    });
  }

  private showServerOverlays(overlays: DrawableOverlays): void {
    if (overlays.vertexCount !== this.view.vertexCount) {
      // Built for the level drawn before a swap: ask again for this one.
      this.feed.frameArrived();
      return;
    }
    this.cut.setCut(overlays.cutEdges, overlays.refined, overlays.cutTriangles, overlays.refinedTriangles);
    this.regions.setRegions(overlays.regionColors, overlays.regionEdges);
    hook.regionCount = overlays.regionCount;
    hook.overlaysVersion = Number(overlays.version);
    hook.cutTriangles = this.cut.triangleCount;
    setNote('overlays-status', `Frame ${overlays.version}: ${overlays.regionCount} ` +
      `region${overlays.regionCount === 1 ? '' : 's'}, a cut mesh of ${this.cut.triangleCount} triangles ` +
      `(${overlays.refinedTriangles} at full detail).`);
    this.view.invalidate();
  }

  private describe(error: unknown): string {
    return describeError(error, this.params.sessionId, this.params.serverUrl);
  }

  // Follows the session until it is gone or the token is refused. A stream
  // that breaks or ends without being asked to (a server restart, a cut
  // connection) is opened again with backoff (reconnect.ts), from the last
  // version seen: the server then sends the current frame, its keyframe
  // first. After a lost keyframe (resync) the stream is reopened from
  // version 0 at once: the server sends the current frame again, keyframe first.
  private async follow(): Promise<void> {
    for (;;) {
      const stream = ++this.stream;
      hook.watchStreams = stream;
      this.streamOpen = false;
      // A stream at another level than the one drawn sends that level's
      // keyframe only with a newer frame: from version 0, the current one comes at once.
      const afterVersion = this.resyncAsked || !this.detail.levelKept ? 0n : this.lastVersion;
      this.resyncAsked = false;
      if (this.attempt > 0) setStatus(`Reconnecting (attempt ${this.attempt})…`);
      this.detail.streamOpening(stream);
      const end = await this.pipeline.watch(stream, afterVersion, this.detail.budget);
      if (end.aborted) {
        // resync(): again at once the first time, then backing off, in
        // case the server's keyframe itself cannot be decoded here.
        ++hook.resyncs;
        const delay = this.resyncDelayMs;
        this.resyncDelayMs = Math.min(Math.max(2 * delay, 500), RESYNC_MAX_MS);
        setStatus('Asking the server for a keyframe again…');
        if (delay > 0) await new Promise((resolve) => window.setTimeout(resolve, delay));
        continue;
      }
      const ended = end.error;
      if (ended !== null && isFinal(ended)) {
        if (isCode(ended, Code.NotFound) && this.lastVersion > 0n) {
          hook.state = 'closed';
          setStatus('The session was closed.');
          showError(this.describe(ended));
        } else {
          fail(this.describe(ended));
        }
        return;
      }
      await this.backOff(ended);
    }
  }

  // The stream is open (the server answered): live again.
  private opened(): void {
    if (this.streamOpen) return;
    this.streamOpen = true;
    if (this.attempt > 0) {
      ++hook.reconnects;
      this.participants.refresh();  // handles may have changed meanwhile (or the server restarted)
      this.history.refresh();
    }
    this.attempt = 0;
    this.downSince = null;
    hook.state = 'live';
    setStatus('Live.');
  }

  // Waits before the next attempt, saying why and for how long; "Retry now" and the browser going online cut it short.
  private async backOff(ended: unknown): Promise<void> {
    const now = performance.now();
    this.downSince ??= now;
    ++this.attempt;
    const delay = retryDelay(this.attempt, now - this.downSince);
    hook.state = 'reconnecting';
    hook.lastLoss = lossReason(ended);
    const status = byId('status');
    const retry = document.createElement('button');
    retry.type = 'button';
    retry.id = 'retry-now';
    retry.textContent = 'Retry now';
    status.replaceChildren(`Connection lost (${hook.lastLoss}). Reconnecting in ${(delay / 1000).toFixed(1)} s ` +
      `(attempt ${this.attempt})…`, retry);
    await new Promise<void>((resolve) => {
      const done = () => {
        window.clearTimeout(timer);
        window.removeEventListener('online', done);
        resolve();
      };
      const timer = window.setTimeout(done, delay);
      window.addEventListener('online', done);
      retry.addEventListener('click', done);
    });
  }

  // The keyframe the next frames are relative to was lost (it could not be
  // decoded, or never came): reopen the Watch, unless a newer keyframe waits.
  private resync(): void {
    if (this.resyncAsked) return;
    this.resyncAsked = true;
    this.pipeline.clear();  // relative to the lost keyframe, all of them
    this.pipeline.stopWatch(this.stream);
  }

  // A frame the worker read off the stream (and applies): the panel's part.
  private onFrame(arrival: Arrival): void {
    const start = performance.now();
    const { frame } = arrival;
    this.stats.frameArrived(frame, start, arrival.bytes);
    ++hook.framesReceived;
    // Frames sent again (a level switch or a resync sends the current frame,
    // its keyframe first) are no new changes.
    if (frame.version > this.lastVersion) {
      this.lastVersion = frame.version;
      this.lastNewFrameAt = start;
      hook.lastNewFrameAt = start;
      this.changes.add(frame);
      this.participants.frameArrived(frame);
      if (frame.changes.length > 0) this.history.refresh();
    }
    hook.newestVersion = Number(this.lastVersion);
    this.feed.frameArrived();
    if (hook.framesReceived === 1) {
      // From the first frame on, the count includes this page's own Watch.
      pollPresence(() => this.client.entry(), (text) => { byId('presence').textContent = text; }, (e) => this.describe(e));
    }
    this.pendingPageMs += performance.now() - start;
  }

  // A frame applied in the worker: counted (drawing may skip it).
  private applied(result: Applied): void {
    ++hook.framesApplied;
    const { decodeMs, applyMs } = result;
    this.stats.frameApplied({ decodeMs, applyMs, normalsMs: 0, stretchMs: 0 }, this.pendingPageMs, performance.now());
    hook.pageMsTotal += this.pendingPageMs;
    this.pendingPageMs = 0;
  }

  // The newest applied state, to draw at the next animation frame.
  private ready(result: Ready): void {
    const start = performance.now();
    const old = this.view.setBuffers(result.buffers.positions, result.buffers.normals);
    let oldColors: Float32Array | null = null;
    if (result.buffers.colors !== null) {
      if (this.shown.has(this.stretch)) {
        oldColors = this.stretch.setColors(result.buffers.colors, result.stretchMax);
        hook.stretchMax = result.stretchMax;
      } else {
        oldColors = result.buffers.colors;
      }
    }
    this.pipeline.recycle({ ...old, colors: oldColors });
    this.drawn(result, start);
  }

  // A new level of detail with its first frame: its geometry swapped in
  // whole (one short task: the worker built it; three.js uploads it at the
  // next draw), the overlays rebound to it. The old buffers are not handed
  // back: the worker has a set of the new size.
  private levelReady(result: LevelReady): void {
    const start = performance.now();
    const full = result.faces === null;
    const faces = result.faces ?? this.fullFaces;
    this.view.setLevel(result.buffers.positions, result.buffers.normals, faces, full ? this.fullCoarse : result.coarseFaces,
      result.ids);
    this.wireframe.setLevel(full ? this.baseIds : result.baseIndex);
    this.cut.rebind();
    this.regions.rebind();
    const colors = result.buffers.colors;
    this.stretch.rebind();
    if (colors !== null && this.shown.has(this.stretch)) {
      this.stretch.setColors(colors, result.stretchMax);
      hook.stretchMax = result.stretchMax;
    }
    this.feed.frameArrived();  // the cut and the regions again, for this level (while shown)
    hook.vertexCount = result.vertexCount;
    hook.triangleCount = faces.length / 3;
    hook.coarseTriangles = ((full ? this.fullCoarse : result.coarseFaces)?.length ?? 0) / 3;
    hook.framesAtLevel = 0;
    this.detail.levelShown(result.vertexCount, result.ids);
    hook.levelSwapMs = performance.now() - start;
    hook.levelSwapMsMax = Math.max(hook.levelSwapMsMax, hook.levelSwapMs);
    this.drawn(result, start);
  }

  // After a state was swapped in: what the panel and the hook show of it.
  private drawn(result: Ready | LevelReady, start: number): void {
    for (const overlay of this.overlays) if (overlay.id === 'base' && this.shown.has(overlay)) overlay.update(this.view.positions);
    this.presence.meshMoved();
    ++hook.framesAtLevel;
    hook.maxError = result.maxError;
    this.appliedVersion = result.version;
    this.resyncDelayMs = 0;
    hook.version = Number(result.version);
    hook.displacement = result.displacement;
    hook.frameKind = result.kind;
    if (result.kind === 'sparse') ++hook.framesSparse;
    const { decodeMs, applyMs, normalsMs, stretchMs } = result;
    this.stats.frameReady({ decodeMs, applyMs, normalsMs, stretchMs });
    const pageMs = performance.now() - start;
    this.stats.pageTime(pageMs, performance.now());
    hook.pageMsTotal += pageMs;
    window.dispatchEvent(new Event(FRAME_EVENT));
  }

  private failed(result: Failed): void {
    // One bad frame is reported; the next good one repairs the view (a
    // sparse frame is whole against its keyframe), unless the next ones
    // need the keyframe that failed or never came: then it is asked again.
    showError(result.version === 0n ? `The level of detail could not be shown: ${result.message}`
      : `Frame ${result.version} could not be shown: ${result.message}`);
    if (result.resync && result.stream === this.stream) this.resync();
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
            : this.describe(error), true);
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
        const updated = await this.client.setOptions(value, wholeMesh.checked, CLIENT_NAME);
        this.history.refresh();
        const t = updated.options?.wholeMesh ? '∞ (whole mesh)' : String(updated.options?.threshold ?? value);
        setNote('options-status', `T is now ${t}.`);
      } catch (error) {
        setNote('options-status', isCode(error, Code.PermissionDenied)
          ? 'Changing the threshold needs the editor token; this page was opened with another token.'
          : this.describe(error), true);
      }
    });
  }

  // Submits the current merged pose unchanged (so nothing moves) and times
  // the frame that includes it: SubmitPose → first frame of a larger version, arrived and drawn.
  private async timeRoundTrip(joined: Joined): Promise<void> {
    try {
      const state = await this.client.getState();
      // Before anything was driven the merged pose may be empty: the rest base.
      const pose = state.pose.length > 0 ? state.pose : Array.from(joined.basePositions);
      setNote('round-trip-status', 'Waiting for the frame…');
      const accepted = this.stats.poseSent(performance.now());
      accepted(await this.client.submitPose(this.nextPoseId++, pose, CLIENT_NAME));
      setNote('round-trip-status', 'Pose accepted; the times show under “own edit → frame” and “→ drawn”.');
    } catch (error) {
      setNote('round-trip-status', isCode(error, Code.PermissionDenied)
        ? 'Submitting a pose needs the editor token; this page was opened with another token.'
        : this.describe(error), true);
    }
  }
}

// Starts the viewer for the page's address.
function openSession(): void {
  const result = readParams(window.location.search, window.location.origin, window.location.hash);
  if (result.kind === 'usage') {
    hook.state = 'usage';
    setStatus('No session named.');
    // The front door; a session made there opens in this page, no reload.
    void new FrontDoor(window.location.origin, (href) => {
      window.history.pushState(null, '', href);
      document.body.classList.remove('front');
      byId('front').hidden = true;
      openSession();
    }).start();
    return;
  }
  if (result.kind === 'error') {
    fail(result.message);
    askForToken();
    return;
  }
  // A token in the query is moved to the fragment: reloads and bookmarks then keep it off the wire.
  const moved = tokenOutOfQuery(window.location.href);
  if (moved !== null) window.history.replaceState(null, '', moved);
  new Viewer(result.params).start().catch((error: unknown) => {
    fail(error instanceof Error ? `${error.name}: ${error.message}` : String(error));
  });
}

// A session named without a token (a link from the session list): ask for one.
function askForToken(): void {
  const form = byId<HTMLFormElement>('token-form');
  form.hidden = false;
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    const token = byId<HTMLInputElement>('token-input').value.trim();
    if (token === '') return;
    const url = new URL(window.location.href);
    const fragment = new URLSearchParams(url.hash.replace(/^#/, ''));
    fragment.set('token', token);
    url.hash = fragment.toString();
    window.location.replace(url.href);
    window.location.reload();
  });
}

// Back from a session opened by the front door: show the address's page afresh.
window.addEventListener('popstate', () => window.location.reload());

openSession();
