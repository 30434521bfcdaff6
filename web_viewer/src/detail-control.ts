// The page's level of detail (levels.ts, detail.ts): the budget its Watch
// streams ask for, the panel's Detail section (what is drawn; Auto, a level
// or Full), and SetDetail on the live stream whenever the budget changes, so
// that the stream switches without being reopened. One SetDetail in flight,
// the newest budget wins. Auto is re-judged every TICK_MS.
import { Code, isCode, type SessionClient } from './client';
import { AutoDetail, detailLabel, levelChoices, parseDetail, type DetailChoice, type DetailSample } from './detail';
import { hook } from './hook';
import { LatestSender } from './latest-sender';
import { levelVerticesFor } from './levels';
import { byId, setNote } from './panel';

const TICK_MS = 250;
const f = (x: number) => x.toLocaleString('en-US');

export interface DetailEvents {
  // What Auto judges by, now.
  sample(): DetailSample;
  describe(error: unknown): string;
}

export class DetailControl {
  private choice: DetailChoice;
  private auto: AutoDetail | null = null;
  private wanted: number;
  private stream = 0;                       // the page's current Watch stream
  private streamId: bigint | null = null;   // its DetailLevel.stream_id, once announced
  private streamLevel = 0;                  // the level it announced last
  private shown: number;                    // the level drawn
  private supported: boolean | null = null; // the server has levels (null: not known yet)
  private readonly sender: LatestSender<{ stream: number; streamId: bigint; budget: number }>;
  private readonly select = byId<HTMLSelectElement>('detail');

  constructor(private readonly client: SessionClient, private readonly fullVertices: number,
              private readonly baseVertices: number, param: string | undefined, private readonly events: DetailEvents) {
    const parsed = parseDetail(param);
    if ('error' in parsed) setNote('detail-status', parsed.error, true);
    this.choice = 'error' in parsed ? { mode: 'auto', start: null } : parsed;
    this.shown = fullVertices;
    this.wanted = this.budgetOf(this.choice);
    this.sender = new LatestSender((request) => this.send(request));
    this.fillChoices();
    this.select.addEventListener('change', () => this.choose(this.select.value));
    hook.fullVertexCount = fullVertices;
    hook.levelVertices = fullVertices;
    hook.levelIds = () => null;
    this.publish('start');
    this.showLevel();
    window.setInterval(() => this.tick(), TICK_MS);
  }

  // The budget a Watch stream asks for (WatchRequest.max_vertices): the
  // mesh's vertex count for full detail, so that it can switch later.
  get budget(): number {
    return this.wanted;
  }

  // Whether the level a new stream will announce is the one drawn (else its
  // keyframe must come too: open it from version 0).
  get levelKept(): boolean {
    return levelVerticesFor(this.wanted, this.baseVertices, this.fullVertices) === this.shown;
  }

  // A new Watch stream opens: its level is not known yet.
  streamOpening(stream: number): void {
    this.stream = stream;
    this.streamId = null;
    this.streamLevel = 0;
  }

  // Stream `stream` announced a level (streamId null: it sent frames at once,
  // the server has no levels of detail).
  levelArrived(stream: number, streamId: bigint | null, vertexCount: number): void {
    if (stream !== this.stream) return;
    ++hook.levelsArrived;
    if (streamId === null) {
      this.supported = false;
      this.select.disabled = true;
      setNote('detail-status', 'This server sends full detail only.');
      return;
    }
    this.supported = true;
    this.streamId = streamId;
    this.streamLevel = vertexCount;
    hook.streamId = String(streamId);
    // The budget changed before the stream could be switched.
    if (levelVerticesFor(this.wanted, this.baseVertices, this.fullVertices) !== vertexCount && this.sender.idle) {
      this.sender.push({ stream, streamId, budget: this.wanted });
    }
  }

  // A level is drawn now (the geometry swapped).
  levelShown(vertexCount: number, ids: Uint32Array | null): void {
    this.shown = vertexCount;
    hook.levelVertices = vertexCount;
    hook.levelIds = () => (ids ? Array.from(ids) : null);
    ++hook.levelSwaps;
    this.auto?.levelShown(performance.now());
    this.showLevel();
  }

  // The panel's choice: 'auto', 'full' or a budget.
  choose(value: string): void {
    const parsed = parseDetail(value);
    if ('error' in parsed) return;
    this.choice = parsed;
    this.auto = null;
    this.change(this.budgetOf(parsed), 'chosen');
    this.showLevel();
  }

  private budgetOf(choice: DetailChoice): number {
    if (choice.mode === 'full') return this.fullVertices;
    if (choice.mode === 'fixed') return Math.min(choice.budget, this.fullVertices);
    this.auto ??= new AutoDetail(this.fullVertices, this.baseVertices, choice.start);
    return this.auto.budget;
  }

  private tick(): void {
    if (this.auto === null || this.supported === false) return;
    const budget = this.auto.update(this.events.sample());
    if (budget !== this.wanted) this.change(budget, this.auto.reason);
  }

  // Auto's budget at once (a drag started: frames are coming).
  nudge(): void {
    this.tick();
  }

  private change(budget: number, reason: string): void {
    if (budget === this.wanted) return;
    this.wanted = budget;
    this.publish(reason);
    this.showLevel();
    if (this.supported === false || this.streamId === null) return;  // the stream, once open, asks for it
    if (levelVerticesFor(budget, this.baseVertices, this.fullVertices) === this.streamLevel && this.sender.idle) return;
    this.sender.push({ stream: this.stream, streamId: this.streamId, budget });
  }

  private async send(request: { stream: number; streamId: bigint; budget: number }): Promise<void> {
    ++hook.setDetailCalls;
    try {
      const level = await this.client.setDetail(request.streamId, request.budget);
      ++hook.setDetailAnswers;
      if (request.stream === this.stream) this.streamLevel = level;
    } catch (error) {
      // The stream ended meanwhile: the next one opens at this budget.
      if (isCode(error, Code.NotFound)) return;
      if (isCode(error, Code.Unimplemented)) {
        this.supported = false;
        this.select.disabled = true;
        setNote('detail-status', 'This server cannot change the level of a stream; it stays as it is.', true);
        return;
      }
      setNote('detail-status', this.events.describe(error), true);
    }
  }

  private publish(reason: string): void {
    hook.detailMode = this.choice.mode;
    hook.detailBudget = this.wanted;
    hook.detailTarget = levelVerticesFor(this.wanted, this.baseVertices, this.fullVertices);
    hook.detailLog.push({ at: performance.now(), budget: this.wanted, reason });
    if (hook.detailLog.length > 100) hook.detailLog.shift();
  }

  private fillChoices(): void {
    const option = (value: string, text: string) => {
      const o = document.createElement('option');
      o.value = value;
      o.textContent = text;
      return o;
    };
    const levels = levelChoices(this.fullVertices, this.baseVertices);
    const options = [option('auto', 'Auto'), ...levels.map((p) => option(String(p), `${f(p)} vertices`)),
      option('full', `Full (${f(this.fullVertices)} vertices)`)];
    const c = this.choice;
    if (c.mode === 'fixed' && !levels.includes(c.budget) && c.budget < this.fullVertices) {
      options.splice(1, 0, option(String(c.budget), `at most ${f(c.budget)} vertices`));
    }
    this.select.replaceChildren(...options);
    this.select.value = c.mode === 'auto' ? 'auto' : c.mode === 'full' || c.budget >= this.fullVertices ? 'full' : String(c.budget);
  }

  private showLevel(): void {
    byId('detail-level').textContent = detailLabel(this.shown, this.fullVertices);
    const target = levelVerticesFor(this.wanted, this.baseVertices, this.fullVertices);
    if (this.supported === false) return;
    const switching = target !== this.shown ? `Switching to ${f(target)} vertices… ` : '';
    const auto = this.choice.mode === 'auto'
      ? 'Auto: coarser while frames stream and the page falls behind, full detail when the session rests.' : '';
    setNote('detail-status', `${switching}${auto}`);
  }
}
