// The three.js side: the detailed mesh (one geometry for the whole session,
// updated in place per frame), lights that bring out surface detail, and an
// orbit camera framing the rest mesh; picking and screen projection for
// handle editing (handles.ts).
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

export class MeshView {
  readonly scene = new THREE.Scene();
  readonly geometry = new THREE.BufferGeometry();
  // The live positions: frames write rest + delta here (frame.ts, applyDeltas).
  readonly positions: Float32Array;
  readonly mesh: THREE.Mesh;
  readonly radius: number;  // of the rest mesh's bounding sphere
  private readonly renderer: THREE.WebGLRenderer;
  private readonly camera: THREE.PerspectiveCamera;
  private readonly controls: OrbitControls;
  private dirty = true;
  framesRendered = 0;

  constructor(private readonly container: HTMLElement, rest: Float32Array, faces: Uint32Array) {
    this.positions = rest.slice();
    const position = new THREE.BufferAttribute(this.positions, 3);
    // Rewritten by every frame: tells WebGL to expect frequent uploads.
    position.setUsage(THREE.DynamicDrawUsage);
    this.geometry.setAttribute('position', position);
    this.geometry.setIndex(new THREE.BufferAttribute(faces, 1));
    this.geometry.computeVertexNormals();
    (this.geometry.getAttribute('normal') as THREE.BufferAttribute).setUsage(THREE.DynamicDrawUsage);
    this.geometry.computeBoundingSphere();

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

    this.renderer = new THREE.WebGLRenderer({ antialias: true });
    this.renderer.setPixelRatio(window.devicePixelRatio);
    container.appendChild(this.renderer.domElement);

    const sphere = this.geometry.boundingSphere!;
    const radius = this.radius = Math.max(sphere.radius, 1e-6);
    this.camera = new THREE.PerspectiveCamera(40, 1, radius / 100, radius * 100);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => this.invalidate());
    this.frame(sphere.center, radius);

    // A sky/ground hemisphere for the overall shape, plus a key light that
    // rides with the camera at a grazing angle: fine relief stays visible
    // from every viewpoint.
    this.scene.add(new THREE.HemisphereLight(0xf4f1ea, 0x2a2622, 0.8));
    const key = new THREE.DirectionalLight(0xffffff, 2.4);
    // Both ends in camera space: the light comes from the upper right at
    // about 55° to the view direction, whatever the orbit.
    key.position.set(1.5, 1.5, 0.5);
    key.target.position.set(0, 0, -1);
    this.camera.add(key, key.target);
    this.scene.add(this.camera);

    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
    this.renderer.setAnimationLoop(() => this.render());
  }

  // Puts the whole sphere in view, looking along −z.
  private frame(center: THREE.Vector3, radius: number): void {
    const distance = radius / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2)) * 1.1;
    this.camera.position.copy(center).add(new THREE.Vector3(0, 0, distance));
    this.controls.target.copy(center);
    this.controls.update();
  }

  // After the positions array was rewritten: upload it and fix the shading.
  positionsChanged(): void {
    this.geometry.getAttribute('position').needsUpdate = true;
    // Reuses the existing normal attribute (same count), no allocation.
    this.geometry.computeVertexNormals();
    this.invalidate();
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

  // The detailed mesh under the page point, as it is now (null: background).
  pick(clientX: number, clientY: number): THREE.Intersection | null {
    // three.js skips meshes whose bounding sphere the ray misses, and frames
    // move vertices out of the rest sphere: refresh it (one pass, per click).
    this.geometry.computeBoundingSphere();
    return this.rayAt(clientX, clientY).intersectObject(this.mesh, false)[0] ?? null;
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

  // Where vertex i is drawn now, in page coordinates.
  vertexOnScreen(i: number): { x: number; y: number } {
    return this.toScreen(new THREE.Vector3().fromArray(this.positions, 3 * i));
  }

  // The vertex nearest to the camera now: nothing hides it.
  nearestVertexToCamera(): number {
    const eye = this.camera.position;
    const p = this.positions;
    let best = -1;
    let bestDistance = Infinity;
    for (let i = 0; i < p.length / 3; ++i) {
      const d = (p[3 * i] - eye.x) ** 2 + (p[3 * i + 1] - eye.y) ** 2 + (p[3 * i + 2] - eye.z) ** 2;
      if (d < bestDistance) [best, bestDistance] = [i, d];
    }
    return best;
  }

  private resize(): void {
    const { clientWidth: width, clientHeight: height } = this.container;
    if (width === 0 || height === 0) return;
    this.renderer.setSize(width, height);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.invalidate();
  }

  // Draws only when something changed: an idle viewer costs no GPU time.
  private render(): void {
    if (!this.dirty) return;
    this.dirty = false;
    this.renderer.render(this.scene, this.camera);
    ++this.framesRendered;
  }

  // The current image as a PNG data URL. Renders first, in the same task:
  // without preserveDrawingBuffer the canvas is only readable until the
  // browser composites it.
  capture(): string {
    this.dirty = true;
    this.render();
    return this.renderer.domElement.toDataURL('image/png');
  }
}
