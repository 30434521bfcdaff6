// The session's edit history in the panel: undo and redo (buttons, Ctrl+Z,
// Ctrl+Shift+Z and Ctrl+Y on editor pages), the newest entries (author in
// their colour, what, when, undone), and checkpoints (save, restore, compare).
//
// Every change is an entry of its author (this page's: its client name);
// Undo and Redo are this page's own: an undo restores only the base vertices
// no one else changed since, and says whose later work it kept.
//
// GetHistory is asked on join, after every frame that names a change (and
// after this page's own history calls), through PacedCalls: one call in
// flight, at most one per 250 ms, the newest `HISTORY_NEWEST` entries only.
// The worker parses the answer (each entry lists every base vertex it
// changed) and hands over a summary; the list is rebuilt only when it differs.
import { Code, isCode, type SessionClient, type UndoResponse } from './client';
import { HistoryEntry_Kind, UndoResponse_Outcome } from './gen/filigree/v1/filigree_pb';
import { PacedCalls } from './paced-calls';
import { participantColour } from './participants';
import type { CheckpointLine, HistoryLine, HistoryLines } from './pipeline-protocol';

export const HISTORY_NEWEST = 50;
// How long an answer's message stays under the buttons.
export const MESSAGE_MS = 8000;
// Checkpoints made elsewhere show without a frame (they make none) after at most this long.
export const POLL_MS = 10_000;

export const plural = (n: number, one: string, many: string) => `${n.toLocaleString('en-US')} ${n === 1 ? one : many}`;
const vertices = (n: number) => plural(n, 'vertex', 'vertices');
const baseVertices = (n: number) => plural(n, 'base vertex', 'base vertices');

// A short word for an entry's kind (the list's data-kind, the tests').
export function kindName(kind: number): string {
  switch (kind) {
    case HistoryEntry_Kind.POSE: return 'pose';
    case HistoryEntry_Kind.HANDLES: return 'handles';
    case HistoryEntry_Kind.THRESHOLD: return 'threshold';
    case HistoryEntry_Kind.RESTORE: return 'restore';
    case HistoryEntry_Kind.UNDO: return 'undo';
    case HistoryEntry_Kind.REDO: return 'redo';
    default: return 'change';
  }
}

// What an entry did, in words ("moved 34 base vertices").
export function describeEntry(entry: Pick<HistoryLine, 'kind' | 'vertices' | 'target'>,
  checkpoints: readonly Pick<CheckpointLine, 'id' | 'name'>[] = []): string {
  switch (entry.kind) {
    case HistoryEntry_Kind.POSE:
      return `moved ${baseVertices(entry.vertices)}`;
    case HistoryEntry_Kind.HANDLES:
      return entry.vertices > 0 ? `moved handles (${baseVertices(entry.vertices)})` : 'changed handles';
    case HistoryEntry_Kind.THRESHOLD:
      return 'changed the threshold';
    case HistoryEntry_Kind.RESTORE: {
      const checkpoint = checkpoints.find((c) => c.id === BigInt(entry.target));
      return `restored checkpoint ${checkpoint ? `“${checkpoint.name}”` : `#${entry.target}`}` +
        (entry.vertices > 0 ? ` (${baseVertices(entry.vertices)})` : '');
    }
    case HistoryEntry_Kind.UNDO:
      return `undid #${entry.target}` + (entry.vertices > 0 ? ` (${baseVertices(entry.vertices)})` : '');
    case HistoryEntry_Kind.REDO:
      return `redid #${entry.target}` + (entry.vertices > 0 ? ` (${baseVertices(entry.vertices)})` : '');
    default:
      return 'changed the session';
  }
}

// "Ben's later change on 1 vertex and Ann's later change on 4 vertices":
// the others' work an undo kept, by author (a conflict without vertices is
// the threshold).
export function keptPhrase(conflicts: readonly { author: string; baseVertices: ArrayLike<number> }[], own: string): string {
  const byAuthor = new Map<string, { count: number; threshold: boolean }>();
  for (const c of conflicts) {
    const seen = byAuthor.get(c.author) ?? { count: 0, threshold: false };
    seen.count += c.baseVertices.length;
    if (c.baseVertices.length === 0) seen.threshold = true;
    byAuthor.set(c.author, seen);
  }
  const parts = [...byAuthor].map(([author, { count, threshold }]) => {
    const whose = author === '' ? 'someone else\'s' : author === own ? 'your own' : `${author}'s`;
    const what = [count > 0 ? `change on ${vertices(count)}` : '', threshold ? 'threshold' : ''].filter(Boolean).join(' and ');
    return `${whose} later ${what}`;
  });
  return parts.length <= 1 ? parts.join('') : `${parts.slice(0, -1).join(', ')} and ${parts[parts.length - 1]}`;
}

// The words for what was undone or redone: "change to 120 base vertices".
function changeWords(target: HistoryLine | undefined): string {
  if (!target) return 'latest change';
  switch (target.kind) {
    case HistoryEntry_Kind.POSE: return `change to ${baseVertices(target.vertices)}`;
    case HistoryEntry_Kind.HANDLES: return 'handle change';
    case HistoryEntry_Kind.THRESHOLD: return 'threshold change';
    case HistoryEntry_Kind.RESTORE: return 'checkpoint restore';
    default: return 'latest change';
  }
}

// An undo's or redo's answer in plain words. `target`: the entry it names,
// when the page has it.
export function undoText(answer: Pick<UndoResponse, 'outcome' | 'conflicts'>, redo: boolean, own: string,
  target?: HistoryLine): string {
  const Did = redo ? 'Redid' : 'Undid';
  const kept = () => {
    const phrase = keptPhrase(answer.conflicts, own);
    return `Kept ${phrase}.`;
  };
  switch (answer.outcome) {
    case UndoResponse_Outcome.NOTHING:
      return `Nothing of yours to ${redo ? 'redo' : 'undo'}.`;
    case UndoResponse_Outcome.DONE:
      return `${Did} your ${changeWords(target)}.`;
    case UndoResponse_Outcome.PARTIAL: {
      const conflicting = answer.conflicts.reduce((n, c) => n + c.baseVertices.length, 0);
      const restored = !redo && target && target.kind === HistoryEntry_Kind.POSE && target.vertices > conflicting
        ? `your change on ${target.vertices - conflicting} of ${baseVertices(target.vertices)}` : 'the rest of your change';
      return `${Did} ${restored}. ${kept()}`;
    }
    case UndoResponse_Outcome.CONFLICT:
      return `Nothing ${redo ? 'redone' : 'undone'}: others changed all of it since. ${kept()}`;
    default:
      return 'Done.';
  }
}

// "12 base vertices differ, max distance 0.0123 (1.2 % of the mesh's size)".
export function diffText(diff: { baseVertices: ArrayLike<number>; maxDistance: number; thresholdDiffers: boolean },
  meshSize: number): string {
  const n = diff.baseVertices.length;
  const differ = `${baseVertices(n)} ${n === 1 ? 'differs' : 'differ'}`;
  const distance = n === 0 ? '' : `, max distance ${diff.maxDistance.toPrecision(3)}` +
    (meshSize > 0 ? ` (${((100 * diff.maxDistance) / meshSize).toFixed(1)} % of the mesh's size)` : '');
  return `${differ}${distance}${diff.thresholdDiffers ? '; the threshold differs' : ''}.`;
}

// A server sentence as a sentence: capital first, full stop last.
export function sentence(text: string): string {
  if (text === '') return '';
  const s = text[0].toUpperCase() + text.slice(1);
  return /[.!?]$/.test(s) ? s : `${s}.`;
}

// A string equal for equal lists (what is shown of them).
export function historyKey(lines: HistoryLines): string {
  return lines.entries.map((e) => `${e.seq}:${e.undone ? 1 : 0}:${e.vertices}:${e.endTime}`).join(',') + '|' +
    lines.checkpoints.map((c) => `${c.id}:${c.name}`).join(',');
}

const timeOf = (unixSeconds: number) => new Date(unixSeconds * 1000)
  .toLocaleTimeString([], { hour: '2-digit', minute: '2-digit', second: '2-digit' });

// An author as a coloured tag (their colour on every page and on the server).
export function authorTag(author: string, own: string): HTMLSpanElement {
  const tag = document.createElement('span');
  tag.className = 'author';
  const { css, darkText } = participantColour(author);
  tag.style.background = css;
  tag.style.color = darkText ? '#111' : '#fff';
  tag.textContent = (author || '(unnamed client)') + (author === own ? ' (you)' : '');
  return tag;
}

export interface HistoryEvents {
  // GetHistory of the newest entries, summarised (the worker's).
  fetch(newest: number): Promise<HistoryLines>;
  describe(error: unknown): string;
  // After an undo, redo or restore answered by a change: this page's handles may differ on the server now.
  changed(): void;
  // The page may edit (an editor token).
  canEdit(): boolean;
  // The mesh's size (its bounding diameter), for distances in the comparisons.
  meshSize: number;
}

export interface UndoShown { redo: boolean; outcome: number; text: string; message: string; conflicts: string[]; forced: boolean }

export class HistoryPanel {
  private readonly paced: PacedCalls;
  private lines: HistoryLines | null = null;
  private key: string | null = null;
  private queue: Promise<void> = Promise.resolve();
  private messageTimer: ReturnType<typeof setTimeout> | undefined;
  private readonly compared = new Map<string, string>();  // checkpoint id → its comparison shown
  answers = 0;
  calls = 0;
  inFlight = 0;
  mostInFlight = 0;
  pendingUndos = 0;
  undos: UndoShown[] = [];

  constructor(private readonly client: SessionClient, readonly ownName: string, private readonly events: HistoryEvents,
              private readonly list: HTMLOListElement, private readonly checkpointList: HTMLUListElement,
              private readonly undoStatus: HTMLElement, private readonly historyStatus: HTMLElement,
              private readonly checkpointStatus: HTMLElement) {
    this.paced = new PacedCalls(() => this.fetch());
    window.setInterval(() => {
      if (!document.hidden) this.refresh();
    }, POLL_MS);
  }

  // Asks for the history again (paced).
  refresh(): void {
    this.paced.request();
  }

  get fetching(): boolean {
    return !this.paced.idle;
  }

  get entries(): readonly HistoryLine[] {
    return this.lines?.entries ?? [];
  }

  get checkpoints(): readonly CheckpointLine[] {
    return this.lines?.checkpoints ?? [];
  }

  private async fetch(): Promise<void> {
    ++this.calls;
    this.mostInFlight = Math.max(this.mostInFlight, ++this.inFlight);
    try {
      const lines = await this.events.fetch(HISTORY_NEWEST);
      ++this.answers;
      this.historyStatus.textContent = lines.entries.length >= HISTORY_NEWEST ? `The newest ${HISTORY_NEWEST} entries.` : '';
      this.historyStatus.className = 'note';
      this.show(lines);
    } catch (error) {
      if (isCode(error, Code.Unimplemented)) {
        this.paced.enabled = false;
        this.historyStatus.textContent = 'This server keeps no edit history (no GetHistory).';
      } else {
        this.historyStatus.textContent = this.events.describe(error);
      }
      this.historyStatus.className = 'note bad';
    } finally {
      --this.inFlight;
    }
  }

  private show(lines: HistoryLines): void {
    this.lines = lines;
    const key = historyKey(lines);
    if (key === this.key) return;
    this.key = key;
    this.renderEntries(lines);
    this.renderCheckpoints(lines.checkpoints);
  }

  private renderEntries(lines: HistoryLines): void {
    if (lines.entries.length === 0) {
      const none = document.createElement('li');
      none.className = 'note';
      none.textContent = 'No changes yet.';
      this.list.replaceChildren(none);
      return;
    }
    this.list.replaceChildren(...lines.entries.map((entry) => {
      const item = document.createElement('li');
      item.dataset.seq = String(entry.seq);
      item.dataset.author = entry.author;
      item.dataset.kind = kindName(entry.kind);
      item.dataset.undone = String(entry.undone);
      if (entry.undone) item.classList.add('undone');
      const seq = document.createElement('span');
      seq.className = 'version';
      seq.textContent = `#${entry.seq}`;
      const what = document.createElement('span');
      what.className = 'what';
      what.textContent = describeEntry(entry, lines.checkpoints);
      const when = document.createElement('time');
      when.className = 'version';
      when.dateTime = new Date(entry.startTime * 1000).toISOString();
      when.textContent = timeOf(entry.startTime);
      item.append(seq, ' ', authorTag(entry.author, this.ownName), ' ', what, ' ', when);
      if (entry.undone) {
        const badge = document.createElement('span');
        badge.className = 'badge';
        badge.textContent = 'undone';
        item.append(' ', badge);
      }
      return item;
    }));
  }

  private renderCheckpoints(checkpoints: readonly CheckpointLine[]): void {
    if (checkpoints.length === 0) {
      const none = document.createElement('li');
      none.className = 'note';
      none.textContent = 'No checkpoints yet.';
      this.checkpointList.replaceChildren(none);
      return;
    }
    this.checkpointList.replaceChildren(...checkpoints.map((c) => {
      const item = document.createElement('li');
      item.dataset.checkpoint = String(c.id);
      item.dataset.name = c.name;
      const name = document.createElement('strong');
      name.className = 'checkpoint-name';
      name.textContent = c.name;
      const when = document.createElement('span');
      when.className = 'version';
      when.textContent = timeOf(c.time);
      const restore = document.createElement('button');
      restore.type = 'button';
      restore.className = 'editor-only restore';
      restore.textContent = 'Restore';
      restore.title = 'Go back to this checkpoint (an entry of yours: Undo takes it back)';
      restore.addEventListener('click', () => void this.restore(c));
      const compare = document.createElement('button');
      compare.type = 'button';
      compare.className = 'compare';
      compare.textContent = 'Compare';
      compare.title = 'How far the mesh is from this checkpoint now';
      const result = document.createElement('span');
      result.className = 'note compare-result';
      result.textContent = this.compared.get(String(c.id)) ?? '';
      compare.addEventListener('click', () => void this.compare(c));
      const buttons = document.createElement('span');
      buttons.className = 'checkpoint-buttons';
      buttons.append(restore, compare);
      item.append(name, ' ', authorTag(c.author, this.ownName), ' ', when, buttons, result);
      return item;
    }));
  }

  // ---- undo and redo

  // Undoes (redo: redoes) this page's latest change; presses queue up, one call at a time.
  undo(redo: boolean, force = false): void {
    if (!this.events.canEdit()) return;
    ++this.pendingUndos;
    this.note(redo ? 'Redoing…' : 'Undoing…');
    this.queue = this.queue.then(() => this.runUndo(redo, force)).finally(() => { --this.pendingUndos; });
  }

  private async runUndo(redo: boolean, force: boolean): Promise<void> {
    let answer: UndoResponse;
    try {
      answer = await this.client.undo(this.ownName, redo, force);
    } catch (error) {
      this.note(isCode(error, Code.Unimplemented) ? 'This server has no undo.'
        : isCode(error, Code.PermissionDenied) ? 'Undo needs the editor token; this page was opened with another token.'
          : this.events.describe(error), true);
      return;
    }
    const target = this.entries.find((e) => e.seq === Number(answer.entry));
    const text = undoText(answer, redo, this.ownName, target);
    const bad = answer.outcome === UndoResponse_Outcome.CONFLICT;
    this.undos.push({
      redo, outcome: answer.outcome, text, message: answer.message, conflicts: answer.conflicts.map((c) => c.author), forced: force,
    });
    this.note(text, bad, answer.message, bad ? () => this.undo(redo, true) : undefined, redo ? 'Redo anyway' : 'Undo anyway');
    if (answer.outcome === UndoResponse_Outcome.DONE || answer.outcome === UndoResponse_Outcome.PARTIAL) this.events.changed();
    this.refresh();
  }

  // The answer's words under the buttons for MESSAGE_MS (a button to force a refused undo with them).
  private note(text: string, bad = false, detail = '', force?: () => void, forceLabel = ''): void {
    clearTimeout(this.messageTimer);
    this.undoStatus.className = bad ? 'note bad' : 'note';
    this.undoStatus.title = detail ? sentence(detail) : '';
    this.undoStatus.replaceChildren(text);
    if (force) {
      const button = document.createElement('button');
      button.type = 'button';
      button.id = 'undo-force';
      button.textContent = forceLabel;
      button.title = 'Overwrites the others\' later changes on these vertices (theirs stay in the history)';
      button.addEventListener('click', () => {
        button.disabled = true;
        force();
      });
      this.undoStatus.append(' ', button);
    }
    if (text.endsWith('…')) return;
    this.messageTimer = setTimeout(() => {
      this.undoStatus.replaceChildren();
      this.undoStatus.title = '';
    }, MESSAGE_MS);
  }

  // ---- checkpoints

  async save(name: string): Promise<boolean> {
    this.checkpointNote(`Saving “${name}”…`);
    try {
      const made = await this.client.createCheckpoint(name, this.ownName);
      this.checkpointNote(`Saved checkpoint “${made.name}”.`);
      this.refresh();
      return true;
    } catch (error) {
      this.checkpointNote(isCode(error, Code.PermissionDenied)
        ? 'Saving a checkpoint needs the editor token; this page was opened with another token.'
        : this.events.describe(error), true);
      return false;
    }
  }

  private async restore(c: CheckpointLine): Promise<void> {
    this.checkpointNote(`Restoring “${c.name}”…`);
    try {
      const answer = await this.client.restoreCheckpoint(c.id, this.ownName);
      this.checkpointNote(sentence(answer.message) || `Restored “${c.name}”.`);
      if (answer.outcome !== UndoResponse_Outcome.NOTHING) this.events.changed();
      this.refresh();
    } catch (error) {
      this.checkpointNote(isCode(error, Code.PermissionDenied)
        ? 'Restoring needs the editor token; this page was opened with another token.' : this.events.describe(error), true);
    }
  }

  private async compare(c: CheckpointLine): Promise<void> {
    this.showComparison(c.id, 'Comparing…');
    try {
      const diff = await this.client.diffCheckpoint(c.id);
      const text = `Now against “${c.name}”: ${diffText(diff, this.events.meshSize)}`;
      this.compared.set(String(c.id), text);
      this.showComparison(c.id, text);
    } catch (error) {
      this.showComparison(c.id, this.events.describe(error), true);
    }
  }

  // In the checkpoint's line as shown now (the list may have been rebuilt meanwhile).
  private showComparison(id: bigint, text: string, bad = false): void {
    const result = this.checkpointList.querySelector<HTMLElement>(`li[data-checkpoint="${id}"] .compare-result`);
    if (!result) return;
    result.textContent = text;
    result.className = bad ? 'note bad compare-result' : 'note compare-result';
  }

  private checkpointNote(text: string, bad = false): void {
    this.checkpointStatus.textContent = text;
    this.checkpointStatus.className = bad ? 'note bad' : 'note';
  }
}
