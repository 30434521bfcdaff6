// Who is here, live (WatchPresence): every participant's name, colour and
// role in the panel; over the mesh, the base vertices each other participant
// is touching (their latest change, for 10 s) as small dots in their colour,
// and their pointer (a dot and a name tag at the vertex they point at). This
// page's own pointer goes to the others with SetPresence (PointerSender).
//
// The stream's first message is the presence as it is: a page that joins
// late sees everyone at once. The stream is opened again after it breaks
// (reconnect.ts's backoff), and stops on a final answer.
//
// Light on the page's thread: a presence message (at most every 100 ms from
// the server) rebuilds the dots' arrays (at most MAX_MARKERS per
// participant) and the panel list only when what it shows changed; the
// dots and tags follow the mesh once per animation frame in which a frame
// was swapped in or the camera moved, no layout read.
import * as THREE from 'three';

import { Code, isCode, type Presence, type SessionClient } from './client';
import { Participant_Role } from './gen/filigree/v1/filigree_pb';
import { PacedCalls } from './paced-calls';
import { noteLine, participantLine, prefersDarkText } from './participants';
import { isFinal, retryDelay } from './reconnect';
import type { MeshView } from './scene';

// Dots drawn per participant at most: evenly spread.
export const MAX_MARKERS = 2048;
// A participant changing more than this share of the base vertices (a
// program driving whole poses) moves the mesh as a whole: no dots, which
// would only speckle all of it; the panel says so.
export const WHOLE_MESH_SHARE = 0.5;
// SetPresence at most this often (10 a second).
export const POINTER_INTERVAL_MS = 100;
const LABEL_GAP = 8;

export interface PresentParticipant {
  name: string;
  colour: string;
  darkText: boolean;
  role: 'editor' | 'viewer';
  you: boolean;
  touching: Uint32Array;   // base vertex indices (at most MAX_MARKERS of them, evenly spread)
  touchingCount: number;   // all of them
  handles: number;
  pointer: { x: number; y: number; z: number; vertex: number } | null;
  idleSeconds: number;
}

// Every `count / max`-th of `values` (all when there are at most `max`).
export function spread(values: ArrayLike<number>, max: number): Uint32Array {
  if (values.length <= max) return Uint32Array.from(values as ArrayLike<number>);
  const out = new Uint32Array(max);
  for (let k = 0; k < max; ++k) out[k] = values[Math.floor((k * values.length) / max)];
  return out;
}

// What a presence message shows: everyone, this page first, then by name.
export function presentParticipants(presence: Pick<Presence, 'participants'>, own: string, max = MAX_MARKERS): PresentParticipant[] {
  return presence.participants.map((p) => {
    const colour = /^#[0-9a-fA-F]{6}$/.test(p.colour) ? p.colour.toLowerCase() : '#9aa3ad';
    return {
      name: p.clientName, colour, darkText: prefersDarkText(colour), role: p.role === Participant_Role.EDITOR ? 'editor' as const : 'viewer' as const,
      you: p.clientName === own, touching: spread(p.touching, max), touchingCount: p.touching.length, handles: p.handleVertices.length,
      pointer: p.hasPointer ? { x: p.pointerX, y: p.pointerY, z: p.pointerZ, vertex: p.pointerVertex } : null,
      idleSeconds: p.idleSeconds,
    };
  }).sort((a, b) => (a.you !== b.you ? (a.you ? -1 : 1) : a.name < b.name ? -1 : a.name > b.name ? 1 : 0));
}

// Whether `p` moves most of a mesh of `baseCount` base vertices (no dots then).
export const movesWholeMesh = (p: Pick<PresentParticipant, 'touchingCount'>, baseCount: number) =>
  baseCount > 0 && p.touchingCount > WHOLE_MESH_SHARE * baseCount;

// What the panel line says besides name and role.
export function activity(p: PresentParticipant, baseCount = 0): string {
  const parts: string[] = [];
  const count = `${p.touchingCount.toLocaleString('en-US')} base ${p.touchingCount === 1 ? 'vertex' : 'vertices'}`;
  if (movesWholeMesh(p, baseCount)) parts.push(`moving most of the mesh (${count})`);
  else if (p.touchingCount > 0) parts.push(`touching ${count}`);
  if (p.handles > 0) parts.push(`${p.handles} handle${p.handles === 1 ? '' : 's'}`);
  if (p.pointer && !p.you) parts.push('pointing');
  if (parts.length === 0 && p.idleSeconds >= 60 && p.idleSeconds < 1e8) parts.push(`idle ${Math.floor(p.idleSeconds / 60)} min`);
  return parts.join(', ');
}

// The panel's key: equal when the list would look the same.
export function presenceKey(participants: readonly PresentParticipant[], baseCount = 0): string {
  return participants.map((p) => `${p.name}\u0000${p.colour}${p.role}${p.you}\u0000${activity(p, baseCount)}`).join('\u0001');
}

export interface PresenceEvents {
  // After every message: what it shows.
  shown(participants: readonly PresentParticipant[], first: boolean): void;
  status(text: string, bad?: boolean): void;
  describe(error: unknown): string;
}

// A round dot for the markers (a point sprite).
function dotTexture(): THREE.Texture {
  const canvas = document.createElement('canvas');
  canvas.width = canvas.height = 32;
  const context = canvas.getContext('2d')!;
  context.fillStyle = '#fff';
  context.beginPath();
  context.arc(16, 16, 13, 0, 2 * Math.PI);
  context.fill();
  context.lineWidth = 3;
  context.strokeStyle = '#000';
  context.stroke();
  return new THREE.CanvasTexture(canvas);
}

interface DrawnPointer { name: string; colour: string; vertex: number; fallback: THREE.Vector3; sphere: THREE.Mesh; label: HTMLDivElement }

export class PresenceLayer {
  private readonly abort = new AbortController();
  private readonly markerGeometry = new THREE.BufferGeometry();
  private readonly markers: THREE.Points;
  private markerIds = new Uint32Array(0);     // original id of each dot
  private markerOwner: string[] = [];         // whose each dot is, by run
  private readonly pointerGroup = new THREE.Group();
  private readonly pointerSphere: THREE.SphereGeometry;
  private readonly materials = new Map<string, THREE.MeshBasicMaterial>();
  private readonly labels: HTMLDivElement;
  private pointers: DrawnPointer[] = [];
  private participants: PresentParticipant[] = [];
  private key: string | null = null;
  private placing = false;
  private stopped = false;
  private visible = true;
  messages = 0;
  streams = 0;
  firstNames: string[] = [];   // the participants of the current stream's first message

  // `baseIds[b]`: the original id of base vertex b.
  constructor(private readonly view: MeshView, private readonly client: SessionClient, readonly ownName: string,
              private readonly baseIds: Uint32Array, private readonly list: HTMLElement, private readonly events: PresenceEvents) {
    this.markers = new THREE.Points(this.markerGeometry, new THREE.PointsMaterial({
      size: 9, sizeAttenuation: false, vertexColors: true, map: dotTexture(), alphaTest: 0.5, depthTest: false, transparent: true,
    }));
    this.markers.frustumCulled = false;
    this.markers.renderOrder = 3;
    this.markers.visible = false;
    view.add(this.markers);
    this.pointerSphere = new THREE.SphereGeometry(view.radius * 0.014, 12, 8);
    this.pointerGroup.renderOrder = 3;
    view.add(this.pointerGroup);
    this.labels = document.createElement('div');
    this.labels.className = 'participant-labels';
    this.labels.setAttribute('aria-hidden', 'true');  // the panel's list says who points
    view.canvas.after(this.labels);
    view.onViewChange(() => this.followSoon());
  }

  // Follows the session's presence until a final answer.
  async start(): Promise<void> {
    let attempt = 0;
    let downSince: number | null = null;
    while (!this.stopped) {
      let ended: unknown = null;
      ++this.streams;
      let first = true;
      try {
        for await (const presence of this.client.watchPresence(this.ownName, this.abort.signal)) {
          attempt = 0;
          downSince = null;
          this.received(presence, first);
          first = false;
        }
      } catch (error) {
        ended = error;
      }
      if (this.abort.signal.aborted) return;
      if (ended !== null && (isFinal(ended) || isCode(ended, Code.Unimplemented))) {
        this.events.status(isCode(ended, Code.Unimplemented) ? 'This server does not share who is here (no WatchPresence).'
          : this.events.describe(ended), true);
        return;
      }
      const now = performance.now();
      downSince ??= now;
      ++attempt;
      await new Promise((resolve) => setTimeout(resolve, retryDelay(attempt, now - downSince!)));
    }
  }

  // Shows or hides the dots and pointers (the panel's list stays).
  setVisible(on: boolean): void {
    this.visible = on;
    this.markers.visible = on && this.markerIds.length > 0;
    this.pointerGroup.visible = on;
    this.labels.hidden = !on;
    this.view.invalidate();
  }

  stop(): void {
    this.stopped = true;
    this.abort.abort();
  }

  get shown(): readonly PresentParticipant[] {
    return this.participants;
  }

  // For the tests: the dots drawn per participant.
  markerCounts(): Record<string, number> {
    const counts: Record<string, number> = {};
    for (const name of this.markerOwner) counts[name] = (counts[name] ?? 0) + 1;
    return counts;
  }

  // For the tests: each pointer drawn, its colour and page point (null: behind the camera).
  pointersOnPage(): { name: string; colour: string; vertex: number; x: number | null; y: number | null; visible: boolean }[] {
    const rect = this.view.canvas.getBoundingClientRect();
    const out = new Float32Array(2);
    return this.pointers.map((p) => {
      const { x, y, z } = p.sphere.position;
      this.view.projectPoints([x, y, z], 1, out);
      return {
        name: p.name, colour: `#${(p.sphere.material as THREE.MeshBasicMaterial).color.getHexString()}`, vertex: p.vertex,
        x: Number.isNaN(out[0]) ? null : rect.left + out[0], y: Number.isNaN(out[1]) ? null : rect.top + out[1],
        visible: this.visible && p.sphere.visible && !p.label.hidden,
      };
    });
  }

  // A frame was swapped in: the dots and pointers follow their vertices.
  meshMoved(): void {
    if (this.markerIds.length > 0 || this.pointers.length > 0) this.followSoon();
  }

  private received(presence: Presence, first: boolean): void {
    ++this.messages;
    const participants = presentParticipants(presence, this.ownName);
    if (first) this.firstNames = participants.map((p) => p.name);
    this.participants = participants;
    if (first) this.events.status('');
    const key = presenceKey(participants, this.baseIds.length);
    if (key !== this.key) {
      this.key = key;
      this.renderList();
    }
    this.setMarkers(participants);
    this.setPointers(participants);
    this.followSoon();
    this.events.shown(participants, first);
  }

  // The dots: every other participant's touched base vertices, in their colour.
  private setMarkers(participants: readonly PresentParticipant[]): void {
    const others = participants.filter((p) => !p.you && p.touching.length > 0 && !movesWholeMesh(p, this.baseIds.length));
    const count = others.reduce((n, p) => n + p.touching.length, 0);
    const ids = new Uint32Array(count);
    const colours = new Float32Array(3 * count);
    const owner: string[] = new Array(count);
    const colour = new THREE.Color();
    let k = 0;
    for (const p of others) {
      colour.set(p.colour);
      for (const b of p.touching) {
        if (b >= this.baseIds.length) continue;
        ids[k] = this.baseIds[b];
        colours.set([colour.r, colour.g, colour.b], 3 * k);
        owner[k] = p.name;
        ++k;
      }
    }
    const same = k === this.markerIds.length && this.markerIds.every((id, i) => id === ids[i] && owner[i] === this.markerOwner[i]);
    if (same) return;  // the same dots (a presence message for something else)
    this.markerIds = ids.slice(0, k);
    this.markerOwner = owner.slice(0, k);
    // The old arrays' GPU buffers go with them.
    this.markerGeometry.dispose();
    if (k === 0) {
      if (this.markers.visible) {
        this.markers.visible = false;
        this.view.invalidate();
      }
      return;
    }
    this.markerGeometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * k), 3));
    this.markerGeometry.setAttribute('color', new THREE.BufferAttribute(colours.subarray(0, 3 * k), 3));
    this.markers.visible = this.visible;
  }

  private material(colour: string): THREE.MeshBasicMaterial {
    let material = this.materials.get(colour);
    if (!material) {
      material = new THREE.MeshBasicMaterial({ color: new THREE.Color(colour), depthTest: false });
      this.materials.set(colour, material);
    }
    return material;
  }

  // The others' pointers: a dot and a name tag each (reused by name).
  private setPointers(participants: readonly PresentParticipant[]): void {
    const wanted = participants.filter((p) => !p.you && p.pointer !== null);
    const byName = new Map(this.pointers.map((p) => [p.name, p]));
    const next: DrawnPointer[] = [];
    for (const p of wanted) {
      let drawn = byName.get(p.name);
      byName.delete(p.name);
      if (!drawn) {
        const sphere = new THREE.Mesh(this.pointerSphere, this.material(p.colour));
        sphere.renderOrder = 3;
        sphere.userData.participant = p.name;
        this.pointerGroup.add(sphere);
        const label = document.createElement('div');
        label.className = 'pointer-label';
        label.dataset.pointer = p.name;
        this.labels.append(label);
        drawn = { name: p.name, colour: p.colour, vertex: 0, fallback: new THREE.Vector3(), sphere, label };
      }
      drawn.colour = p.colour;
      drawn.sphere.material = this.material(p.colour);
      drawn.label.textContent = p.name || '(unnamed client)';
      drawn.label.style.background = p.colour;
      drawn.label.style.color = p.darkText ? '#111' : '#fff';
      drawn.vertex = p.pointer!.vertex;
      drawn.fallback.set(p.pointer!.x, p.pointer!.y, p.pointer!.z);
      next.push(drawn);
    }
    for (const gone of byName.values()) {
      this.pointerGroup.remove(gone.sphere);
      gone.label.remove();
    }
    this.pointers = next;
  }

  private followSoon(): void {
    if (this.placing) return;
    this.placing = true;
    requestAnimationFrame(() => {
      this.placing = false;
      this.follow();
    });
  }

  // Dots and pointers at their vertices' current positions (a vertex the
  // level drawn lacks: the pointer where it was set; the dot hidden).
  private follow(): void {
    const positions = this.view.positions;
    const attribute = this.markerGeometry.getAttribute('position') as THREE.BufferAttribute | undefined;
    if (attribute && this.markerIds.length > 0 && attribute.count === this.markerIds.length) {
      const out = attribute.array as Float32Array;
      for (let k = 0; k < this.markerIds.length; ++k) {
        const i = this.view.indexOf(this.markerIds[k]);
        if (i < 0) {
          out[3 * k] = out[3 * k + 1] = out[3 * k + 2] = NaN;
        } else {
          out[3 * k] = positions[3 * i];
          out[3 * k + 1] = positions[3 * i + 1];
          out[3 * k + 2] = positions[3 * i + 2];
        }
      }
      attribute.needsUpdate = true;
    }
    if (this.pointers.length > 0) {
      const anchors = new Float32Array(3 * this.pointers.length);
      this.pointers.forEach((p, k) => {
        const i = this.view.indexOf(p.vertex);
        if (i >= 0) p.sphere.position.fromArray(positions, 3 * i);
        else p.sphere.position.copy(p.fallback);
        p.sphere.position.toArray(anchors, 3 * k);
      });
      const projected = new Float32Array(2 * this.pointers.length);
      this.view.projectPoints(anchors, this.pointers.length, projected);
      this.pointers.forEach((p, k) => {
        const x = projected[2 * k];
        const y = projected[2 * k + 1];
        const hidden = Number.isNaN(x);
        if (p.label.hidden !== hidden) p.label.hidden = hidden;
        if (!hidden) p.label.style.transform = `translate(${Math.round(x + LABEL_GAP)}px, ${Math.round(y + LABEL_GAP)}px)`;
      });
    }
    this.view.invalidate();
  }

  // The panel: a line per participant (swatch, name, role, what they do).
  private renderList(): void {
    if (this.participants.length === 0) {
      this.list.replaceChildren(noteLine('No one is here.'));
      return;
    }
    this.list.replaceChildren(...this.participants.map((p) => {
      const item = participantLine(p.name, p.colour, (p.name || '(unnamed client)') + (p.you ? ' (you)' : ''), [p.role],
        activity(p, this.baseIds.length) || undefined);
      item.dataset.role = p.role;
      return item;
    }));
  }
}

// This page's pointer for the others: where it points on the mesh (the
// vertex under it, an original id), at most every POINTER_INTERVAL_MS and
// only when that vertex changes; cleared when the pointer leaves the mesh.
export class PointerSender {
  private at: { x: number; y: number } | null = null;
  private sent: number | null | undefined = undefined;  // the vertex last sent (null: none; undefined: nothing sent yet)
  private readonly paced: PacedCalls;
  calls = 0;
  lastVertex: number | null = null;

  constructor(private readonly view: MeshView, private readonly client: SessionClient, private readonly ownName: string,
              private readonly failed: (error: unknown) => void) {
    this.paced = new PacedCalls(() => this.send(), undefined, POINTER_INTERVAL_MS);
    view.canvas.addEventListener('pointermove', (event) => {
      this.at = { x: event.clientX, y: event.clientY };
      this.paced.request();
    }, { passive: true });
    view.canvas.addEventListener('pointerleave', () => {
      this.at = null;
      this.paced.request();
    }, { passive: true });
  }

  private async send(): Promise<void> {
    // A task of its own: not inside the pointer event that asked (input stays quick).
    await new Promise((resolve) => setTimeout(resolve, 0));
    const vertex = this.at === null ? null : this.view.pointVertex(this.at.x, this.at.y);
    if (vertex === this.sent) return;
    const p = vertex === null ? null : this.view.positionOf(vertex);
    this.sent = vertex;
    try {
      await this.client.setPresence(this.ownName, p === null || vertex === null ? null : { x: p.x, y: p.y, z: p.z, vertex });
      ++this.calls;
      this.lastVertex = vertex;
    } catch (error) {
      this.sent = undefined;  // sent again with the next move
      if (isCode(error, Code.Unimplemented) || isCode(error, Code.NotFound)) this.paced.enabled = false;
      this.failed(error);
    }
  }
}
