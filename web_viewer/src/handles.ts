// Handle editing (editor token): a press on the mesh makes the nearest corner
// of the triangle under the pointer a handle (a sphere at its target), and
// dragging moves the target in the plane facing the camera. Every change sends
// all of this page's handles with SetHandles, one call in flight (newest
// wins); the server solves the base pose and the frame comes back on Watch.
// A right-click on a handle drops it. Presses on the background orbit as usual.
import * as THREE from 'three';

import { Code, isCode, type HandleTarget, type SessionClient } from './client';
import { LatestSender } from './latest-sender';
import type { MeshView } from './scene';

export const EDITOR_NEEDED = 'Handles need the editor token; this page was opened with another token ' +
  '(orbit, zoom and the overlays still work).';

export interface HandleEvents {
  // A note for the panel (bad: an error).
  status(text: string, bad?: boolean): void;
  // After every change: this page's handles, and everyone's after the last answer.
  counts(own: number, inSession: number | null): void;
  describe(error: unknown): string;
}

// The corner of the hit triangle nearest to the hit point.
export function nearestCorner(hit: THREE.Intersection, positions: Float32Array): number | null {
  if (!hit.face) return null;
  let best: number | null = null;
  let bestDistance = Infinity;
  for (const v of [hit.face.a, hit.face.b, hit.face.c]) {
    const d = hit.point.distanceToSquared(new THREE.Vector3().fromArray(positions, 3 * v));
    if (d < bestDistance) [best, bestDistance] = [v, d];
  }
  return best;
}

export class HandleEditor {
  private readonly spheres = new Map<number, THREE.Mesh>();  // vertex → sphere at its target
  private readonly group = new THREE.Group();
  private readonly sphere: THREE.SphereGeometry;
  private readonly idle = new THREE.MeshBasicMaterial({ color: 0x39d0ff, depthTest: false });
  private readonly active = new THREE.MeshBasicMaterial({ color: 0xffe14d, depthTest: false });
  private readonly sender = new LatestSender<HandleTarget[]>((handles) => this.send(handles));
  private drag: { vertex: number; pointerId: number; plane: THREE.Plane } | null = null;
  private refused = false;  // the server refused this page's token for editing
  inSession: number | null = null;
  answered = 0;             // SetHandles calls answered OK
  acceptedAt = 0n;          // the version the last of them was accepted at

  constructor(private readonly view: MeshView, private readonly client: SessionClient,
              readonly clientName: string, private readonly events: HandleEvents) {
    this.sphere = new THREE.SphereGeometry(view.radius * 0.02, 16, 12);
    this.group.renderOrder = 2;
    view.add(this.group);
    // Capture phase on the container: runs before the orbit controls' own
    // listener on the canvas, which never sees a press that starts a drag.
    view.canvas.parentElement!.addEventListener('pointerdown', (e) => this.down(e), { capture: true });
    view.canvas.addEventListener('pointermove', (e) => this.move(e));
    view.canvas.addEventListener('pointerup', (e) => this.up(e));
    view.canvas.addEventListener('pointercancel', (e) => this.up(e));
  }

  get count(): number {
    return this.spheres.size;
  }

  // A SetHandles call is running or waiting.
  get sending(): boolean {
    return !this.sender.idle;
  }

  // The page point → the vertex a press there would take (null: none).
  vertexAt(clientX: number, clientY: number): number | null {
    const handle = this.handleAt(clientX, clientY);
    if (handle !== null) return handle;
    const hit = this.view.pick(clientX, clientY);
    return hit && nearestCorner(hit, this.view.positions);
  }

  clear(): void {
    this.endDrag();
    for (const vertex of [...this.spheres.keys()]) this.removeSphere(vertex);
    this.changed();
  }

  private down(event: PointerEvent): void {
    if (this.drag) return;
    if (event.button === 2) {
      const handle = this.handleAt(event.clientX, event.clientY);
      if (handle === null) return;  // a pan
      stop(event);
      this.removeSphere(handle);
      this.changed();
      return;
    }
    if (event.button !== 0) return;
    let vertex = this.handleAt(event.clientX, event.clientY);
    if (vertex === null) {
      const hit = this.view.pick(event.clientX, event.clientY);
      vertex = hit && nearestCorner(hit, this.view.positions);
      if (vertex === null) return;  // the background: an orbit
      if (this.refused) {
        this.events.status(EDITOR_NEEDED, true);
        return;
      }
      this.addSphere(vertex, new THREE.Vector3().fromArray(this.view.positions, 3 * vertex));
    }
    stop(event);
    const sphere = this.spheres.get(vertex)!;
    sphere.material = this.active;
    this.view.setOrbitEnabled(false);
    this.view.canvas.setPointerCapture(event.pointerId);
    this.drag = { vertex, pointerId: event.pointerId, plane: this.view.facingPlane(sphere.position) };
    this.changed();
  }

  private move(event: PointerEvent): void {
    if (!this.drag || event.pointerId !== this.drag.pointerId) return;
    const point = this.view.rayAt(event.clientX, event.clientY).ray.intersectPlane(this.drag.plane, new THREE.Vector3());
    if (!point) return;  // the plane is edge-on
    this.spheres.get(this.drag.vertex)!.position.copy(point);
    this.changed();
  }

  private up(event: PointerEvent): void {
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

  // The local set changed: redraw, and send it.
  private changed(): void {
    this.view.invalidate();
    this.events.counts(this.spheres.size, this.inSession);
    this.sender.push([...this.spheres].map(([vertex, { position: p }]) => ({ vertex, x: p.x, y: p.y, z: p.z })));
  }

  private async send(handles: HandleTarget[]): Promise<void> {
    try {
      const answer = await this.client.setHandles(this.clientName, handles);
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
