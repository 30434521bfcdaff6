// The three.js side: the detailed mesh (one geometry for the whole session,
// updated in place per frame), lights that bring out surface detail, and an
// orbit camera framing the rest mesh.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

export class MeshView {
  readonly scene = new THREE.Scene();
  readonly geometry = new THREE.BufferGeometry();
  // The live positions: frames write rest + delta here (frame.ts, applyDeltas).
  readonly positions: Float32Array;
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

    const material = new THREE.MeshStandardMaterial({ color: 0xc9bfae, roughness: 0.55, metalness: 0.0 });
    const mesh = new THREE.Mesh(this.geometry, material);
    // Frames move vertices beyond the rest bounding sphere; recomputing it
    // per frame costs a pass over every vertex, not culling costs nothing.
    mesh.frustumCulled = false;
    this.scene.add(mesh);
    this.scene.background = new THREE.Color(0x1d2024);

    this.renderer = new THREE.WebGLRenderer({ antialias: true });
    this.renderer.setPixelRatio(window.devicePixelRatio);
    container.appendChild(this.renderer.domElement);

    const sphere = this.geometry.boundingSphere!;
    const radius = Math.max(sphere.radius, 1e-6);
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
