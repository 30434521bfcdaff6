// Frame statistics for the panel. What the page measures: frames arrived,
// applied (finished by the session worker and handed to the GPU) and drawn
// per second, how many versions the drawing is behind the newest arrival, the
// time from this page's own edits to the frame that includes them arriving
// and being drawn, the worker's and the page's own time per frame and the
// draw's; next to what the server reports per frame (Frame.stats).
// Statistics count what was drawn, not what arrived (DESIGN §3.6).
import type { Frame } from './client';
import { isChunked, isKeyframe } from './frame';

const WINDOW_MS = 2000;  // rates and means are over the last two seconds

// Times of events within the window.
class Rate {
  private times: number[] = [];

  add(now: number): void {
    this.times.push(now);
    this.trim(now);
  }

  perSecond(now: number): number {
    this.trim(now);
    return this.times.length / (WINDOW_MS / 1000);
  }

  get list(): readonly number[] {
    return this.times;
  }

  private trim(now: number): void {
    let drop = 0;
    while (drop < this.times.length && this.times[drop] < now - WINDOW_MS) ++drop;
    if (drop > 0) this.times.splice(0, drop);
  }
}

// Values with their times, for a mean over the window.
class Mean {
  private values: { at: number; value: number }[] = [];

  add(value: number, now: number): void {
    this.values.push({ at: now, value });
    while (this.values.length > 0 && this.values[0].at < now - WINDOW_MS) this.values.shift();
  }

  get(): number | null {
    if (this.values.length === 0) return null;
    return this.sum() / this.values.length;
  }

  sum(): number {
    return this.values.reduce((s, v) => s + v.value, 0);
  }
}

export interface WorkerTimes { decodeMs: number; applyMs: number; normalsMs: number; stretchMs: number }

export interface StatsSnapshot {
  framesPerSecond: number;          // arrived
  appliedPerSecond: number;
  drawnPerSecond: number;
  lastIntervalMs: number | null;    // between the last two frame arrivals
  meanIntervalMs: number | null;    // over the window
  behind: number;                   // newest version arrived − version drawn
  roundTripMs: number | null;       // own edit → the frame that includes it arrives
  editToDrawnMs: number | null;     // own edit → that frame (or a newer one) drawn
  bytesPerFrame: number;            // the delta bytes of the last frame (frameBytes)
  bytesPerVertex: number;
  decodeMs: number | null;          // in the worker, last frame
  worker: WorkerTimes | null;       // the worker's stages, last frame
  pageMs: number | null;            // the page's own JavaScript per applied frame (over the window)
  drawMs: number | null;            // uploads and draw call per drawn frame (mean)
  framesSkipped: number;            // superseded before the worker saw them (a slow page)
  frame: Frame | null;              // the last frame arrived, for its stats and version
  drawnVersion: bigint | null;
}

// One own edit being timed: when it was sent, the version it was accepted at
// (unset until the call answers), the frames that arrived since it was sent
// (a frame can overtake the answer).
interface Timed { sentAt: number; acceptedAt?: bigint; arrivals: { version: bigint; at: number }[]; arrived: boolean }

const MAX_TIMED = 16;

export class StatsTracker {
  private readonly arrivals = new Rate();
  private readonly applied = new Rate();
  private readonly drawn = new Rate();
  private readonly pageMs = new Mean();
  private readonly drawMs = new Mean();
  private lastInterval: number | null = null;
  private lastArrival: number | null = null;
  private roundTrip: number | null = null;
  private toDrawn: number | null = null;
  private decodeMs: number | null = null;
  private worker: WorkerTimes | null = null;
  private skipped = 0;
  private last: Frame | null = null;
  private lastBytes = 0;
  private newestArrived: bigint | null = null;
  private drawnVersion: bigint | null = null;
  private timed: Timed[] = [];

  // `bytes`: its delta bytes, when the frame's own were left out (the worker keeps them).
  frameArrived(frame: Frame, now: number, bytes = frameBytes(frame)): void {
    this.last = frame;
    this.lastBytes = bytes;
    if (this.newestArrived === null || frame.version > this.newestArrived) this.newestArrived = frame.version;
    if (this.lastArrival !== null) this.lastInterval = now - this.lastArrival;
    this.lastArrival = now;
    this.arrivals.add(now);
    for (const t of this.timed) if (!t.arrived) t.arrivals.push({ version: frame.version, at: now });
    this.settle();
  }

  frameDecoded(decodeMs: number): void {
    this.decodeMs = decodeMs;
  }

  // A frame the worker applied; `pageMs`: the page's own JavaScript for the
  // frames since the last one (receiving them off the stream, handing them on).
  frameApplied(times: WorkerTimes, pageMs: number, now: number): void {
    this.decodeMs = times.decodeMs;
    this.applied.add(now);
    this.pageMs.add(pageMs, now);
  }

  // The state handed to the page for drawing, with the worker's stage times.
  frameReady(times: WorkerTimes): void {
    this.worker = times;
  }

  // The page's own time for swapping a state in, counted with the applied frames' time.
  pageTime(pageMs: number, now: number): void {
    this.pageMs.add(pageMs, now);
  }

  // A draw showing `version`; drawMs: the draw's uploads and draw call.
  frameDrawn(version: bigint | null, drawMs: number, now: number): void {
    this.drawMs.add(drawMs, now);
    if (version === null || (this.drawnVersion !== null && version <= this.drawnVersion)) return;  // a redraw (orbit, overlay)
    this.drawnVersion = version;
    this.drawn.add(now);
    // Own edits accepted before this version are now on screen.
    this.timed = this.timed.filter((t) => {
      if (t.acceptedAt === undefined || version <= t.acceptedAt) return true;
      this.toDrawn = now - t.sentAt;
      return false;
    });
  }

  frameSkipped(count = 1): void {
    this.skipped += count;
  }

  // Call when an own edit (a pose, handles) is sent; give the returned
  // function the version the call answered with.
  poseSent(now: number): (acceptedAt: bigint) => void {
    const timed: Timed = { sentAt: now, arrivals: [], arrived: false };
    this.timed.push(timed);
    if (this.timed.length > MAX_TIMED) this.timed.shift();
    return (acceptedAt) => {
      timed.acceptedAt = acceptedAt;
      this.settle();
    };
  }

  // The frame that includes an edit is the first with a larger version.
  private settle(): void {
    for (const t of this.timed) {
      if (t.arrived || t.acceptedAt === undefined) continue;
      const hit = t.arrivals.find((a) => a.version > t.acceptedAt!);
      if (!hit) continue;
      this.roundTrip = hit.at - t.sentAt;
      t.arrived = true;
      t.arrivals = [];
    }
  }

  snapshot(now: number): StatsSnapshot {
    // Trimmed to the window first: the list is trimmed in place.
    const framesPerSecond = this.arrivals.perSecond(now);
    const times = this.arrivals.list;
    const n = times.length;
    const bytes = this.last ? this.lastBytes : 0;
    const behind = this.newestArrived === null ? 0
      : Number(this.newestArrived - (this.drawnVersion ?? 0n));
    return {
      framesPerSecond,
      appliedPerSecond: this.applied.perSecond(now),
      drawnPerSecond: this.drawn.perSecond(now),
      lastIntervalMs: this.lastInterval,
      meanIntervalMs: n >= 2 ? (times[n - 1] - times[0]) / (n - 1) : null,
      behind: Math.max(0, behind),
      roundTripMs: this.roundTrip,
      editToDrawnMs: this.toDrawn,
      bytesPerFrame: bytes,
      bytesPerVertex: this.last && this.last.vertexCount > 0 ? bytes / this.last.vertexCount : 0,
      decodeMs: this.decodeMs,
      worker: this.worker,
      pageMs: this.applied.list.length > 0 ? this.pageMs.sum() / this.applied.list.length : null,
      drawMs: this.drawMs.get(),
      framesSkipped: this.skipped,
      frame: this.last,
      drawnVersion: this.drawnVersion,
    };
  }
}

const ms = (v: number | null | undefined) => (v == null ? '–' : `${v.toFixed(1)} ms`);

// A frame's delta bytes as the server counts them (FrameStats.encoded_bytes):
// the single buffer, or the chunks' buffers and 4 bytes per run.
export function frameBytes(frame: Frame): number {
  let bytes = frame.deltas.length;
  for (const chunk of frame.chunks) bytes += chunk.deltas.length + 4 * chunk.runs.length;
  return bytes;
}

// "single", "keyframe, 3 chunks", "sparse on keyframe 12: 420 of 1839 vertices in 1 chunk".
function frameKind(f: Frame): string {
  if (!isChunked(f)) return 'single';
  const chunks = `${f.chunks.length} chunk${f.chunks.length === 1 ? '' : 's'}`;
  if (isKeyframe(f)) return `keyframe, ${chunks}`;
  let present = 0;
  for (const chunk of f.chunks) {
    if (chunk.runs.length === 0) present += chunk.vertexCount;
    for (let r = 1; r < chunk.runs.length; r += 2) present += chunk.runs[r];
  }
  return `sparse on keyframe ${f.keyframeVersion}: ${present} of ${f.vertexCount} vertices in ${chunks}`;
}

// Chunks carry their own bits: their range.
function quantization(f: Frame): string {
  let bits = `${f.quantizationBits} bits`;
  if (f.chunks.length > 0) {
    const all = f.chunks.map((chunk) => chunk.quantizationBits);
    const [low, high] = [Math.min(...all), Math.max(...all)];
    bits = low === high ? `${low} bits` : `${low}–${high} bits`;
  }
  return `${bits}, max error ${f.maxError.toExponential(2)}`;
}

// The rows of the panel: [label, value].
export function statsRows(s: StatsSnapshot): [string, string][] {
  const f = s.frame;
  const st = f?.stats;
  const w = s.worker;
  const threshold = st ? (st.threshold === Infinity ? '∞ (whole mesh)' : String(st.threshold)) : '–';
  return [
    ['version', s.drawnVersion === null ? (f ? String(f.version) : '–') : String(s.drawnVersion)],
    ['frames/s', `${s.framesPerSecond.toFixed(1)} arrived, ${s.appliedPerSecond.toFixed(1)} applied, ` +
      `${s.drawnPerSecond.toFixed(1)} drawn`],
    ['behind by', `${s.behind} version${s.behind === 1 ? '' : 's'}`],
    ['arrival interval', s.lastIntervalMs == null ? '–' : `${ms(s.lastIntervalMs)} (mean ${ms(s.meanIntervalMs)})`],
    ['own edit → frame', ms(s.roundTripMs)],
    ['own edit → drawn', ms(s.editToDrawnMs)],
    ['bytes/frame', f ? `${s.bytesPerFrame} (${s.bytesPerVertex.toFixed(2)} B/vertex)` : '–'],
    ['frame', f ? frameKind(f) : '–'],
    ['quantization', f ? quantization(f) : '–'],
    ['T', threshold],
    ['regions', st ? `${st.regions} (largest ${st.largestRegion}, ${st.regionVertices} vertices)` : '–'],
    ['cut nodes', st ? String(st.cutNodes) : '–'],
    ['server compute', st ? `${ms(st.computeMs)} (rotations ${ms(st.rotationsMs)}, cut ${ms(st.cutUpdateMs)}, ` +
      `recover ${ms(st.recoverMs)}, regions ${ms(st.regionsMs)})` : '–'],
    ['server encode', st ? ms(st.encodeMs) : '–'],
    ['worker', w ? `decode ${ms(w.decodeMs)}, apply ${ms(w.applyMs)}, normals ${ms(w.normalsMs)}` +
      (w.stretchMs > 0 ? `, stretch ${ms(w.stretchMs)}` : '') : '–'],
    ['page JS/frame', ms(s.pageMs)],
    ['draw', ms(s.drawMs)],
    ['frames skipped', String(s.framesSkipped)],
  ];
}
