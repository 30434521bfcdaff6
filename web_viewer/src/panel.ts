// The side panel's DOM: status line, error box, and the tables and toggles
// filled from the session and its frames. No logic beyond presentation.
import type { SessionInfo } from './client';
import { hook } from './hook';
import type { Overlay } from './overlays';

export const byId = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;

export function setStatus(text: string): void {
  byId('status').textContent = text;
}

export function showError(message: string): void {
  hook.error = message;
  const box = byId('error');
  box.textContent = message;
  box.hidden = false;
}

// A stop: the page shows why and does nothing more.
export function fail(message: string): void {
  hook.state = 'error';
  setStatus('Stopped.');
  showError(message);
}

// A note under a control, e.g. the answer to SetOptions.
export function setNote(id: string, text: string, bad = false): void {
  const note = byId(id);
  note.textContent = text;
  note.className = bad ? 'note bad' : 'note';
}

// `triangles`, `baseVertices`: the counts (the worker keeps the arrays; info's are emptied).
export function showSession(info: SessionInfo, serverUrl: string, clientName: string, triangles: number,
  baseVertices: number): void {
  fillList(byId('session-info'), [
    ['session', info.sessionId],
    ['you are', clientName],
    ['server', serverUrl],
    ['mesh hash', info.meshHash],
    ['vertices', String(info.rest?.vertexCount ?? 0)],
    ['triangles', String(triangles)],
    ['base vertices', String(baseVertices)],
  ]);
}

function fillList(list: HTMLElement, rows: [string, string][]): void {
  list.replaceChildren(...rows.flatMap(([label, value]) => {
    const dt = document.createElement('dt');
    dt.textContent = label;
    const dd = document.createElement('dd');
    dd.textContent = value;
    return [dt, dd];
  }));
}

export function showStats(rows: [string, string][]): void {
  byId('stats').querySelector('tbody')!.replaceChildren(...rows.map(([label, value]) => {
    const row = document.createElement('tr');
    const name = document.createElement('td');
    name.textContent = label;
    const cell = document.createElement('td');
    cell.textContent = value;
    row.append(name, cell);
    return row;
  }));
}

// A checkbox per overlay; `changed` after each toggle.
export function showOverlayToggles(overlays: Overlay[], changed: (overlay: Overlay, visible: boolean) => void): void {
  byId('overlays').replaceChildren(...overlays.map((overlay) => {
    const label = document.createElement('label');
    const box = document.createElement('input');
    box.type = 'checkbox';
    box.id = `overlay-${overlay.id}`;
    box.addEventListener('change', () => {
      overlay.setVisible(box.checked);
      changed(overlay, box.checked);
    });
    label.append(box, ` ${overlay.label}`);
    return label;
  }));
}
