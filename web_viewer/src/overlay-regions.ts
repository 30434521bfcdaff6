// The optimisation regions (GetOverlays.region_of; thesis Fig. 3.21) as vertex
// colours: vertices of the cut mesh neutral grey, each region its own hue.
import * as THREE from 'three';

import type { Overlay } from './overlays';

export const CUT_GREY: [number, number, number] = [0.55, 0.55, 0.55];
const GOLDEN = 0.618033988749895;

// sRGB components in [0, 1] for a region_of label: 0 (a cut vertex) grey,
// r + 1 a hue stepped by the golden ratio from region to region, so that
// regions with close numbers (often neighbours) differ clearly.
export function regionColor(label: number): [number, number, number] {
  if (label === 0) return CUT_GREY;
  const hue = ((label - 1) * GOLDEN + 0.08) % 1;
  const lightness = label % 2 === 0 ? 0.5 : 0.62;
  const { r, g, b } = new THREE.Color().setHSL(hue, 0.75, lightness, THREE.SRGBColorSpace)
    .getRGB({ r: 0, g: 0, b: 0 }, THREE.SRGBColorSpace);
  return [r, g, b];
}

// Linear-space vertex colours (what three.js expects in a color attribute).
export function regionColors(regionOf: ArrayLike<number>, out: Float32Array): void {
  const color = new THREE.Color();
  for (let i = 0; i < regionOf.length; ++i) {
    color.setRGB(...regionColor(regionOf[i]), THREE.SRGBColorSpace);
    out[3 * i] = color.r;
    out[3 * i + 1] = color.g;
    out[3 * i + 2] = color.b;
  }
}

// The detailed mesh drawn again over itself (same position, normal and index
// attributes, so frames move it too) with the region colours.
export class RegionsOverlay implements Overlay {
  readonly id = 'regions';
  readonly label = 'Regions';
  readonly fromServer = true;
  readonly object: THREE.Mesh;
  private readonly colors: Float32Array;

  constructor(mesh: THREE.BufferGeometry) {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', mesh.getAttribute('position'));
    geometry.setAttribute('normal', mesh.getAttribute('normal'));
    geometry.setIndex(mesh.getIndex());
    const count = mesh.getAttribute('position').count;
    this.colors = new Float32Array(3 * count);
    regionColors(new Uint8Array(count), this.colors);  // all grey until the server answers
    geometry.setAttribute('color', new THREE.BufferAttribute(this.colors, 3));
    const material = new THREE.MeshStandardMaterial({
      vertexColors: true, roughness: 0.6, polygonOffset: true, polygonOffsetFactor: -1, polygonOffsetUnits: -1,
    });
    this.object = new THREE.Mesh(geometry, material);
    this.object.frustumCulled = false;
    this.object.visible = false;
  }

  setVisible(visible: boolean): void {
    this.object.visible = visible;
  }

  update(): void {}  // the shared attributes already move

  setRegions(regionOf: ArrayLike<number>): void {
    if (regionOf.length !== this.colors.length / 3) return;  // not this mesh's (never expected)
    regionColors(regionOf, this.colors);
    this.object.geometry.getAttribute('color').needsUpdate = true;
  }
}
