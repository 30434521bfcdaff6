// The cut mesh (GetOverlays.cut_faces): the triangles the runtime is made of
// after its last cut update, coarse where detail is recovered directly and
// fine where it was refined, drawn as a wireframe over the deformed positions.
import * as THREE from 'three';

import { uniqueEdges, type Overlay } from './overlays';

export class CutWireframe implements Overlay {
  readonly id = 'cut';
  readonly label = 'Cut mesh';
  readonly fromServer = true;
  readonly object: THREE.LineSegments;
  private faces: ArrayLike<number> = [];

  // `live` is the mesh's position attribute (original order), which every frame replaces the array of.
  constructor(private readonly live: THREE.BufferAttribute) {
    // Depth-tested (the mesh is pushed back a little, scene.ts): only the
    // visible side's edges, else tens of thousands of lines overlap.
    const material = new THREE.LineBasicMaterial({ color: 0x7fe3ff, transparent: true, opacity: 0.7 });
    this.object = new THREE.LineSegments(this.geometry([]), material);
    this.object.frustumCulled = false;
    this.object.renderOrder = 1;
    this.object.visible = false;
  }

  setVisible(visible: boolean): void {
    this.object.visible = visible;
  }

  update(): void {}  // the shared position attribute moves it

  // A new cut: a new geometry (the edge count changes), the old one freed.
  setFaces(faces: ArrayLike<number>): void {
    if (sameValues(faces, this.faces)) return;
    this.faces = faces;
    const old = this.object.geometry;
    this.object.geometry = this.geometry(faces);
    // Disposing a geometry frees its attributes' GPU buffers: not the shared one.
    old.deleteAttribute('position');
    old.dispose();
  }

  get triangleCount(): number {
    return Math.floor(this.faces.length / 3);
  }

  private geometry(faces: ArrayLike<number>): THREE.BufferGeometry {
    const geometry = new THREE.BufferGeometry();
    // The mesh's own attribute: one upload per frame serves both.
    geometry.setAttribute('position', this.live);
    geometry.setIndex(new THREE.BufferAttribute(uniqueEdges(faces), 1));
    return geometry;
  }
}

function sameValues(a: ArrayLike<number>, b: ArrayLike<number>): boolean {
  if (a.length !== b.length) return false;
  for (let i = 0; i < a.length; ++i) if (a[i] !== b[i]) return false;
  return true;
}
