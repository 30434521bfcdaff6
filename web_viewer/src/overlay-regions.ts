// The optimisation regions (GetOverlays.region_of; thesis Fig. 3.21): the
// mesh drawn again over itself in region colours (cut vertices neutral grey,
// regions from a bounded palette, neighbours different: overlay-build.ts),
// with the regions' outlines as dark lines, so that thousands of small
// regions on a dense scan read as areas rather than confetti. The session
// worker builds both; this only swaps them in.
import * as THREE from 'three';

import { shareMesh, unshareMesh, type MeshOverlay } from './overlays';

export class RegionsOverlay implements MeshOverlay {
  readonly id = 'regions';
  readonly label = 'Regions';
  readonly fromServer = true;
  readonly object = new THREE.Group();
  private readonly fill: THREE.Mesh;
  private readonly outline: THREE.LineSegments;
  private colors: THREE.BufferAttribute;
  private bound = true;  // to the mesh's attributes (rebind)

  // `mesh`: the detailed mesh's geometry, whose attributes this shares.
  constructor(private readonly mesh: THREE.BufferGeometry) {
    const geometry = new THREE.BufferGeometry();
    this.colors = RegionsOverlay.grey(mesh);
    shareMesh(geometry, mesh, this.colors);
    const material = new THREE.MeshStandardMaterial({
      vertexColors: true, roughness: 0.6, polygonOffset: true, polygonOffsetFactor: -1, polygonOffsetUnits: -1,
    });
    this.fill = new THREE.Mesh(geometry, material);
    this.fill.frustumCulled = false;
    const lines = new THREE.BufferGeometry();
    lines.setAttribute('position', mesh.getAttribute('position'));
    lines.setIndex(new THREE.BufferAttribute(new Uint32Array(0), 1));
    this.outline = new THREE.LineSegments(lines, new THREE.LineBasicMaterial({ color: 0x15181c, transparent: true, opacity: 0.8 }));
    this.outline.frustumCulled = false;
    this.outline.renderOrder = 1;
    this.object.add(this.fill, this.outline);
    this.object.visible = false;
  }

  // Grey until the server answers.
  private static grey(mesh: THREE.BufferGeometry): THREE.BufferAttribute {
    return new THREE.BufferAttribute(new Float32Array(3 * mesh.getAttribute('position').count).fill(0.27), 3);
  }

  // Another level of detail drawn: grey again until the next answer for it
  // (bound to it when shown).
  rebind(): void {
    unshareMesh(this.fill.geometry);
    this.bound = false;
    this.setEdges(new Uint32Array(0));
    if (this.object.visible) this.bind();
  }

  private bind(): void {
    if (this.bound) return;
    this.bound = true;
    this.colors = RegionsOverlay.grey(this.mesh);
    shareMesh(this.fill.geometry, this.mesh, this.colors);
  }

  setVisible(visible: boolean): void {
    if (visible) this.bind();
    this.object.visible = visible;
  }

  update(): void {}  // the shared attributes already move

  // Per-vertex linear colours and the outline's index pairs (the worker's).
  setRegions(colors: Float32Array, edges: Uint32Array): void {
    if (!this.bound || colors.length !== this.colors.array.length) return;  // not for this mesh
    this.colors.array = colors;
    this.colors.needsUpdate = true;
    this.setEdges(edges);
  }

  private setEdges(edges: Uint32Array): void {
    const old = this.outline.geometry;
    const lines = new THREE.BufferGeometry();
    lines.setAttribute('position', this.mesh.getAttribute('position'));
    lines.setIndex(new THREE.BufferAttribute(edges, 1));
    this.outline.geometry = lines;
    // Disposing a geometry frees its attributes' GPU buffers: not the shared one.
    old.deleteAttribute('position');
    old.dispose();
  }
}
