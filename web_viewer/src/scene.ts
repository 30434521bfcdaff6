// The three.js side: the detailed mesh (one geometry for the whole session,
// its position and normal arrays swapped for each finished frame of the
// session worker), lights that bring out surface detail, and an orbit camera
// that frames the mesh from its front (geometry.ts, frameMesh) on load, on
// "f" and on the Fit button; picking and screen projection for editing.
// Draws on requestAnimationFrame only when something changed, and times the
// draw apart from the page's own JavaScript (SwiftShader runs the vertex stage
// on the CPU, inside the draw call).
//
// At a level of detail (levels.ts) the geometry is the level's (setLevel
// swaps it whole) and vertex i of it is original vertex ids[i]: everything
// here that names a vertex to the outside (picking, projection, positions)
// names it by its original id.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

import { firstHit, fitDistance, type Framing } from './geometry';
import { levelIndexOf } from './levels';

const FOV = 40;
const REFINE_MS = 300;
const SLOW_DRAW_MS = 50;
const FAST_DRAW_MS = 25;
const MIN_PIXEL_RATIO = 0.5;


export class MeshView {
  readonly scene = new THREE.Scene();
  readonly geometry = new THREE.BufferGeometry();
  readonly mesh: THREE.Mesh;
  readonly radius: number;  // of the rest mesh's bounding sphere
  private readonly renderer: THREE.WebGLRenderer;
  private readonly camera: THREE.PerspectiveCamera;
  private readonly controls: OrbitControls;
  private positionAttribute: THREE.BufferAttribute;
  private normalAttribute: THREE.BufferAttribute;
  private dirty = true;
  // The coarse stand-in (geometry.ts, coarseIndex), drawn while frames
  // stream or the view moves, in a geometry of its own sharing the position
  // and normal attributes; `geometry` (its full index) when things are still.
  private coarse: THREE.BufferGeometry | null = null;
  // The original id of each vertex drawn (a level of detail); null: the full
  // mesh, whose vertex indices are the ids.
  private ids: Uint32Array | null = null;
  private lastChange = -Infinity;
  private refineTimer: ReturnType<typeof setTimeout> | undefined;
  framesRendered = 0;
  coarseDraws = 0;
  // How long the browser takes to show a draw (the time from the animation
  // frame that drew to the next one: with software compositing the page's
  // thread waits for the GPU's readback in between), smoothed; and what is
  // done about it: a lower pixel ratio, then fewer draws (see render()).
  drawShowMs = 0;
  pixelRatio: number;
  private lastFrameAt = -Infinity;
  private drewLastFrame = false;
  // The last draw was full detail of a mesh with a stand-in, and how long such a draw took to show.
  lastDrawFull = false;
  fullShowMs = 0;
  private lastDrawAt = -Infinity;
  private lastAdjust = 0;
  // Called after each draw with the version drawn, the draw's duration (the
  // uploads and the draw call) and its end time.
  onDrawn: (drawMs: number, at: number) => void = () => {};
  // Called when the camera moved or the view was resized (not for frames):
  // what is placed over the canvas by projecting follows.
  private readonly viewListeners: (() => void)[] = [];
  // The container's size in CSS pixels, as of the last resize (projection
  // without a layout read).
  private cssWidth = 0;
  private cssHeight = 0;
  // The canvas's place on the page, as of the last resize or pointer entry (pointVertex: no layout read per call).
  private canvasRect: { left: number; top: number; width: number; height: number } = { left: 0, top: 0, width: 0, height: 0 };
  private readonly scratch = new THREE.Vector3();

  // `dense`: a mesh heavy enough to be drawn coarser while busy; it is drawn
  // without multisampling (its triangles are mostly smaller than a pixel).
  constructor(private readonly container: HTMLElement, positions: Float32Array, normals: Float32Array,
              faces: Uint32Array, private readonly framing: Framing, dense = false) {
    this.positionAttribute = new THREE.BufferAttribute(positions, 3).setUsage(THREE.DynamicDrawUsage);
    this.normalAttribute = new THREE.BufferAttribute(normals, 3).setUsage(THREE.DynamicDrawUsage);
    this.geometry.setAttribute('position', this.positionAttribute);
    this.geometry.setAttribute('normal', this.normalAttribute);
    this.geometry.setIndex(new THREE.BufferAttribute(faces, 1));
    const [cx, cy, cz] = framing.center;
    this.geometry.boundingSphere = new THREE.Sphere(new THREE.Vector3(cx, cy, cz), framing.radius);

    // Pushed back a little in depth: lines on the surface (the cut mesh) stay in front of it.
    const material = new THREE.MeshStandardMaterial({
      color: 0xc9bfae, roughness: 0.55, metalness: 0.0, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
    });
    this.mesh = new THREE.Mesh(this.geometry, material);
    // Frames move vertices beyond the rest bounding sphere; recomputing it
    // per frame costs a pass over every vertex, not culling costs nothing.
    this.mesh.frustumCulled = false;
    this.scene.add(this.mesh);
    this.scene.background = new THREE.Color(0x1d2024);

    this.renderer = new THREE.WebGLRenderer({ antialias: !dense });
    this.renderer.setPixelRatio(window.devicePixelRatio);
    this.pixelRatio = window.devicePixelRatio;
    this.renderer.domElement.tabIndex = 0;
    this.renderer.domElement.setAttribute('aria-label', 'The session\'s mesh: drag to orbit, wheel to zoom, F to fit');
    container.appendChild(this.renderer.domElement);

    this.radius = framing.radius;
    this.camera = new THREE.PerspectiveCamera(FOV, 1, framing.radius / 100, framing.radius * 100);
    // OrbitControls reads camera.up once, when it is made: up first.
    this.camera.up.set(...framing.up);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => {
      this.updateClipping();
      this.moved();
      this.viewChanged();
    });

    // A sky/ground hemisphere for the overall shape, plus a key light that
    // rides with the camera at a grazing angle: fine relief stays visible
    // from every viewpoint.
    const hemisphere = new THREE.HemisphereLight(0xf4f1ea, 0x2a2622, 0.8);
    hemisphere.position.set(...framing.up);
    this.scene.add(hemisphere);
    const key = new THREE.DirectionalLight(0xffffff, 2.4);
    // Both ends in camera space: the light comes from the upper right at
    // about 55° to the view direction, whatever the orbit.
    key.position.set(1.5, 1.5, 0.5);
    key.target.position.set(0, 0, -1);
    this.camera.add(key, key.target);
    this.scene.add(this.camera);

    new ResizeObserver(() => this.resize()).observe(container);
    this.renderer.domElement.addEventListener('pointerenter', () => { this.canvasRect = this.canvas.getBoundingClientRect(); });
    this.resize();
    this.fit();
    this.renderer.setAnimationLoop(() => this.render());
  }

  // The live positions (rest + the drawn frame's deltas): replaced, not
  // rewritten, by every frame (setBuffers).
  get positions(): Float32Array {
    return this.positionAttribute.array as Float32Array;
  }

  get normals(): Float32Array {
    return this.normalAttribute.array as Float32Array;
  }

  // The mesh whole and from its front, orbiting about its centre.
  fit(): void {
    const f = this.framing;
    const distance = fitDistance(f, this.camera.fov, this.camera.aspect);
    const [cx, cy, cz] = f.center;
    this.controls.target.set(cx, cy, cz);
    this.camera.up.set(...f.up);
    this.camera.position.set(cx + distance * f.front[0], cy + distance * f.front[1], cz + distance * f.front[2]);
    this.camera.lookAt(this.controls.target);
    this.controls.update();
    this.updateClipping();
    this.invalidate();
    this.viewChanged();
  }

  // The container's size in CSS pixels (as of the last resize).
  get cssSize(): { width: number; height: number } {
    return { width: this.cssWidth, height: this.cssHeight };
  }

  // `listener` runs after every camera move or resize.
  onViewChange(listener: () => void): void {
    this.viewListeners.push(listener);
  }

  private viewChanged(): void {
    for (const listener of this.viewListeners) listener();
  }

  // Projects `count` world points (xyz in `world`) to the container's CSS
  // pixels: out[2k], out[2k + 1]; NaN for a point behind the camera. No
  // allocation and no layout read (the size is the last resize's).
  projectPoints(world: ArrayLike<number>, count: number, out: Float32Array): void {
    this.camera.updateMatrixWorld();
    const v = this.scratch;
    for (let k = 0; k < count; ++k) {
      v.set(world[3 * k], world[3 * k + 1], world[3 * k + 2]).applyMatrix4(this.camera.matrixWorldInverse);
      const behind = v.z >= 0;
      v.applyMatrix4(this.camera.projectionMatrix);
      out[2 * k] = behind ? NaN : (v.x + 1) / 2 * this.cssWidth;
      out[2 * k + 1] = behind ? NaN : (1 - v.y) / 2 * this.cssHeight;
    }
  }

  // Near and far planes from the mesh's size and the camera's distance to it.
  private updateClipping(): void {
    const distance = this.camera.position.distanceTo(this.controls.target);
    const r = this.radius;
    this.camera.near = Math.max(r / 1000, (distance - 2 * r) * 0.5, distance / 1000);
    this.camera.far = distance + 4 * r;
    this.camera.updateProjectionMatrix();
  }

  // Draw the coarse stand-in (triangles over the same vertices) while busy; null: none.
  setCoarse(faces: Uint32Array | null): void {
    this.disposeCoarse();
    if (faces === null) return;
    this.coarse = new THREE.BufferGeometry();
    this.coarse.setAttribute('position', this.positionAttribute);
    this.coarse.setAttribute('normal', this.normalAttribute);
    this.coarse.setIndex(new THREE.BufferAttribute(faces, 1));
    this.coarse.boundingSphere = this.geometry.boundingSphere;
  }

  // Frees the stand-in's own GPU buffer (its index), not the shared ones.
  private disposeCoarse(): void {
    if (this.coarse === null) return;
    if (this.mesh.geometry === this.coarse) this.mesh.geometry = this.geometry;
    this.coarse.deleteAttribute('position');
    this.coarse.deleteAttribute('normal');
    this.coarse.dispose();
    this.coarse = null;
  }

  // Another mesh to draw: a level of detail (ids: each vertex's original id)
  // or the full mesh again (ids null), with its first state. The old
  // geometry's GPU buffers are freed; overlays sharing its attributes must
  // rebind to the new ones (this.geometry, the same object, holds them).
  // Returns the arrays replaced. The uploads happen at the next draw.
  setLevel(positions: Float32Array, normals: Float32Array, faces: Uint32Array, coarse: Uint32Array | null,
    ids: Uint32Array | null): { positions: Float32Array; normals: Float32Array } {
    const old = { positions: this.positions, normals: this.normals };
    this.disposeCoarse();
    this.geometry.dispose();
    this.positionAttribute = new THREE.BufferAttribute(positions, 3).setUsage(THREE.DynamicDrawUsage);
    this.normalAttribute = new THREE.BufferAttribute(normals, 3).setUsage(THREE.DynamicDrawUsage);
    this.geometry.setAttribute('position', this.positionAttribute);
    this.geometry.setAttribute('normal', this.normalAttribute);
    this.geometry.setIndex(new THREE.BufferAttribute(faces, 1));
    this.setCoarse(coarse);
    this.ids = ids;
    this.fullShowMs = 0;  // of the old mesh
    this.moved();
    return old;
  }

  // Vertices drawn.
  get vertexCount(): number {
    return this.positionAttribute.count;
  }

  // The original ids of the vertices drawn (null: the full mesh, every id).
  get levelIds(): Uint32Array | null {
    return this.ids;
  }

  // The index drawn of original vertex `id`, −1 when the level lacks it.
  indexOf(id: number): number {
    return levelIndexOf(this.ids, id, this.vertexCount);
  }

  // The original id of drawn vertex `index`.
  idOf(index: number): number {
    return this.ids === null ? index : this.ids[index];
  }

  // Where original vertex `id` is now (null: not drawn at this level).
  positionOf(id: number): THREE.Vector3 | null {
    const i = this.indexOf(id);
    return i < 0 ? null : new THREE.Vector3().fromArray(this.positions, 3 * i);
  }

  // Something moves (a frame, the camera): coarse for a while if there is a stand-in.
  private moved(): void {
    this.lastChange = performance.now();
    this.invalidate();
  }

  // A finished frame: draw from these arrays from now on; returns the arrays
  // they replace (no longer needed: the draw uploads from the new ones).
  setBuffers(positions: Float32Array, normals: Float32Array): { positions: Float32Array; normals: Float32Array } {
    const old = { positions: this.positions, normals: this.normals };
    this.positionAttribute.array = positions;
    this.normalAttribute.array = normals;
    this.positionAttribute.needsUpdate = true;
    this.normalAttribute.needsUpdate = true;
    this.moved();
    return old;
  }

  add(object: THREE.Object3D): void {
    this.scene.add(object);
    this.invalidate();
  }

  invalidate(): void {
    this.dirty = true;
  }

  get canvas(): HTMLCanvasElement {
    return this.renderer.domElement;
  }

  // Off while a handle is dragged, so that the drag does not also orbit.
  setOrbitEnabled(enabled: boolean): void {
    this.controls.enabled = enabled;
  }

  // A ray from the camera through the page point (clientX, clientY).
  rayAt(clientX: number, clientY: number): THREE.Raycaster {
    const rect = this.canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    const raycaster = new THREE.Raycaster();
    raycaster.setFromCamera(ndc, this.camera);
    return raycaster;
  }

  // The vertex a press at the page point takes (its original id): the
  // corner nearest to the hit of the triangle under it (null: the
  // background). On a mesh with a stand-in the ray is cast against the
  // stand-in (tens of thousands of triangles, not millions: a press answers
  // at once) and the vertex is the mesh's nearest to that hit.
  pickVertex(clientX: number, clientY: number): number | null {
    // three.js skips meshes whose bounding sphere the ray misses, and frames
    // move vertices out of the rest sphere: refresh it (one pass, per press).
    this.geometry.computeBoundingSphere();
    const drawn = this.mesh.geometry;
    this.mesh.geometry = this.coarse ?? this.geometry;
    this.mesh.geometry.boundingSphere = this.geometry.boundingSphere;
    const hit = this.rayAt(clientX, clientY).intersectObject(this.mesh, false)[0] ?? null;
    this.mesh.geometry = drawn;
    if (!hit?.face) return null;
    const p = this.positions;
    const { x, y, z } = hit.point;
    const distance = (v: number) => (p[3 * v] - x) ** 2 + (p[3 * v + 1] - y) ** 2 + (p[3 * v + 2] - z) ** 2;
    const candidates = this.coarse ? null : [hit.face.a, hit.face.b, hit.face.c];
    let best = -1;
    let bestDistance = Infinity;
    const count = candidates ? candidates.length : p.length / 3;
    for (let k = 0; k < count; ++k) {
      const v = candidates ? candidates[k] : k;
      const d = distance(v);
      if (d < bestDistance) [best, bestDistance] = [v, d];
    }
    return best < 0 ? null : this.idOf(best);
  }

  // The vertex under a page point, cheaply enough to follow a pointer (the
  // pointer others see, up to 10 times a second): the corner nearest the hit
  // of the first triangle the ray meets, on the stand-in when there is one (firstHit: a flat loop, no three.js
  // raycast, no pass over every vertex, no layout read: the canvas's place is
  // the last resize's). Its original id; null: the background.
  pointVertex(clientX: number, clientY: number): number | null {
    const rect = this.canvasRect;
    if (rect.width === 0 || rect.height === 0) return null;
    const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    const raycaster = new THREE.Raycaster();
    raycaster.setFromCamera(ndc, this.camera);
    const { origin, direction } = raycaster.ray;
    const faces = (this.coarse ?? this.geometry).index!.array as Uint32Array;
    const hit = firstHit(this.positions, faces, [origin.x, origin.y, origin.z], [direction.x, direction.y, direction.z]);
    if (hit === null) return null;
    const p = this.positions;
    const x = origin.x + hit.t * direction.x;
    const y = origin.y + hit.t * direction.y;
    const z = origin.z + hit.t * direction.z;
    let best = faces[3 * hit.face];
    let bestDistance = Infinity;
    for (let k = 0; k < 3; ++k) {
      const v = faces[3 * hit.face + k];
      const d = (p[3 * v] - x) ** 2 + (p[3 * v + 1] - y) ** 2 + (p[3 * v + 2] - z) ** 2;
      if (d < bestDistance) [best, bestDistance] = [v, d];
    }
    return this.idOf(best);
  }

  // Where a world point is drawn, in page coordinates.
  toScreen(point: THREE.Vector3): { x: number; y: number } {
    const rect = this.canvas.getBoundingClientRect();
    const ndc = point.clone().project(this.camera);
    return { x: rect.left + (ndc.x + 1) / 2 * rect.width, y: rect.top + (1 - ndc.y) / 2 * rect.height };
  }

  // The plane facing the camera through a point: handles are dragged in it.
  facingPlane(point: THREE.Vector3): THREE.Plane {
    const normal = this.camera.getWorldDirection(new THREE.Vector3());
    return new THREE.Plane().setFromNormalAndCoplanarPoint(normal, point);
  }

  // Where original vertex `id` is drawn now, in page coordinates (null: not at this level).
  vertexOnScreen(id: number): { x: number; y: number } | null {
    const p = this.positionOf(id);
    return p === null ? null : this.toScreen(p);
  }

  // The vertex nearest to the camera now (its original id): nothing hides it.
  nearestVertexToCamera(): number {
    const eye = this.camera.position;
    const p = this.positions;
    let best = -1;
    let bestDistance = Infinity;
    for (let i = 0; i < p.length / 3; ++i) {
      const d = (p[3 * i] - eye.x) ** 2 + (p[3 * i + 1] - eye.y) ** 2 + (p[3 * i + 2] - eye.z) ** 2;
      if (d < bestDistance) [best, bestDistance] = [i, d];
    }
    return best < 0 ? best : this.idOf(best);
  }

  // The bounding rectangle of the mesh as drawn, as fractions of the canvas
  // (projected vertices; for the tests of the framing).
  screenExtent(): { width: number; height: number; left: number; top: number } {
    const p = this.positions;
    const v = new THREE.Vector3();
    let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
    const step = Math.max(1, Math.floor(p.length / 3 / 20000));
    for (let i = 0; i < p.length / 3; i += step) {
      v.fromArray(p, 3 * i).project(this.camera);
      x0 = Math.min(x0, v.x); x1 = Math.max(x1, v.x); y0 = Math.min(y0, v.y); y1 = Math.max(y1, v.y);
    }
    return { width: (x1 - x0) / 2, height: (y1 - y0) / 2, left: (x0 + 1) / 2, top: (1 - y1) / 2 };
  }

  // Which way the camera looks, and its up (world space).
  viewDirection(): { look: [number, number, number]; up: [number, number, number] } {
    const d = this.camera.getWorldDirection(new THREE.Vector3());
    const up = new THREE.Vector3(0, 1, 0).applyQuaternion(this.camera.quaternion);
    return { look: [d.x, d.y, d.z], up: [up.x, up.y, up.z] };
  }

  // How long things must be still before full detail is drawn: REFINE_MS, or
  // three times as long as the last full-detail draw took to show (a 1M-vertex
  // mesh in software GL takes about a second: not between streamed frames).
  private refineMs(): number {
    return Math.max(REFINE_MS, 3 * this.fullShowMs);
  }

  // Things are still: full detail at the device's pixel ratio, however slow to show.
  private settle(): void {
    if (this.pixelRatio !== window.devicePixelRatio) {
      this.pixelRatio = window.devicePixelRatio;
      this.renderer.setPixelRatio(this.pixelRatio);
      this.resize();
    }
    this.invalidate();
  }

  // Drawing resolution: lower while draws are slow to show, back up when
  // they are quick; at most one step a second.
  private adapt(now: number): void {
    if (now - this.lastAdjust < 1000) return;
    let ratio = this.pixelRatio;
    const busy = now - this.lastChange < this.refineMs();  // lower only while things move: a still view stays sharp
    if (this.drawShowMs > SLOW_DRAW_MS && busy) ratio = Math.max(MIN_PIXEL_RATIO, ratio * 0.75);
    else if (this.drawShowMs < FAST_DRAW_MS) ratio = Math.min(window.devicePixelRatio, ratio / 0.75);
    if (ratio === this.pixelRatio) return;
    this.lastAdjust = now;
    this.pixelRatio = ratio;
    this.renderer.setPixelRatio(ratio);
    this.resize();
  }

  private resize(): void {
    const { clientWidth: width, clientHeight: height } = this.container;
    if (width === 0 || height === 0) return;
    this.renderer.setSize(width, height);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.invalidate();
    this.canvasRect = this.canvas.getBoundingClientRect();
    if (width !== this.cssWidth || height !== this.cssHeight) {
      this.cssWidth = width;
      this.cssHeight = height;
      this.viewChanged();
    }
  }

  // Draws only when something changed: an idle viewer costs no GPU time.
  private render(): void {
    const now = performance.now();
    if (this.drewLastFrame) {
      // The previous animation frame drew: this one came once that draw was shown.
      const shown = now - this.lastFrameAt;
      if (this.lastDrawFull) {
        this.fullShowMs = shown;
      } else {
        this.drawShowMs = this.drawShowMs === 0 ? shown : 0.8 * this.drawShowMs + 0.2 * shown;
        this.adapt(now);
      }
    }
    this.lastFrameAt = now;
    this.drewLastFrame = false;
    if (!this.dirty) return;
    // Slow to show even at the lowest pixel ratio: leave the page's thread
    // idle between draws as long as a draw takes to show, so that input never
    // waits behind two draws in a row.
    if (this.pixelRatio <= MIN_PIXEL_RATIO && this.drawShowMs > SLOW_DRAW_MS && now - this.lastDrawAt < 2 * this.drawShowMs) return;
    this.dirty = false;
    this.drewLastFrame = true;
    this.lastDrawAt = now;
    const start = performance.now();
    this.lastDrawFull = false;
    if (this.coarse) {
      // Full detail once nothing has moved for refineMs().
      const quiet = this.refineMs();
      const busy = start - this.lastChange < quiet;
      this.mesh.geometry = busy ? this.coarse : this.geometry;
      this.lastDrawFull = !busy;
      if (busy) {
        ++this.coarseDraws;
        clearTimeout(this.refineTimer);
        this.refineTimer = setTimeout(() => this.settle(), quiet + 10 - (start - this.lastChange));
      }
    }
    this.renderer.render(this.scene, this.camera);
    const end = performance.now();
    ++this.framesRendered;
    this.onDrawn(end - start, end);
  }

  // The current image as a PNG data URL. Renders first, in the same task:
  // without preserveDrawingBuffer the canvas is only readable until the
  // browser composites it.
  // Full detail at the device's pixel ratio, whatever the load.
  capture(): string {
    const ratio = this.pixelRatio;
    if (ratio !== window.devicePixelRatio) {
      this.renderer.setPixelRatio(window.devicePixelRatio);
      this.resize();
    }
    this.dirty = true;
    this.lastChange = -Infinity;
    this.drewLastFrame = false;  // a draw outside the animation frames: not timed
    this.lastDrawAt = -Infinity;
    this.render();
    this.drewLastFrame = false;
    const image = this.renderer.domElement.toDataURL('image/png');
    if (ratio !== window.devicePixelRatio) {
      this.renderer.setPixelRatio(ratio);
      this.resize();
    }
    return image;
  }
}
