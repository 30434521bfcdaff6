// The stretch heat map: every triangle of the detailed mesh coloured by
// |L2 − 1| of its current shape against its rest shape (stretch.ts), blue
// (rigid) to red (≥ STRETCH_RED). Computed here from the frames, only while shown.
import * as THREE from 'three';

import type { Overlay } from './overlays';
import { stretchColor, TriangleStretch } from './stretch';

export class StretchOverlay implements Overlay {
  readonly id = 'stretch';
  readonly label = 'Stretch (|L2 − 1|)';
  readonly fromServer = false;
  readonly object: THREE.Mesh;
  private readonly stretch: TriangleStretch;
  private readonly values: Float32Array;
  // One vertex per triangle corner, so that each triangle has one colour.
  private readonly corners: Float32Array;
  private readonly cornerNormals: Float32Array;
  private readonly colors: Float32Array;

  // `live` is the mesh's position array and `normals` its normal attribute,
  // both rewritten by every frame.
  constructor(rest: Float32Array, private readonly faces: Uint32Array, private readonly live: Float32Array,
              private readonly normals: THREE.BufferAttribute) {
    this.stretch = new TriangleStretch(rest, faces);
    this.values = new Float32Array(this.stretch.triangleCount);
    this.corners = new Float32Array(9 * this.values.length);
    this.cornerNormals = new Float32Array(this.corners.length);
    this.colors = new Float32Array(this.corners.length);
    const geometry = new THREE.BufferGeometry();
    for (const [name, array] of [['position', this.corners], ['normal', this.cornerNormals], ['color', this.colors]] as const) {
      geometry.setAttribute(name, new THREE.BufferAttribute(array, 3).setUsage(THREE.DynamicDrawUsage));
    }
    // Drawn just in front of the mesh it colours.
    const material = new THREE.MeshStandardMaterial({
      vertexColors: true, roughness: 0.6, polygonOffset: true, polygonOffsetFactor: -2, polygonOffsetUnits: -2,
    });
    this.object = new THREE.Mesh(geometry, material);
    this.object.frustumCulled = false;
    this.object.visible = false;
  }

  setVisible(visible: boolean): void {
    this.object.visible = visible;
    if (visible) this.update();
  }

  update(): void {
    if (!this.object.visible) return;
    this.stretch.l2(this.live, this.values);
    const normals = this.normals.array;
    const color = new THREE.Color();
    for (let f = 0; f < this.values.length; ++f) {
      color.setRGB(...stretchColor(this.values[f]), THREE.SRGBColorSpace);
      for (let k = 0; k < 3; ++k) {
        const v = 3 * this.faces[3 * f + k];
        const o = 9 * f + 3 * k;
        for (let c = 0; c < 3; ++c) {
          this.corners[o + c] = this.live[v + c];
          this.cornerNormals[o + c] = normals[v + c];
        }
        this.colors[o] = color.r;
        this.colors[o + 1] = color.g;
        this.colors[o + 2] = color.b;
      }
    }
    const geometry = this.object.geometry;
    for (const name of ['position', 'normal', 'color']) geometry.getAttribute(name).needsUpdate = true;
  }

  // The largest |L2 − 1| over the triangles at the last update (for the panel and tests).
  get maxDeviation(): number {
    let max = 0;
    for (const value of this.values) max = Math.max(max, Math.abs(value - 1));
    return max;
  }
}
