// The cut mesh (GetOverlays.cut_faces): the triangles the runtime is made of
// after its last cut update, coarse where detail is recovered directly and
// fine where it was refined. Drawn so that it reads on a dense scan: the
// edges of its coarse triangles (those that are not triangles of the
// detailed mesh) as lines, and where it is refined to full detail as a cyan
// tint of the surface, not every one of its triangles. The session worker
// builds both (overlay-build.ts); this only swaps them in.
import * as THREE from 'three';

import { shareMesh, unshareMesh, type MeshOverlay } from './overlays';

export class CutWireframe implements MeshOverlay {
  readonly id = 'cut';
  readonly label = 'Cut mesh (lines: coarse, cyan: refined)';
  readonly fromServer = true;
  readonly object = new THREE.Group();
  private readonly lines: THREE.LineSegments;
  private readonly tint: THREE.Mesh;
  private colors: THREE.BufferAttribute;
  private bound = true;  // the tint, to the mesh's attributes (rebind)
  triangleCount = 0;
  refinedTriangles = 0;

  // `mesh`: the detailed mesh's geometry, whose attributes this shares.
  constructor(private readonly mesh: THREE.BufferGeometry) {
    // Depth-tested (the mesh is pushed back a little, scene.ts): only the visible side's edges.
    const material = new THREE.LineBasicMaterial({ color: 0x7fe3ff, transparent: true, opacity: 0.8 });
    this.lines = new THREE.LineSegments(this.edges(new Uint32Array(0)), material);
    this.lines.frustumCulled = false;
    this.lines.renderOrder = 1;
    const geometry = new THREE.BufferGeometry();
    this.colors = new THREE.BufferAttribute(new Float32Array(mesh.getAttribute('position').count * 3), 3);
    shareMesh(geometry, mesh, this.colors);
    this.tint = new THREE.Mesh(geometry, new THREE.MeshStandardMaterial({
      vertexColors: true, roughness: 0.55, polygonOffset: true, polygonOffsetFactor: -1, polygonOffsetUnits: -1,
    }));
    this.tint.frustumCulled = false;
    this.tint.visible = false;
    this.object.add(this.tint, this.lines);
    this.object.visible = false;
  }

  setVisible(visible: boolean): void {
    if (visible) this.bind();
    this.object.visible = visible;
  }

  update(): void {}  // the shared position attribute moves it

  // Another level of detail drawn: nothing shown until the next answer for
  // it (the tint bound to it when shown).
  rebind(): void {
    unshareMesh(this.tint.geometry);
    this.bound = false;
    this.setCut(new Uint32Array(0), new Float32Array(0), 0, 0);
    this.tint.visible = false;
    if (this.object.visible) this.bind();
  }

  private bind(): void {
    if (this.bound) return;
    this.bound = true;
    this.colors = new THREE.BufferAttribute(new Float32Array(this.mesh.getAttribute('position').count * 3), 3);
    shareMesh(this.tint.geometry, this.mesh, this.colors);
  }

  // A new cut: its coarse edges (index pairs) and the per-vertex tint.
  setCut(coarse: Uint32Array, tint: Float32Array, triangles: number, refined: number): void {
    this.triangleCount = triangles;
    this.refinedTriangles = refined;
    const old = this.lines.geometry;
    this.lines.geometry = this.edges(coarse);
    // Disposing a geometry frees its attributes' GPU buffers: not the shared one.
    old.deleteAttribute('position');
    old.dispose();
    if (this.bound && tint.length === this.colors.array.length) {
      this.colors.array = tint;
      this.colors.needsUpdate = true;
      this.tint.visible = refined > 0;
    }
  }

  private edges(pairs: Uint32Array): THREE.BufferGeometry {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', this.mesh.getAttribute('position'));
    geometry.setIndex(new THREE.BufferAttribute(pairs, 1));
    return geometry;
  }
}
