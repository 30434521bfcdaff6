// The other participants' handles: every client that holds handles in the
// session (other pages, programs), each in a colour of its own with its name
// next to its handles, and a legend in the panel (name, colour, handle count).
// This page's own handles are handles.ts's (their own look); viewer pages
// show the others' too, read-only.
//
// GetHandles is asked on join, after a reconnect, and whenever a frame's
// changes name a client other than this page (the changes name the clients
// whose poses or handles changed since the previous frame): at most one call
// in flight and one per MIN_INTERVAL_MS, the frames in between making one
// more call (newest wins). An answer equal to what is drawn changes nothing.
//
// Light on the page's thread: nothing per frame but a look at its changes;
// spheres, labels and legend are rebuilt only when an answer differs; the
// labels (DOM, over the canvas) are moved only when the camera moves or the
// view is resized (projected once per animation frame, no layout read).
import * as THREE from 'three';

import { Code, isCode, type Frame, type SessionClient, type SessionHandles } from './client';
import { PacedCalls } from './paced-calls';
import type { MeshView } from './scene';

export { MIN_INTERVAL_MS } from './paced-calls';

// Participants' colours: the server's (Participant.colour, server/session_presence.cpp),
// computed here alike so that a name has its colour before any presence
// arrives (history authors, handles): FNV-1a of the name's UTF-8 bytes over
// this palette. `darkText`: a label on it reads better in dark letters.
export const PALETTE: readonly { css: string; darkText: boolean }[] = [
  '#e6194b', '#3cb44b', '#4363d8', '#f58231', '#911eb4', '#bfef45', '#f032e6', '#9a6324',
].map((css) => ({ css, darkText: prefersDarkText(css) }));
// A label's largest width and about its height (CSS: .participant-label), and its gap to the anchor.
const LABEL_MAX_WIDTH = 160;
const LABEL_HEIGHT = 20;
const LABEL_GAP = 9;

// WCAG contrast: dark text (#111) on `css` reads better than white.
export function prefersDarkText(css: string): boolean {
  const channel = (k: number) => {
    const c = parseInt(css.slice(1 + 2 * k, 3 + 2 * k), 16) / 255;
    return c <= 0.03928 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4;
  };
  const l = 0.2126 * channel(0) + 0.7152 * channel(1) + 0.0722 * channel(2);
  return (l + 0.05) / (0.0056 + 0.05) > 1.05 / (l + 0.05);
}

const utf8 = new TextEncoder();

// FNV-1a (32 bits) of the name's UTF-8 bytes (as the server hashes it).
export function nameHash(name: string): number {
  let h = 0x811c9dc5;
  for (const byte of utf8.encode(name)) {
    h ^= byte;
    h = Math.imul(h, 0x01000193);
  }
  return h >>> 0;
}

// The palette entry of a client name: the same on every page and on the server, for good.
export function participantColour(name: string): (typeof PALETTE)[number] {
  return PALETTE[nameHash(name) % PALETTE.length];
}

// Whether a frame's changes name a client other than `own` (no allocation).
export function namesOther(frame: Pick<Frame, 'changes'>, own: string): boolean {
  for (const change of frame.changes) if (change.clientName !== own) return true;
  return false;
}

export interface ShownHandle { vertex: number; x: number; y: number; z: number }
export interface Participant { name: string; colour: string; darkText: boolean; handles: ShownHandle[] }

// The participants to show from an answer: every one but `own`, with at
// least one handle, by name.
export function othersOf(answer: Pick<SessionHandles, 'participants'>, own: string): Participant[] {
  return answer.participants
    .filter((p) => p.clientName !== own && p.handles.length > 0)
    .map((p) => {
      const { css, darkText } = participantColour(p.clientName);
      return {
        name: p.clientName, colour: css, darkText,
        handles: p.handles.map(({ vertex, x, y, z }) => ({ vertex, x, y, z })),
      };
    })
    .sort((a, b) => (a.name < b.name ? -1 : a.name > b.name ? 1 : 0));
}

// A string equal for equal lists of participants (names and handles).
export function participantsKey(participants: readonly Participant[]): string {
  return participants.map((p) => `${p.name}\u0000${p.handles.map((h) => `${h.vertex},${h.x},${h.y},${h.z}`).join(';')}`)
    .join('\u0001');
}

// When to ask: request() marks an ask due; asks run one at a time, at most
// one per MIN_INTERVAL_MS; requests meanwhile make one more ask after it.
// `failed` returns true when asking again is pointless (the server lacks the call).
export class HandlesFeed<A> {
  private readonly paced: PacedCalls;

  constructor(fetch: () => Promise<A>,
              answered: (answer: A) => void,
              failed: (error: unknown) => boolean,
              now: () => number = () => performance.now()) {
    this.paced = new PacedCalls(() => fetch().then(answered, (error: unknown) => {
      if (failed(error)) this.paced.enabled = false;
    }), now);
  }

  request(): void {
    this.paced.request();
  }

  get idle(): boolean {
    return this.paced.idle;
  }
}

export interface ParticipantsEvents {
  // The participants drawn now (after every change) and the answer's version.
  shown(participants: readonly Participant[], version: bigint): void;
  // A note under the legend (bad: an error); '' clears it.
  status(text: string, bad?: boolean): void;
  describe(error: unknown): string;
}

// What the layer draws for one participant.
interface Drawn extends Participant {
  spheres: THREE.Mesh[];
  label: HTMLDivElement;
}

export class ParticipantsLayer {
  private readonly group = new THREE.Group();
  private readonly sphere: THREE.SphereGeometry;
  private readonly materials = new Map<string, THREE.MeshBasicMaterial>();  // by colour: at most the palette
  private readonly pool: THREE.Mesh[] = [];
  private readonly labels: HTMLDivElement;
  private readonly feed: HandlesFeed<SessionHandles>;
  private drawn: Drawn[] = [];
  private key: string | null = null;  // of what is drawn (null: no answer yet)
  private anchors = new Float32Array(0);  // each label's anchor (xyz), then its projection (xy)
  private projected = new Float32Array(0);
  private placing = false;  // an animation frame is due to move the labels
  answers = 0;
  version = 0n;

  constructor(private readonly view: MeshView, client: SessionClient, readonly ownName: string,
              private readonly legend: HTMLElement, private readonly events: ParticipantsEvents) {
    // The size of this page's own handles (handles.ts).
    this.sphere = new THREE.SphereGeometry(view.radius * 0.02, 16, 12);
    this.group.renderOrder = 1;
    view.add(this.group);
    this.labels = document.createElement('div');
    this.labels.className = 'participant-labels';
    this.labels.setAttribute('aria-hidden', 'true');  // the legend says the same in the panel
    view.canvas.after(this.labels);
    view.onViewChange(() => this.placeLabelsSoon());
    this.feed = new HandlesFeed(() => client.getHandles(), (answer) => this.show(answer), (error) => {
      if (isCode(error, Code.Unimplemented)) {
        this.events.status('This server does not share the participants\' handles (no GetHandles).', true);
        return true;
      }
      this.events.status(this.events.describe(error), true);
      return false;
    });
  }

  // On join and after a reconnect: ask for everyone's handles.
  refresh(): void {
    this.feed.request();
  }

  // Every frame that arrives: ask again when someone else changed something.
  frameArrived(frame: Frame): void {
    if (namesOther(frame, this.ownName)) this.feed.request();
  }

  // A GetHandles call is running or due.
  get fetching(): boolean {
    return !this.feed.idle;
  }

  get participants(): readonly Participant[] {
    return this.drawn;
  }

  // For the tests: each other participant's sphere in the scene, with the
  // colour it is drawn in and where it is on the page (null: behind the camera).
  spheresOnPage(): { name: string; colour: string; vertex: number; visible: boolean; x: number | null; y: number | null }[] {
    const rect = this.view.canvas.getBoundingClientRect();
    const out = new Float32Array(2);
    return this.group.children.map((object) => {
      const mesh = object as THREE.Mesh;
      const { x, y, z } = mesh.position;
      this.view.projectPoints([x, y, z], 1, out);
      const material = mesh.material as THREE.MeshBasicMaterial;
      return {
        name: mesh.userData.participant as string, colour: `#${material.color.getHexString()}`,
        vertex: mesh.userData.vertex as number, visible: mesh.visible && this.group.visible,
        x: Number.isNaN(out[0]) ? null : rect.left + out[0], y: Number.isNaN(out[1]) ? null : rect.top + out[1],
      };
    });
  }

  private show(answer: SessionHandles): void {
    ++this.answers;
    this.version = answer.version;
    this.events.status('');
    const participants = othersOf(answer, this.ownName);
    const key = participantsKey(participants);
    if (key === this.key) {
      this.events.shown(this.drawn, this.version);
      return;
    }
    this.key = key;
    this.draw(participants);
    this.renderLegend();
    this.placeLabelsSoon();
    this.view.invalidate();
    this.events.shown(this.drawn, this.version);
  }

  private material(colour: string): THREE.MeshBasicMaterial {
    let material = this.materials.get(colour);
    if (!material) {
      // Always drawn, through the mesh, as this page's own handles are.
      material = new THREE.MeshBasicMaterial({ color: new THREE.Color(colour), depthTest: false });
      this.materials.set(colour, material);
    }
    return material;
  }

  // Spheres and labels for `participants`; meshes are reused.
  private draw(participants: Participant[]): void {
    for (const object of this.group.children) this.pool.push(object as THREE.Mesh);
    this.group.clear();
    const labels: HTMLDivElement[] = [];
    this.drawn = participants.map((p) => {
      const material = this.material(p.colour);
      const spheres = p.handles.map((h) => {
        const sphere = this.pool.pop() ?? new THREE.Mesh(this.sphere);
        sphere.material = material;
        sphere.position.set(h.x, h.y, h.z);
        sphere.renderOrder = 1;
        sphere.userData.participant = p.name;
        sphere.userData.vertex = h.vertex;
        this.group.add(sphere);
        return sphere;
      });
      const label = document.createElement('div');
      label.className = 'participant-label';
      label.textContent = p.name || '(unnamed client)';
      label.style.background = p.colour;
      label.style.color = p.darkText ? '#111' : '#fff';
      label.dataset.participant = p.name;
      labels.push(label);
      return { ...p, spheres, label };
    });
    this.labels.replaceChildren(...labels);
    // Each label next to its participant's newest handle (the last one set).
    this.anchors = new Float32Array(3 * this.drawn.length);
    this.projected = new Float32Array(2 * this.drawn.length);
    this.drawn.forEach((p, k) => {
      const last = p.handles[p.handles.length - 1];
      this.anchors.set([last.x, last.y, last.z], 3 * k);
    });
  }

  private placeLabelsSoon(): void {
    if (this.placing || this.drawn.length === 0) return;
    this.placing = true;
    requestAnimationFrame(() => {
      this.placing = false;
      this.placeLabels();
    });
  }

  // Moves each label beside its anchor as drawn now (above right; left or
  // below near the view's right or top edge); hides it behind the camera.
  private placeLabels(): void {
    this.view.projectPoints(this.anchors, this.drawn.length, this.projected);
    const { width } = this.view.cssSize;
    for (let k = 0; k < this.drawn.length; ++k) {
      const { label } = this.drawn[k];
      const x = this.projected[2 * k];
      const y = this.projected[2 * k + 1];
      const hidden = Number.isNaN(x);
      if (label.hidden !== hidden) label.hidden = hidden;
      if (hidden) continue;
      const left = x + LABEL_GAP + LABEL_MAX_WIDTH > width && x > width / 2;
      const below = y - LABEL_GAP - LABEL_HEIGHT < 0;
      label.style.transform = `translate(${Math.round(left ? x - LABEL_GAP : x + LABEL_GAP)}px, ` +
        `${Math.round(below ? y + LABEL_GAP : y - LABEL_GAP)}px) translate(${left ? -100 : 0}%, ${below ? 0 : -100}%)`;
    }
  }

  // The panel's legend: a swatch, the name and the handle count per participant.
  private renderLegend(): void {
    if (this.drawn.length === 0) {
      this.legend.replaceChildren(noteLine('No other participant holds handles.'));
      return;
    }
    this.legend.replaceChildren(...this.drawn.map((p) =>
      participantLine(p.name, p.colour, p.name || '(unnamed client)',
        [`${p.handles.length} handle${p.handles.length === 1 ? '' : 's'}`])));
  }
}

// A panel list's line when it has nothing to list.
export function noteLine(text: string): HTMLLIElement {
  const none = document.createElement('li');
  none.className = 'note';
  none.textContent = text;
  return none;
}

// A participant's line in a panel list: their colour's swatch, their name
// (`label`), then `counts` (what they hold or are) and `activity` (what they do).
export function participantLine(name: string, colour: string, label: string, counts: string[],
  activity?: string): HTMLLIElement {
  const item = document.createElement('li');
  item.dataset.participant = name;
  const swatch = document.createElement('span');
  swatch.className = 'swatch';
  swatch.style.background = colour;
  const nameSpan = document.createElement('span');
  nameSpan.className = 'participant-name';
  nameSpan.textContent = label;
  item.append(swatch, nameSpan);
  for (const text of counts) {
    const count = document.createElement('span');
    count.className = 'participant-count';
    count.textContent = text;
    item.append(count);
  }
  if (activity) {
    const detail = document.createElement('span');
    detail.className = 'participant-activity';
    detail.textContent = activity;
    item.append(detail);
  }
  return item;
}
