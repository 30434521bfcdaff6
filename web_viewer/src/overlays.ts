// Things drawn over the detailed mesh, each one toggled from the panel: the
// base-mesh wireframe (here), the cut mesh (overlay-cut.ts), the regions
// (overlay-regions.ts) and the stretch map (overlay-stretch.ts). The cut and
// the regions come from the server (GetOverlays, overlay-feed.ts); the rest is
// computed from the frames.
import * as THREE from 'three';

export interface Overlay {
  readonly id: string;
  readonly label: string;
  // True for overlays drawn from GetOverlays: it is polled while one is shown.
  readonly fromServer: boolean;
  setVisible(visible: boolean): void;
  // Called after every applied frame with the live detailed positions.
  update(positions: Float32Array): void;
}

// Overlays drawn from the mesh's own attributes (sharing its position,
// normal and index): after the mesh is swapped for another level of detail,
// rebind() lets the old ones go and frees the overlay's own buffers; it takes
// the new ones (and allocates its colours, 12 bytes a vertex) when shown.
export interface MeshOverlay extends Overlay {
  rebind(): void;
}

// Lets `geometry` go of the mesh's attributes and frees its own GPU buffers
// (not the shared ones, which the mesh frees).
export function unshareMesh(geometry: THREE.BufferGeometry): void {
  if (!geometry.getAttribute('position')) return;
  geometry.deleteAttribute('position');
  geometry.deleteAttribute('normal');
  geometry.setIndex(null);
  geometry.dispose();
}

// Points `geometry` at `mesh`'s position, normal and index (unsharing what
// it held), with a colour attribute of `colors` when given.
export function shareMesh(geometry: THREE.BufferGeometry, mesh: THREE.BufferGeometry, colors?: THREE.BufferAttribute): void {
  unshareMesh(geometry);
  geometry.setAttribute('position', mesh.getAttribute('position'));
  geometry.setAttribute('normal', mesh.getAttribute('normal'));
  geometry.setIndex(mesh.getIndex());
  if (colors) geometry.setAttribute('color', colors);
}

// Each undirected edge of the triangles once, as index pairs.
export function uniqueEdges(faces: ArrayLike<number>): Uint32Array {
  const seen = new Set<number>();
  const edges: number[] = [];
  const vertexLimit = 2 ** 26;  // keeps a·limit + b exact in a double
  for (let f = 0; f + 2 < faces.length; f += 3) {
    for (let k = 0; k < 3; ++k) {
      const a = faces[f + k];
      const b = faces[f + ((k + 1) % 3)];
      const [lo, hi] = a < b ? [a, b] : [b, a];
      if (hi >= vertexLimit) throw new Error(`base vertex index ${hi} is too large`);
      const key = lo * vertexLimit + hi;
      if (seen.has(key)) continue;
      seen.add(key);
      edges.push(lo, hi);
    }
  }
  return Uint32Array.from(edges);
}

// out[i] = positions[ids[i]] (x y z): the base vertices' current positions.
// A negative id (a vertex the level drawn lacks) leaves out[i] as it is.
export function gatherVertices(positions: Float32Array, ids: ArrayLike<number>, out: Float32Array): void {
  for (let i = 0; i < ids.length; ++i) {
    const id = ids[i];
    if (id < 0) continue;
    out[3 * i] = positions[3 * id];
    out[3 * i + 1] = positions[3 * id + 1];
    out[3 * i + 2] = positions[3 * id + 2];
  }
}

// The base mesh as a wireframe drawn through the surface. Base vertex i is
// original vertex originalIds[i], and the deformer places base vertices at
// the pose (core/runtime/deformer.h), so each frame already carries the
// merged base pose to within Frame.max_error: no GetState round trip needed.
export class BaseWireframe implements Overlay {
  readonly id = 'base';
  readonly label = 'Base mesh';
  readonly fromServer = false;
  readonly object: THREE.LineSegments;
  private readonly positions: Float32Array;
  // Where each base vertex is in the positions drawn: its original id, or
  // its index in the level of detail drawn (setLevel).
  private index: ArrayLike<number>;

  constructor(restPositions: ArrayLike<number>, faces: ArrayLike<number>, originalIds: Uint32Array) {
    this.index = originalIds;
    this.positions = Float32Array.from(restPositions);
    const geometry = new THREE.BufferGeometry();
    const position = new THREE.BufferAttribute(this.positions, 3);
    position.setUsage(THREE.DynamicDrawUsage);
    geometry.setAttribute('position', position);
    geometry.setIndex(new THREE.BufferAttribute(uniqueEdges(faces), 1));
    // Drawn over the surface (no depth test) so the whole cage is seen.
    const material = new THREE.LineBasicMaterial({ color: 0xff9a3c, transparent: true, opacity: 0.75, depthTest: false });
    this.object = new THREE.LineSegments(geometry, material);
    this.object.frustumCulled = false;
    this.object.renderOrder = 1;
    this.object.visible = false;
  }

  setVisible(visible: boolean): void {
    this.object.visible = visible;
  }

  // The positions drawn are a level's: base vertex i is its vertex index[i] (−1: not in it).
  setLevel(index: ArrayLike<number>): void {
    this.index = index;
  }

  update(positions: Float32Array): void {
    gatherVertices(positions, this.index, this.positions);
    this.object.geometry.getAttribute('position').needsUpdate = true;
  }
}
