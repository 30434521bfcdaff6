// "Who changed what": the changes named by recent frames, newest first.
import type { Frame } from './client';

const KEPT = 30;

export interface ChangeLine {
  version: bigint;
  text: string;
}

// One line per Change of the frame; a frame with none (a threshold change,
// the current frame of a late join) gives none. A change without a pose
// (pose 0) comes from SetHandles.
export function changeLines(frame: Frame): ChangeLine[] {
  return frame.changes.map((change) => ({
    version: frame.version,
    text: `${change.clientName || '(unnamed client)'}: ` + (change.poseId === 0n
      ? (change.vertexCount === 0 ? 'cleared its handles' : 'moved handles')
      : `pose ${change.poseId}, ${change.vertexCount} base ${change.vertexCount === 1 ? 'vertex' : 'vertices'}`),
  }));
}

// The list is rebuilt at most once per animation frame, however many frames arrive.
export class ChangeLog {
  private lines: ChangeLine[] = [];
  private scheduled = false;

  constructor(private readonly list: HTMLOListElement) {}

  add(frame: Frame): void {
    const added = changeLines(frame);
    if (added.length === 0) return;
    this.lines = [...added, ...this.lines].slice(0, KEPT);
    if (this.scheduled) return;
    this.scheduled = true;
    requestAnimationFrame(() => {
      this.scheduled = false;
      this.render();
    });
  }

  private render(): void {
    this.list.replaceChildren(...this.lines.map((line) => {
      const item = document.createElement('li');
      const version = document.createElement('span');
      version.className = 'version';
      version.textContent = `v${line.version}`;
      item.append(version, ` ${line.text}`);
      return item;
    }));
  }
}
