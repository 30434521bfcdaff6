// Which level of detail the page asks for (levels.ts): the panel's choice
// (Auto, a level, Full) and the address's `detail=`, and Auto's policy. Pure:
// the page's DetailControl (detail-control.ts) calls these.
//
// Auto, on a mesh of over AUTO_ABOVE vertices: a coarse level while frames
// stream (BUSY_BUDGET to start), coarser while the page does not keep up with
// them (the worker applies fewer than arrive, or fewer are drawn), one step
// finer after a while of keeping up, and full detail once the session rests
// (no new frame for IDLE_MS). Smaller meshes stay at full detail unless the
// address names a starting budget (`detail=auto:N`).
import { levelVerticesFor } from './levels';

export const AUTO_ABOVE = 200_000;
export const BUSY_BUDGET = 65_536;
export const MIN_BUDGET = 16_384;
export const IDLE_MS = 1500;
// After a switch, the statistics (2 s windows) describe the old level for a while.
export const SETTLE_MS = 2500;
// Keeping up this long at a level before trying the next finer one.
export const REFINE_AFTER_MS = 6000;
// A level given up for not keeping up is not tried again for this long.
export const BLOCK_MS = 30_000;
// Judged only while at least this many frames arrive per second.
const MIN_RATE = 3;

export type DetailChoice =
  | { mode: 'auto'; start: number | null }   // start: the busy budget (null: the default for the mesh)
  | { mode: 'full' }
  | { mode: 'fixed'; budget: number };

// `detail=` of the address: auto (the default), auto:N, full, or a budget N ≥ 1.
export function parseDetail(text: string | undefined): DetailChoice | { error: string } {
  const t = (text ?? '').trim().toLowerCase();
  if (t === '' || t === 'auto') return { mode: 'auto', start: null };
  if (t === 'full') return { mode: 'full' };
  const auto = /^auto:(\d+)$/.exec(t);
  if (auto && Number(auto[1]) >= 1) return { mode: 'auto', start: Number(auto[1]) };
  if (/^\d+$/.test(t) && Number(t) >= 1) return { mode: 'fixed', budget: Number(t) };
  return { error: `detail=${text} is not auto, auto:N, full or a number of vertices; using auto.` };
}

// "Detail: 65,536 of 1,000,000 vertices".
export function detailLabel(levelVertices: number, fullVertices: number): string {
  const f = (x: number) => x.toLocaleString('en-US');
  return `Detail: ${f(levelVertices)} of ${f(fullVertices)} vertices`;
}

// The levels the panel offers between the base and the full mesh: powers of
// two above the base's count and below the mesh's, at most the `most`
// largest, ascending (Full comes apart).
export function levelChoices(fullVertices: number, baseVertices: number, most = 8): number[] {
  const out: number[] = [];
  for (let p = 2 ** Math.ceil(Math.log2(Math.max(2, baseVertices + 1))); p < fullVertices; p *= 2) out.push(p);
  return out.slice(-most);
}

// What Auto sees each tick.
export interface DetailSample {
  now: number;
  lastArrivalAt: number | null;  // the newest frame's arrival (null: none yet)
  arrivedPerSecond: number;
  appliedPerSecond: number;
  drawnPerSecond: number;
  interacting: boolean;          // a pull or a handle drag in progress
}

export type AutoReason = 'start' | 'idle' | 'busy' | 'behind' | 'keeping up';

// Auto's policy: the budget to ask for, from what the page manages.
export class AutoDetail {
  private busyBudget: number;
  private readonly floor: number;
  private readonly adapts: boolean;
  private wanted: number;
  private lastSwitch = -Infinity;   // when the level drawn last changed
  private goodSince: number | null = null;
  private blocked: { budget: number; until: number } | null = null;
  reason: AutoReason = 'start';

  constructor(private readonly fullVertices: number, private readonly baseVertices: number, start: number | null = null) {
    this.adapts = start !== null || fullVertices > AUTO_ABOVE;
    this.busyBudget = start !== null ? Math.min(start, fullVertices) : this.adapts ? BUSY_BUDGET : fullVertices;
    this.floor = Math.min(MIN_BUDGET, this.busyBudget);
    this.wanted = this.busyBudget;
  }

  get budget(): number {
    return this.wanted;
  }

  get busy(): number {
    return this.busyBudget;
  }

  // The level drawn changed (a swap): the statistics start over.
  levelShown(now: number): void {
    this.lastSwitch = now;
    this.goodSince = null;
  }

  // The budget to ask for now; changes it when the page rests, gets busy,
  // falls behind or keeps up.
  update(s: DetailSample): number {
    const idle = !s.interacting && (s.lastArrivalAt === null || s.now - s.lastArrivalAt > IDLE_MS);
    if (idle) {
      this.goodSince = null;
      this.set(this.fullVertices, 'idle');
      return this.wanted;
    }
    if (this.wanted !== this.busyBudget) this.set(this.busyBudget, 'busy');  // from full detail, at rest
    if (!this.adapts || s.now - this.lastSwitch < SETTLE_MS || s.arrivedPerSecond < MIN_RATE) return this.wanted;
    const behind = s.appliedPerSecond < 0.85 * s.arrivedPerSecond || s.drawnPerSecond < 0.5 * s.arrivedPerSecond;
    const keepingUp = s.appliedPerSecond >= 0.97 * s.arrivedPerSecond && s.drawnPerSecond >= 0.9 * s.arrivedPerSecond;
    if (behind) {
      this.goodSince = null;
      const coarser = Math.max(this.floor, Math.floor(this.busyBudget / 2));
      if (this.level(coarser) < this.level(this.busyBudget)) {
        this.blocked = { budget: this.busyBudget, until: s.now + BLOCK_MS };
        this.busyBudget = coarser;
        this.set(coarser, 'behind');
      }
    } else if (keepingUp) {
      this.goodSince ??= s.now;
      const finer = this.busyBudget * 2;
      const blocked = this.blocked !== null && s.now < this.blocked.until && finer >= this.blocked.budget;
      if (s.now - this.goodSince >= REFINE_AFTER_MS && !blocked && this.level(finer) < this.fullVertices) {
        this.goodSince = null;
        this.busyBudget = finer;
        this.set(finer, 'keeping up');
      }
    } else {
      this.goodSince = null;
    }
    return this.wanted;
  }

  private level(budget: number): number {
    return levelVerticesFor(budget, this.baseVertices, this.fullVertices);
  }

  private set(budget: number, reason: AutoReason): void {
    if (budget === this.wanted) return;
    this.wanted = budget;
    this.reason = reason;
  }
}
