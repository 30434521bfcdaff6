// Frame statistics for the panel: what the client measures (rate, arrival
// interval, round trip of its own poses, bytes, decode time) next to what the
// server reports per frame (Frame.stats).
import type { Frame } from './client';
import { isChunked, isKeyframe } from './frame';

const WINDOW_MS = 2000;  // rates and means are over the last two seconds

export interface StatsSnapshot {
  framesPerSecond: number;
  lastIntervalMs: number | null;    // between the last two frame arrivals
  meanIntervalMs: number | null;    // over the window
  roundTripMs: number | null;       // own SubmitPose → the frame that includes it
  bytesPerFrame: number;            // the delta bytes of the last frame (frameBytes)
  bytesPerVertex: number;
  decodeMs: number | null;          // in the worker, last frame
  framesSkipped: number;            // superseded before they were decoded (a slow page)
  frame: Frame | null;              // the last frame, for its stats and version
}

export class StatsTracker {
  private arrivals: number[] = [];  // arrival times within the window
  private lastInterval: number | null = null;
  private lastArrival: number | null = null;
  private roundTrip: number | null = null;
  private decodeMs: number | null = null;
  private skipped = 0;
  private last: Frame | null = null;
  // The own pose being timed (the newest one sent): the version it was
  // accepted at (unset until SubmitPose answers) and the frames that arrived
  // since it was sent, since a frame can overtake the SubmitPose answer.
  private timed: { sentAt: number; acceptedAt?: bigint; arrivals: { version: bigint; at: number }[] } | null = null;

  frameArrived(frame: Frame, now: number): void {
    this.last = frame;
    if (this.lastArrival !== null) this.lastInterval = now - this.lastArrival;
    this.lastArrival = now;
    this.arrivals.push(now);
    while (this.arrivals.length > 0 && this.arrivals[0] < now - WINDOW_MS) this.arrivals.shift();
    this.timed?.arrivals.push({ version: frame.version, at: now });
    this.settle();
  }

  frameDecoded(decodeMs: number): void {
    this.decodeMs = decodeMs;
  }

  frameSkipped(): void {
    ++this.skipped;
  }

  // Call when an own pose is sent; give the returned function the version
  // SubmitPose answered with.
  poseSent(now: number): (acceptedAt: bigint) => void {
    const timed: NonNullable<StatsTracker['timed']> = { sentAt: now, arrivals: [] };
    this.timed = timed;
    return (acceptedAt) => {
      timed.acceptedAt = acceptedAt;
      if (this.timed === timed) this.settle();
    };
  }

  // The frame that includes the pose is the first with a larger version.
  private settle(): void {
    const timed = this.timed;
    if (timed?.acceptedAt === undefined) return;
    const hit = timed.arrivals.find((a) => a.version > timed.acceptedAt!);
    if (!hit) return;
    this.roundTrip = hit.at - timed.sentAt;
    this.timed = null;
  }

  snapshot(now: number): StatsSnapshot {
    const inWindow = this.arrivals.filter((t) => t >= now - WINDOW_MS);
    const n = this.arrivals.length;
    const bytes = this.last ? frameBytes(this.last) : 0;
    return {
      framesPerSecond: inWindow.length / (WINDOW_MS / 1000),
      lastIntervalMs: this.lastInterval,
      meanIntervalMs: n >= 2 ? (this.arrivals[n - 1] - this.arrivals[0]) / (n - 1) : null,
      roundTripMs: this.roundTrip,
      bytesPerFrame: bytes,
      bytesPerVertex: this.last && this.last.vertexCount > 0 ? bytes / this.last.vertexCount : 0,
      decodeMs: this.decodeMs,
      framesSkipped: this.skipped,
      frame: this.last,
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
  const threshold = st ? (st.threshold === Infinity ? '∞ (whole mesh)' : String(st.threshold)) : '–';
  return [
    ['version', f ? String(f.version) : '–'],
    ['frames/s', s.framesPerSecond.toFixed(1)],
    ['arrival interval', s.lastIntervalMs == null ? '–' : `${ms(s.lastIntervalMs)} (mean ${ms(s.meanIntervalMs)})`],
    ['own pose → frame', ms(s.roundTripMs)],
    ['bytes/frame', f ? `${s.bytesPerFrame} (${s.bytesPerVertex.toFixed(2)} B/vertex)` : '–'],
    ['frame', f ? frameKind(f) : '–'],
    ['quantization', f ? quantization(f) : '–'],
    ['T', threshold],
    ['regions', st ? `${st.regions} (largest ${st.largestRegion}, ${st.regionVertices} vertices)` : '–'],
    ['cut nodes', st ? String(st.cutNodes) : '–'],
    ['server compute', st ? `${ms(st.computeMs)} (rotations ${ms(st.rotationsMs)}, cut ${ms(st.cutUpdateMs)}, ` +
      `recover ${ms(st.recoverMs)}, regions ${ms(st.regionsMs)})` : '–'],
    ['server encode', st ? ms(st.encodeMs) : '–'],
    ['decode (worker)', ms(s.decodeMs)],
    ['frames skipped', String(s.framesSkipped)],
  ];
}
