// Mesh arithmetic of the session worker (session.worker.ts), pure so that the
// unit tests check it: vertex normals, the framing of a mesh on load (which
// way is up, which side is the front), and the falloff of proportional edits.
// Imports nothing at run time.

// Area-weighted vertex normals, as three.js's computeVertexNormals computes
// them (each face adds its unnormalised cross product to its corners), into
// `out` (3 per vertex). Vertices on no face get 0.
export function vertexNormals(positions: Float32Array, faces: Uint32Array, out: Float32Array): void {
  out.fill(0);
  const p = positions;
  for (let f = 0; f + 2 < faces.length; f += 3) {
    const a = 3 * faces[f];
    const b = 3 * faces[f + 1];
    const c = 3 * faces[f + 2];
    const e1x = p[b] - p[a];
    const e1y = p[b + 1] - p[a + 1];
    const e1z = p[b + 2] - p[a + 2];
    const e2x = p[c] - p[a];
    const e2y = p[c + 1] - p[a + 1];
    const e2z = p[c + 2] - p[a + 2];
    const nx = e1y * e2z - e1z * e2y;
    const ny = e1z * e2x - e1x * e2z;
    const nz = e1x * e2y - e1y * e2x;
    out[a] += nx; out[a + 1] += ny; out[a + 2] += nz;
    out[b] += nx; out[b + 1] += ny; out[b + 2] += nz;
    out[c] += nx; out[c + 1] += ny; out[c + 2] += nz;
  }
  for (let i = 0; i < out.length; i += 3) {
    const length = Math.hypot(out[i], out[i + 1], out[i + 2]);
    if (length > 0) {
      out[i] /= length;
      out[i + 1] /= length;
      out[i + 2] /= length;
    }
  }
}

export type Vec3 = [number, number, number];

// How to look at a mesh: the camera sits at center + distance·front, with
// `up` up; `halfWidth`/`halfHeight`/`halfDepth` are the bounding box's half
// extents along right = up × front, up and front.
export interface Framing {
  center: Vec3;
  radius: number;     // of the bounding sphere around center (half the box diagonal)
  up: Vec3;
  front: Vec3;
  halfWidth: number;
  halfHeight: number;
  halfDepth: number;
  upAxis: 'y' | 'z';
}

// The eigenvectors of a symmetric 3×3 matrix (row-major, 9 values), by
// Jacobi rotations; sorted by decreasing eigenvalue.
export function principalAxes(m: number[]): { values: number[]; vectors: Vec3[] } {
  const a = m.slice();
  const v = [1, 0, 0, 0, 1, 0, 0, 0, 1];
  for (let sweep = 0; sweep < 50; ++sweep) {
    const off = a[1] ** 2 + a[2] ** 2 + a[5] ** 2;
    if (off < 1e-30 * (a[0] ** 2 + a[4] ** 2 + a[8] ** 2 + 1e-300)) break;
    for (const [p, q] of [[0, 1], [0, 2], [1, 2]]) {
      const apq = a[3 * p + q];
      if (Math.abs(apq) < 1e-300) continue;
      const theta = (a[3 * q + q] - a[3 * p + p]) / (2 * apq);
      const t = Math.sign(theta || 1) / (Math.abs(theta) + Math.sqrt(theta * theta + 1));
      const c = 1 / Math.sqrt(t * t + 1);
      const s = t * c;
      for (let k = 0; k < 3; ++k) {  // a = a·J
        const akp = a[3 * k + p];
        const akq = a[3 * k + q];
        a[3 * k + p] = c * akp - s * akq;
        a[3 * k + q] = s * akp + c * akq;
      }
      for (let k = 0; k < 3; ++k) {  // a = Jᵀ·a
        const apk = a[3 * p + k];
        const aqk = a[3 * q + k];
        a[3 * p + k] = c * apk - s * aqk;
        a[3 * q + k] = s * apk + c * aqk;
      }
      for (let k = 0; k < 3; ++k) {  // v = v·J: columns are the eigenvectors
        const vkp = v[3 * k + p];
        const vkq = v[3 * k + q];
        v[3 * k + p] = c * vkp - s * vkq;
        v[3 * k + q] = s * vkp + c * vkq;
      }
    }
  }
  const order = [0, 1, 2].sort((i, j) => a[4 * j] - a[4 * i]);
  return {
    values: order.map((i) => a[4 * i]),
    vectors: order.map((i) => [v[i], v[3 + i], v[6 + i]] as Vec3),
  };
}

const dot = (a: Vec3, b: Vec3) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a: Vec3, b: Vec3): Vec3 => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];

// Which way is up and which side is the front of a mesh, from its vertices
// and vertex normals (what the viewer frames on load and on "fit").
//
// Up: meshes come Y-up (glTF, most OBJ) or Z-up (scans, CAD, Blender). A body
// standing upright is longest along up, so when the principal axis of largest
// variance is clearly the longest (1.5× the next) and lies along y or z, that
// axis is up; a flat mesh (smallest variance clearly smallest, along z) is a
// Z-up terrain or plate; anything else is taken as Y-up.
// Front: of the four horizontal directions ±right, ±forward, the one most
// vertex normals face (a scan's front carries the detail, hence the
// vertices); ties keep the convention (+z for Y-up, −y for Z-up).
export function frameMesh(positions: Float32Array, normals: Float32Array): Framing {
  const n = positions.length / 3;
  const mean: Vec3 = [0, 0, 0];
  for (let i = 0; i < positions.length; i += 3) {
    mean[0] += positions[i]; mean[1] += positions[i + 1]; mean[2] += positions[i + 2];
  }
  for (let k = 0; k < 3; ++k) mean[k] /= Math.max(n, 1);
  const cov = new Array<number>(9).fill(0);
  for (let i = 0; i < positions.length; i += 3) {
    const d = [positions[i] - mean[0], positions[i + 1] - mean[1], positions[i + 2] - mean[2]];
    for (let r = 0; r < 3; ++r) for (let c = r; c < 3; ++c) cov[3 * r + c] += d[r] * d[c];
  }
  for (let r = 0; r < 3; ++r) for (let c = 0; c < r; ++c) cov[3 * r + c] = cov[3 * c + r];
  const { values, vectors } = principalAxes(cov);

  let upAxis: 'y' | 'z' = 'y';
  const longest = vectors[0];
  const flattest = vectors[2];
  if (values[0] > 1.5 * values[1] && Math.abs(longest[2]) > Math.max(Math.abs(longest[0]), Math.abs(longest[1]))) upAxis = 'z';
  else if (values[0] > 1.5 * values[1] && Math.abs(longest[1]) > Math.max(Math.abs(longest[0]), Math.abs(longest[2]))) upAxis = 'y';
  else if (values[2] < 0.5 * values[1] && Math.abs(flattest[2]) > 0.8) upAxis = 'z';
  const up: Vec3 = upAxis === 'z' ? [0, 0, 1] : [0, 1, 0];

  // The horizontal candidates, the conventional front first (it wins ties).
  const candidates: Vec3[] = upAxis === 'z'
    ? [[0, -1, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0]]
    : [[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0]];
  const facing = [0, 0, 0, 0];
  for (let i = 0; i < normals.length; i += 3) {
    const nv: Vec3 = [normals[i], normals[i + 1], normals[i + 2]];
    candidates.forEach((c, k) => { if (dot(nv, c) > 0.5) ++facing[k]; });
  }
  let best = 0;
  // A clear majority only (5 % more than the convention): noise keeps the convention.
  for (let k = 1; k < 4; ++k) if (facing[k] > facing[best] && facing[k] > 1.05 * facing[0]) best = k;
  const front = candidates[best];
  const right = cross(up, front);

  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < positions.length; i += 3) {
    for (let k = 0; k < 3; ++k) {
      const x = positions[i + k];
      if (x < lo[k]) lo[k] = x;
      if (x > hi[k]) hi[k] = x;
    }
  }
  if (n === 0) return { center: [0, 0, 0], radius: 1, up, front, halfWidth: 1, halfHeight: 1, halfDepth: 1, upAxis };
  const center: Vec3 = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2];
  const half: Vec3 = [(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, (hi[2] - lo[2]) / 2];
  const along = (axis: Vec3) => Math.abs(dot(axis, half));  // axes are coordinate axes
  const radius = Math.max(Math.hypot(...half), 1e-9);
  return { center, radius, up, front, halfWidth: along(right), halfHeight: along(up), halfDepth: along(front), upAxis };
}

// The camera distance from the centre at which a box of half extents
// (halfWidth, halfHeight) in the view plane, halfDepth towards the camera,
// fills `fill` of the view's height or width, whichever binds first.
export function fitDistance(f: Pick<Framing, 'halfWidth' | 'halfHeight' | 'halfDepth'>, fovYDegrees: number,
  aspect: number, fill = 0.8): number {
  const tanY = Math.tan((fovYDegrees * Math.PI) / 360);
  const tanX = tanY * aspect;
  const h = Math.max(f.halfHeight, 1e-9);
  const w = Math.max(f.halfWidth, 1e-9);
  // The box's near face is halfDepth closer than the centre.
  return f.halfDepth + Math.max(h / (fill * tanY), w / (fill * tanX));
}

// Proportional editing: the weight of a point at `distance` from the dragged
// point, for an influence radius: 1 at the point, falling smoothly
// (smoothstep) to 0 at the radius, 0 beyond.
export function falloff(distance: number, radius: number): number {
  if (!(radius > 0) || distance >= radius) return 0;
  const t = distance / radius;
  return 1 - t * t * (3 - 2 * t);
}

// A coarse stand-in for a dense mesh, drawn while frames stream or the view
// moves (software GL spends its time on vertices): triangles over a subset
// of the mesh's own vertices, so the live position attribute moves it too.
// Vertex clustering: the vertices in each cell of a grid over the bounding
// box collapse onto the first of them; triangles that collapse are dropped,
// duplicates kept once. The grid is refined until the result has at least
// `target` / 2 triangles (or 512 cells a side). null for meshes of no more
// than 2·target triangles: they are cheap enough.
export function coarseIndex(positions: Float32Array, faces: Uint32Array, target = 40_000): Uint32Array | null {
  const triangles = faces.length / 3;
  if (triangles <= 2 * target) return null;
  const n = positions.length / 3;
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < positions.length; i += 3) {
    for (let k = 0; k < 3; ++k) {
      lo[k] = Math.min(lo[k], positions[i + k]);
      hi[k] = Math.max(hi[k], positions[i + k]);
    }
  }
  const size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-12);
  const representative = new Int32Array(n);
  for (let cells = 32; ; cells *= 2) {
    const scale = cells / size;
    const first = new Map<number, number>();
    for (let v = 0; v < n; ++v) {
      const x = Math.min(cells - 1, Math.floor((positions[3 * v] - lo[0]) * scale));
      const y = Math.min(cells - 1, Math.floor((positions[3 * v + 1] - lo[1]) * scale));
      const z = Math.min(cells - 1, Math.floor((positions[3 * v + 2] - lo[2]) * scale));
      const key = (x * cells + y) * cells + z;
      let r = first.get(key);
      if (r === undefined) {
        r = v;
        first.set(key, v);
      }
      representative[v] = r;
    }
    const out: number[] = [];
    const seen = new Set<string>();
    for (let f = 0; f < faces.length; f += 3) {
      const a = representative[faces[f]];
      const b = representative[faces[f + 1]];
      const c = representative[faces[f + 2]];
      if (a === b || b === c || a === c) continue;
      const sorted = [a, b, c].sort((p, q) => p - q);
      const key = `${sorted[0]},${sorted[1]},${sorted[2]}`;
      if (seen.has(key)) continue;
      seen.add(key);
      out.push(a, b, c);
    }
    if (out.length / 3 >= target / 2 || cells >= 512) return Uint32Array.from(out);
  }
}

// The triangle of `faces` a ray (origin o, direction d) meets first, both
// sides counting (Möller–Trumbore over flat arrays: no allocation, ~1 ms per
// 50k triangles, where a generic raycast takes ten times as long): its index
// and the hit's barycentric weights of its corners (w0 = 1 − u − v, u, v);
// null when it meets none.
export function firstHit(positions: Float32Array, faces: Uint32Array | Uint16Array, o: readonly number[], d: readonly number[]):
  { face: number; u: number; v: number; t: number } | null {
  let best = -1;
  let bestT = Infinity;
  let bestU = 0;
  let bestV = 0;
  const [ox, oy, oz] = o;
  const [dx, dy, dz] = d;
  for (let f = 0; f < faces.length; f += 3) {
    const a = 3 * faces[f];
    const b = 3 * faces[f + 1];
    const c = 3 * faces[f + 2];
    const ax = positions[a], ay = positions[a + 1], az = positions[a + 2];
    const e1x = positions[b] - ax, e1y = positions[b + 1] - ay, e1z = positions[b + 2] - az;
    const e2x = positions[c] - ax, e2y = positions[c + 1] - ay, e2z = positions[c + 2] - az;
    const px = dy * e2z - dz * e2y, py = dz * e2x - dx * e2z, pz = dx * e2y - dy * e2x;
    const det = e1x * px + e1y * py + e1z * pz;
    if (det > -1e-12 && det < 1e-12) continue;  // parallel (or degenerate)
    const inv = 1 / det;
    const sx = ox - ax, sy = oy - ay, sz = oz - az;
    const u = (sx * px + sy * py + sz * pz) * inv;
    if (u < 0 || u > 1) continue;
    const qx = sy * e1z - sz * e1y, qy = sz * e1x - sx * e1z, qz = sx * e1y - sy * e1x;
    const v = (dx * qx + dy * qy + dz * qz) * inv;
    if (v < 0 || u + v > 1) continue;
    const t = (e2x * qx + e2y * qy + e2z * qz) * inv;
    if (t <= 0 || t >= bestT) continue;
    best = f / 3;
    bestT = t;
    bestU = u;
    bestV = v;
  }
  return best < 0 ? null : { face: best, u: bestU, v: bestV, t: bestT };
}
