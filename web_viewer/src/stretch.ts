// Per-triangle stretch of the current mesh against the rest mesh (Sander et
// al. 2001): each triangle's affine map from its rest plane to its current
// position has singular values Γ ≥ γ; its L2 stretch is sqrt((Γ² + γ²) / 2),
// 1 for a rigid motion. Pure, so the unit tests check it without a browser.

export class TriangleStretch {
  // Per face a, b, c with J = [a·d1 | b·d1 + c·d2] for the current edges
  // d1 = q1 − q0, d2 = q2 − q0: the rest triangle laid out in its own plane as
  // (0,0), (l,0), (u, v) gives a = 1/l, b = −u/(l·v), c = 1/v. NaN: degenerate.
  private readonly coefficients: Float64Array;

  constructor(rest: ArrayLike<number>, private readonly faces: ArrayLike<number>) {
    const count = Math.floor(faces.length / 3);
    this.coefficients = new Float64Array(3 * count);
    const e1 = [0, 0, 0];
    const e2 = [0, 0, 0];
    for (let f = 0; f < count; ++f) {
      edges(rest, faces, f, e1, e2);
      const l = Math.hypot(e1[0], e1[1], e1[2]);
      const u = dot(e1, e2) / l;
      const v = Math.hypot(e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]) / l;
      const ok = l > 0 && v > 1e-12 * l;
      this.coefficients[3 * f] = ok ? 1 / l : NaN;
      this.coefficients[3 * f + 1] = ok ? -u / (l * v) : NaN;
      this.coefficients[3 * f + 2] = ok ? 1 / v : NaN;
    }
  }

  get triangleCount(): number {
    return this.coefficients.length / 3;
  }

  // Γ and γ of face f at the current positions; [1, 1] for a degenerate rest triangle.
  singularValues(current: ArrayLike<number>, f: number): [number, number] {
    const [g11, g12, g22] = this.metric(current, f);
    if (Number.isNaN(g11)) return [1, 1];
    const half = (g11 + g22) / 2;
    const root = Math.sqrt(Math.max(0, half * half - (g11 * g22 - g12 * g12)));
    return [Math.sqrt(half + root), Math.sqrt(Math.max(0, half - root))];
  }

  // The L2 stretch of every face into `out` (one value per face).
  l2(current: ArrayLike<number>, out: Float32Array): void {
    for (let f = 0; f < out.length; ++f) {
      const [g11, , g22] = this.metric(current, f);
      // Γ² + γ² is the trace of JᵀJ: no eigenvalues needed.
      out[f] = Number.isNaN(g11) ? 1 : Math.sqrt((g11 + g22) / 2);
    }
  }

  // JᵀJ = [[g11, g12], [g12, g22]].
  private metric(current: ArrayLike<number>, f: number): [number, number, number] {
    const { d1, d2, c1, c2 } = this;
    edges(current, this.faces, f, d1, d2);
    const a = this.coefficients[3 * f];
    const b = this.coefficients[3 * f + 1];
    const c = this.coefficients[3 * f + 2];
    for (let k = 0; k < 3; ++k) {
      c1[k] = a * d1[k];
      c2[k] = b * d1[k] + c * d2[k];
    }
    return [dot(c1, c1), dot(c1, c2), dot(c2, c2)];
  }

  // Scratch vectors of metric(): no allocation per face.
  private readonly d1 = [0, 0, 0];
  private readonly d2 = [0, 0, 0];
  private readonly c1 = [0, 0, 0];
  private readonly c2 = [0, 0, 0];
}

export function l2Stretch(big: number, small: number): number {
  return Math.sqrt((big * big + small * small) / 2);
}

// The heat map's ramp: |L2 − 1| from 0 (blue) to STRETCH_RED and beyond (red).
export const STRETCH_RED = 0.2;
const BLUE = [0.3, 0.5, 0.95];
const RED = [0.95, 0.18, 0.12];

// sRGB components in [0, 1].
export function stretchColor(l2: number): [number, number, number] {
  const t = Math.min(Math.abs(l2 - 1) / STRETCH_RED, 1);
  return [0, 1, 2].map((k) => BLUE[k] + t * (RED[k] - BLUE[k])) as [number, number, number];
}

function edges(p: ArrayLike<number>, faces: ArrayLike<number>, f: number, e1: number[], e2: number[]): void {
  const i0 = 3 * faces[3 * f];
  const i1 = 3 * faces[3 * f + 1];
  const i2 = 3 * faces[3 * f + 2];
  for (let k = 0; k < 3; ++k) {
    e1[k] = p[i1 + k] - p[i0 + k];
    e2[k] = p[i2 + k] - p[i0 + k];
  }
}

function dot(a: number[], b: number[]): number {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
