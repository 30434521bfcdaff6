// The stretch heat map: |L2 − 1| of the triangles of the detailed mesh
// against their rest shape (stretch.ts), blue (rigid) to red (≥ STRETCH_RED).
// The session worker computes it with each frame while this overlay is on
// (per vertex, the largest of its triangles), as a colour attribute of the
// mesh drawn again over itself; the page only swaps the colour array in.
import * as THREE from 'three';

import { shareMesh, unshareMesh, type MeshOverlay } from './overlays';

export class StretchOverlay implements MeshOverlay {
  readonly id = 'stretch';
  readonly label = 'Stretch (|L2 − 1|)';
  readonly fromServer = false;
  readonly object: THREE.Mesh;
  private colors: THREE.BufferAttribute;
  private bound = true;  // to the mesh's attributes (rebind)
  maxDeviation = 0;  // the largest |L2 − 1| of the last colours (for the panel and tests)

  // `mesh`: the detailed mesh's geometry, whose position and normal attributes this shares.
  constructor(private readonly mesh: THREE.BufferGeometry, private readonly visibility: (visible: boolean) => void) {
    const geometry = new THREE.BufferGeometry();
    this.colors = StretchOverlay.blank(mesh);
    shareMesh(geometry, mesh, this.colors);
    // Drawn just in front of the mesh it colours.
    const material = new THREE.MeshStandardMaterial({
      vertexColors: true, roughness: 0.6, polygonOffset: true, polygonOffsetFactor: -2, polygonOffsetUnits: -2,
    });
    this.object = new THREE.Mesh(geometry, material);
    this.object.frustumCulled = false;
    this.object.visible = false;
  }

  private static blank(mesh: THREE.BufferGeometry): THREE.BufferAttribute {
    return new THREE.BufferAttribute(new Float32Array(mesh.getAttribute('position').count * 3), 3).setUsage(THREE.DynamicDrawUsage);
  }

  // Another level of detail drawn; its colours come with its frames (the
  // level's first ones too, when shown: setColors, which binds it).
  rebind(): void {
    unshareMesh(this.object.geometry);
    this.bound = false;
    this.object.visible = false;
  }

  // Shown once the worker has coloured a frame; it starts colouring now.
  setVisible(visible: boolean): void {
    if (!visible) this.object.visible = false;
    this.visibility(visible);
  }

  update(): void {}  // the colours come with the frames (setColors)

  // A frame's colours; returns the array they replace.
  setColors(colors: Float32Array, maxDeviation: number): Float32Array {
    if (!this.bound) {
      this.bound = true;
      this.colors = StretchOverlay.blank(this.mesh);
      shareMesh(this.object.geometry, this.mesh, this.colors);
    }
    const old = this.colors.array as Float32Array;
    this.colors.array = colors;
    this.colors.needsUpdate = true;
    this.maxDeviation = maxDeviation;
    this.object.visible = true;
    return old;
  }
}
