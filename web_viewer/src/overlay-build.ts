// What the session worker makes of GetOverlays for drawing, so that the cut
// and the regions read on a dense scan (hundreds of thousands of triangles,
// thousands of regions): regions in a bounded palette, neighbours in
// different colours, with their boundaries as lines; the cut as the edges of
// its coarse triangles (those not in the detailed mesh) over a tint of where
// it is refined to full detail, instead of every triangle. Pure; imports
// nothing at run time.

// Colour-blind-safe (Okabe–Ito) plus one, sRGB in [0, 1].
export const PALETTE: [number, number, number][] = [
  [0.902, 0.624, 0.0], [0.337, 0.706, 0.914], [0.0, 0.620, 0.451], [0.941, 0.894, 0.259],
  [0.0, 0.447, 0.698], [0.835, 0.369, 0.0], [0.800, 0.475, 0.655], [0.604, 0.816, 0.627],
];
export const CUT_GREY: [number, number, number] = [0.55, 0.55, 0.55];

// Keys an undirected edge of a mesh of n vertices (n ≤ 2^26 keeps it exact).
const edgeKey = (a: number, b: number, n: number) => (a < b ? a * n + b : b * n + a);

// A palette index per region label (regionOf values: 0 a cut vertex, r + 1
// region r), greedily so that regions sharing a triangle differ whenever the
// palette allows; out[0] is unused. Labels are coloured in increasing order.
export function colourRegions(regionOf: ArrayLike<number>, faces: ArrayLike<number>, paletteSize = PALETTE.length): Uint8Array {
  let labels = 0;
  for (let i = 0; i < regionOf.length; ++i) if (regionOf[i] > labels) labels = regionOf[i];
  const neighbours: Set<number>[] = Array.from({ length: labels + 1 }, () => new Set<number>());
  for (let f = 0; f + 2 < faces.length; f += 3) {
    for (let k = 0; k < 3; ++k) {
      const a = regionOf[faces[f + k]];
      const b = regionOf[faces[f + ((k + 1) % 3)]];
      if (a !== b && a !== 0 && b !== 0) {
        neighbours[a].add(b);
        neighbours[b].add(a);
      }
    }
  }
  const colour = new Uint8Array(labels + 1);
  const used = new Uint32Array(paletteSize);
  for (let label = 1; label <= labels; ++label) {
    used.fill(0);
    for (const other of neighbours[label]) if (other < label) ++used[colour[other]];
    // The first colour no coloured neighbour has; else the rarest among them.
    let best = 0;
    for (let c = 1; c < paletteSize; ++c) if (used[c] < used[best]) best = c;
    for (let c = 0; c < paletteSize; ++c) {
      if (used[c] === 0) {
        best = c;
        break;
      }
    }
    colour[label] = best;
  }
  return colour;
}

// Linear-RGB vertex colours (what three.js expects in a colour attribute) of the regions.
export function regionVertexColours(regionOf: ArrayLike<number>, colourOf: Uint8Array, out: Float32Array): void {
  const linear = (c: number) => (c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4);
  const table = [...PALETTE, CUT_GREY].map((rgb) => rgb.map(linear));
  const grey = table.length - 1;
  for (let v = 0; v < regionOf.length; ++v) {
    const label = regionOf[v];
    const rgb = table[label === 0 ? grey : colourOf[label]];
    out[3 * v] = rgb[0];
    out[3 * v + 1] = rgb[1];
    out[3 * v + 2] = rgb[2];
  }
}

// The edges of the triangles whose two ends lie in two different regions:
// where regions meet, as index pairs, each once. Edges to cut vertices are
// left out (the grey already tells those apart; outlining thousands of small
// regions against the cut would cover a dense mesh in dark specks).
export function regionBoundaryEdges(regionOf: ArrayLike<number>, faces: ArrayLike<number>): Uint32Array {
  const n = regionOf.length;
  const seen = new Set<number>();
  const out: number[] = [];
  for (let f = 0; f + 2 < faces.length; f += 3) {
    for (let k = 0; k < 3; ++k) {
      const a = faces[f + k];
      const b = faces[f + ((k + 1) % 3)];
      if (regionOf[a] === regionOf[b] || regionOf[a] === 0 || regionOf[b] === 0) continue;
      const key = edgeKey(a, b, n);
      if (seen.has(key)) continue;
      seen.add(key);
      out.push(a, b);
    }
  }
  return Uint32Array.from(out);
}

// The edges of a mesh of n vertices, keyed (edgeKey).
export function edgeSet(faces: ArrayLike<number>, n: number): Set<number> {
  const edges = new Set<number>();
  for (let f = 0; f + 2 < faces.length; f += 3) {
    for (let k = 0; k < 3; ++k) edges.add(edgeKey(faces[f + k], faces[f + ((k + 1) % 3)], n));
  }
  return edges;
}

// The cut mesh for drawing: `coarse`, the edges of its triangles that are
// not edges of the detailed mesh (index pairs, each once); `refined`, 1 for
// the vertices of its triangles that are triangles of the detailed mesh
// (all three edges fine): where the cut has full detail.
export function cutForDrawing(cutFaces: ArrayLike<number>, fine: Set<number>, n: number):
  { coarse: Uint32Array; refined: Uint8Array; refinedTriangles: number } {
  const seen = new Set<number>();
  const coarse: number[] = [];
  const refined = new Uint8Array(n);
  let refinedTriangles = 0;
  for (let f = 0; f + 2 < cutFaces.length; f += 3) {
    let allFine = true;
    for (let k = 0; k < 3; ++k) {
      const a = cutFaces[f + k];
      const b = cutFaces[f + ((k + 1) % 3)];
      const key = edgeKey(a, b, n);
      if (fine.has(key)) continue;
      allFine = false;
      if (seen.has(key)) continue;
      seen.add(key);
      coarse.push(a, b);
    }
    if (allFine) {
      ++refinedTriangles;
      refined[cutFaces[f]] = refined[cutFaces[f + 1]] = refined[cutFaces[f + 2]] = 1;
    }
  }
  return { coarse: Uint32Array.from(coarse), refined, refinedTriangles };
}
