// Editing by dragging the mesh (editor token), in one of two modes.
//
// Pull (the default, proportional editing as in DCC tools): a press on the
// mesh takes the nearest corner of the triangle under the pointer, and
// dragging moves the base vertices around it by the drag times a smooth
// falloff of their distance (geometry.ts, falloff), 1 at the pressed point
// and 0 at the radius of influence and beyond: the neighbourhood follows, the
// far side stays in place. Each step sends the partial pose of those base
// vertices with SubmitPose, one call in flight (newest wins).
//
// Handles: the pressed vertex becomes a handle (a sphere at its target);
// every change sends all of this page's handles with SetHandles, and the
// server solves the base pose (as-rigid-as-possible: the whole mesh follows
// one handle). A right-click on a handle drops it.
//
// In both, the target moves in the plane facing the camera, and presses on
// the background orbit as usual. The frames come back on Watch. Vertices are
// original ids whatever level of detail is drawn (MeshView maps them).
//
// Every call of one drag carries the drag's gesture id (gesture.ts): the
// server keeps the drag as one history entry, which one undo takes back.
// Dropping a handle and clearing them are gestures of their own.

import * as THREE from 'three';

import { Code, isCode, type HandleTarget, type SessionClient } from './client';
import { falloff } from './geometry';
import { newGestureId } from './gesture';
import { LatestSender } from './latest-sender';
import type { MeshView } from './scene';

export type EditMode = 'pull' | 'handles';

// A partial pose: base vertex indices and 3 coordinates each, and the drag it is part of.
interface PartialPose { indices: number[]; positions: number[]; gesture: bigint }
// This page's whole set of handles, and the gesture that changed it.
interface HandleSet { handles: HandleTarget[]; gesture: bigint }

export const EDITOR_NEEDED = 'Handles need the editor token; this page was opened with another token ' +
  '(orbit, zoom and the overlays still work).';

export interface HandleEvents {
  // A note for the panel (bad: an error).
  status(text: string, bad?: boolean): void;
  // After every change: this page's handles, and everyone's after the last answer.
  counts(own: number, inSession: number | null): void;
  describe(error: unknown): string;
  // An edit was sent; call the result with the version it was accepted at.
  sent(): (acceptedAt: bigint) => void;
  // A pull or a handle drag started (frames will follow).
  started?(): void;
}

export class HandleEditor {
  private readonly spheres = new Map<number, THREE.Mesh>();  // vertex → sphere at its target
  private readonly group = new THREE.Group();
  private readonly sphere: THREE.SphereGeometry;
  private readonly idle = new THREE.MeshBasicMaterial({ color: 0x39d0ff, depthTest: false });
  private readonly active = new THREE.MeshBasicMaterial({ color: 0xffe14d, depthTest: false });
  private readonly sender = new LatestSender<HandleSet>((set) => this.send(set));
  private readonly poses = new LatestSender<PartialPose>((pose) => this.sendPose(pose));
  private drag: { vertex: number; pointerId: number; plane: THREE.Plane; gesture: bigint } | null = null;
  // The pull in progress: where the pressed point started, and the base
  // vertices it moves with their start positions and weights.
  private pull: {
    pointerId: number; plane: THREE.Plane; start: THREE.Vector3; indices: number[]; from: Float32Array; weights: Float32Array;
    gesture: bigint;
  } | null = null;
  private readonly cursor: THREE.Mesh;       // the pressed point while pulling
  private readonly influence: THREE.Mesh;    // the radius of influence around it
  private refused = false;  // the server refused this page's token for editing
  private nextPoseId = 1n;
  mode: EditMode = 'pull';
  radius: number;           // of influence, world units
  inSession: number | null = null;
  answered = 0;             // SetHandles or SubmitPose calls answered OK
  acceptedAt = 0n;          // the version the last of them was accepted at
  pulledVertices = 0;       // base vertices the last pull moved

  // `originalIds[i]`: the detailed-mesh vertex base vertex i is.
  constructor(private readonly view: MeshView, private readonly client: SessionClient,
              readonly clientName: string, private readonly originalIds: Uint32Array, private readonly events: HandleEvents) {
    this.sphere = new THREE.SphereGeometry(view.radius * 0.02, 16, 12);
    this.radius = view.radius * 0.35;
    this.group.renderOrder = 2;
    view.add(this.group);
    this.cursor = new THREE.Mesh(this.sphere, this.active);
    this.influence = new THREE.Mesh(new THREE.SphereGeometry(1, 32, 16),
      new THREE.MeshBasicMaterial({ color: 0xffe14d, transparent: true, opacity: 0.12, depthWrite: false }));
    this.cursor.visible = this.influence.visible = false;
    this.cursor.renderOrder = this.influence.renderOrder = 2;
    view.add(this.cursor);
    view.add(this.influence);
    // Capture phase on the container: runs before the orbit controls' own
    // listener on the canvas, which never sees a press that starts a drag.
    view.canvas.parentElement!.addEventListener('pointerdown', this.onDown, { capture: true });
    view.canvas.addEventListener('pointermove', this.onMove);
    view.canvas.addEventListener('pointerup', this.onUp);
    view.canvas.addEventListener('pointercancel', this.onUp);
  }

  private readonly onDown = (e: PointerEvent) => this.down(e);
  private readonly onMove = (e: PointerEvent) => this.move(e);
  private readonly onUp = (e: PointerEvent) => this.up(e);

  // No editing on this page any more (a viewer token): presses orbit.
  detach(): void {
    this.endDrag();
    this.endPull();
    this.view.canvas.parentElement!.removeEventListener('pointerdown', this.onDown, { capture: true });
    this.view.canvas.removeEventListener('pointermove', this.onMove);
    this.view.canvas.removeEventListener('pointerup', this.onUp);
    this.view.canvas.removeEventListener('pointercancel', this.onUp);
    this.group.clear();
    this.spheres.clear();
  }

  get count(): number {
    return this.spheres.size;
  }

  // A pull or a handle drag is in progress.
  get interacting(): boolean {
    return this.drag !== null || this.pull !== null;
  }

  // A SetHandles or SubmitPose call is running or waiting.
  get sending(): boolean {
    return !this.sender.idle || !this.poses.idle;
  }

  // The page point → the vertex a press there would take (null: none).
  vertexAt(clientX: number, clientY: number): number | null {
    const handle = this.handleAt(clientX, clientY);
    if (handle !== null) return handle;
    return this.view.pickVertex(clientX, clientY);
  }

  clear(): void {
    this.endDrag();
    for (const vertex of [...this.spheres.keys()]) this.removeSphere(vertex);
    this.changed(newGestureId());
  }

  // This page's handles as the server has them now (after an undo, redo or
  // restore changed them there): drawn, not sent. Not while a drag or a
  // call is under way (the page's own set is the newer one then).
  adopt(handles: readonly HandleTarget[]): void {
    if (this.drag || !this.sender.idle) return;
    const key = (list: Iterable<HandleTarget>) => [...list].map((h) => `${h.vertex},${h.x},${h.y},${h.z}`).join(';');
    const own = [...this.spheres].map(([vertex, { position: p }]) => ({ vertex, x: p.x, y: p.y, z: p.z }));
    if (key(own) === key(handles)) return;
    for (const vertex of [...this.spheres.keys()]) this.removeSphere(vertex);
    for (const h of handles) this.addSphere(h.vertex, new THREE.Vector3(h.x, h.y, h.z));
    this.view.invalidate();
    this.events.counts(this.spheres.size, this.inSession);
  }

  private down(event: PointerEvent): void {
    if (this.drag) return;
    if (event.button === 2) {
      const handle = this.handleAt(event.clientX, event.clientY);
      if (handle === null) return;  // a pan
      stop(event);
      this.removeSphere(handle);
      this.changed(newGestureId());
      return;
    }
    if (event.button !== 0) return;
    if (this.mode === 'pull') {
      this.startPull(event);
      return;
    }
    let vertex = this.handleAt(event.clientX, event.clientY);
    if (vertex === null) {
      vertex = this.view.pickVertex(event.clientX, event.clientY);
      if (vertex === null) return;  // the background: an orbit
      if (this.refused) {
        this.events.status(EDITOR_NEEDED, true);
        return;
      }
      const at = this.view.positionOf(vertex);
      if (at === null) return;
      this.addSphere(vertex, at);
    }
    stop(event);
    const sphere = this.spheres.get(vertex)!;
    sphere.material = this.active;
    this.view.setOrbitEnabled(false);
    this.view.canvas.setPointerCapture(event.pointerId);
    this.drag = { vertex, pointerId: event.pointerId, plane: this.view.facingPlane(sphere.position), gesture: newGestureId() };
    this.events.started?.();
    this.changed(this.drag.gesture);
  }

  private startPull(event: PointerEvent): void {
    if (this.pull) return;
    const vertex = this.view.pickVertex(event.clientX, event.clientY);
    if (vertex === null) return;  // the background: an orbit
    if (this.refused) {
      this.events.status(EDITOR_NEEDED, true);
      return;
    }
    const start = this.view.positionOf(vertex);
    if (start === null) return;
    stop(event);
    const p = this.view.positions;
    const indices: number[] = [];
    const from: number[] = [];
    const weights: number[] = [];
    const r2 = this.radius * this.radius;
    for (let i = 0; i < this.originalIds.length; ++i) {
      // Base vertices are in every level of detail (levels grow from the base).
      const at = this.view.indexOf(this.originalIds[i]);
      if (at < 0) continue;
      const o = 3 * at;
      const d2 = (p[o] - start.x) ** 2 + (p[o + 1] - start.y) ** 2 + (p[o + 2] - start.z) ** 2;
      if (d2 >= r2) continue;
      const w = falloff(Math.sqrt(d2), this.radius);
      if (w <= 0) continue;
      indices.push(i);
      from.push(p[o], p[o + 1], p[o + 2]);
      weights.push(w);
    }
    if (indices.length === 0) {
      this.events.status('No base vertex within the radius of influence: make it larger.', true);
      return;
    }
    this.pull = {
      pointerId: event.pointerId, plane: this.view.facingPlane(start), start, indices,
      from: Float32Array.from(from), weights: Float32Array.from(weights), gesture: newGestureId(),
    };
    this.pulledVertices = indices.length;
    this.cursor.position.copy(start);
    this.influence.position.copy(start);
    this.influence.scale.setScalar(this.radius);
    this.cursor.visible = this.influence.visible = true;
    this.view.setOrbitEnabled(false);
    this.view.canvas.setPointerCapture(event.pointerId);
    this.view.invalidate();
    this.events.started?.();
    this.events.status(`Pulling ${indices.length} base ${indices.length === 1 ? 'vertex' : 'vertices'}.`);
  }

  private movePull(event: PointerEvent): void {
    const pull = this.pull!;
    const point = this.view.rayAt(event.clientX, event.clientY).ray.intersectPlane(pull.plane, new THREE.Vector3());
    if (!point) return;
    this.cursor.position.copy(point);
    this.view.invalidate();
    const d = point.sub(pull.start);
    const positions = new Array<number>(3 * pull.indices.length);
    for (let k = 0; k < pull.indices.length; ++k) {
      const w = pull.weights[k];
      positions[3 * k] = pull.from[3 * k] + w * d.x;
      positions[3 * k + 1] = pull.from[3 * k + 1] + w * d.y;
      positions[3 * k + 2] = pull.from[3 * k + 2] + w * d.z;
    }
    this.poses.push({ indices: pull.indices, positions, gesture: pull.gesture });
  }

  private endPull(): void {
    const pull = this.pull;
    if (!pull) return;
    if (this.view.canvas.hasPointerCapture(pull.pointerId)) this.view.canvas.releasePointerCapture(pull.pointerId);
    this.pull = null;
    this.cursor.visible = this.influence.visible = false;
    this.view.setOrbitEnabled(true);
    this.view.invalidate();
  }

  private async sendPose(pose: PartialPose): Promise<void> {
    const accepted = this.events.sent();
    try {
      const at = await this.client.submitPose(this.nextPoseId++, pose.positions, this.clientName, pose.indices, pose.gesture);
      accepted(at);
      this.acceptedAt = at;
      ++this.answered;
    } catch (error) {
      if (isCode(error, Code.PermissionDenied)) {
        this.refused = true;
        this.endPull();
        this.events.status(EDITOR_NEEDED, true);
      } else {
        this.events.status(this.events.describe(error), true);
      }
    }
  }

  private move(event: PointerEvent): void {
    if (this.pull && event.pointerId === this.pull.pointerId) {
      this.movePull(event);
      return;
    }
    if (!this.drag || event.pointerId !== this.drag.pointerId) return;
    const point = this.view.rayAt(event.clientX, event.clientY).ray.intersectPlane(this.drag.plane, new THREE.Vector3());
    if (!point) return;  // the plane is edge-on
    this.spheres.get(this.drag.vertex)!.position.copy(point);
    this.changed(this.drag.gesture);
  }

  private up(event: PointerEvent): void {
    if (this.pull && event.pointerId === this.pull.pointerId) this.endPull();
    if (this.drag && event.pointerId === this.drag.pointerId) this.endDrag();
  }

  private endDrag(): void {
    if (!this.drag) return;
    const sphere = this.spheres.get(this.drag.vertex);
    if (sphere) sphere.material = this.idle;
    if (this.view.canvas.hasPointerCapture(this.drag.pointerId)) this.view.canvas.releasePointerCapture(this.drag.pointerId);
    this.drag = null;
    this.view.setOrbitEnabled(true);
    this.view.invalidate();
  }

  private handleAt(clientX: number, clientY: number): number | null {
    const hit = this.view.rayAt(clientX, clientY).intersectObjects(this.group.children, false)[0];
    return hit ? hit.object.userData.vertex as number : null;
  }

  private addSphere(vertex: number, target: THREE.Vector3): void {
    const sphere = new THREE.Mesh(this.sphere, this.idle);
    sphere.position.copy(target);
    sphere.userData.vertex = vertex;
    sphere.renderOrder = 2;
    this.spheres.set(vertex, sphere);
    this.group.add(sphere);
  }

  private removeSphere(vertex: number): void {
    const sphere = this.spheres.get(vertex);
    if (sphere) this.group.remove(sphere);
    this.spheres.delete(vertex);
  }

  // The local set changed (by the gesture `gesture`): redraw, and send it.
  private changed(gesture: bigint): void {
    this.view.invalidate();
    this.events.counts(this.spheres.size, this.inSession);
    this.sender.push({
      handles: [...this.spheres].map(([vertex, { position: p }]) => ({ vertex, x: p.x, y: p.y, z: p.z })), gesture,
    });
  }

  private async send({ handles, gesture }: HandleSet): Promise<void> {
    const accepted = this.events.sent();
    try {
      const answer = await this.client.setHandles(this.clientName, handles, gesture);
      accepted(answer.acceptedAtVersion);
      this.inSession = answer.handlesInSession;
      this.acceptedAt = answer.acceptedAtVersion;
      ++this.answered;
      this.events.counts(this.spheres.size, this.inSession);
      this.events.status(handles.length === 0 ? 'Handles cleared.' : '');
    } catch (error) {
      if (isCode(error, Code.PermissionDenied)) {
        // A viewer token: nothing this page does will be accepted.
        this.refused = true;
        this.endDrag();
        for (const vertex of [...this.spheres.keys()]) this.removeSphere(vertex);
        this.events.counts(0, this.inSession);
        this.events.status(EDITOR_NEEDED, true);
      } else {
        this.events.status(this.events.describe(error), true);
      }
    }
  }
}

function stop(event: Event): void {
  event.stopPropagation();
  event.preventDefault();
}
