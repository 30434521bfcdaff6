// The session worker's mesh arithmetic (geometry.ts): normals as three.js
// computes them, the framing of Y-up and Z-up meshes from their front, the
// fit distance, the proportional-editing falloff; and the reconnect policy.
import { mkdtempSync, readFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { Code, ConnectError } from '@connectrpc/connect';
import * as THREE from 'three';
import { describe, expect, it } from 'vitest';

import { coarseIndex, falloff, firstHit, fitDistance, frameMesh, principalAxes, vertexNormals, type Vec3 } from '../src/geometry';
import { isFinal, LONG_CAP_MS, retryDelay, SHORT_CAP_MS } from '../src/reconnect';
// @ts-expect-error: a plain ES module of the browser test, without types
import { writeEllipsoidObj } from './harness.mjs';

function readObj(path: string): { positions: Float32Array; faces: Uint32Array } {
  const p: number[] = [];
  const f: number[] = [];
  for (const line of readFileSync(path, 'utf8').split('\n')) {
    const [kind, ...rest] = line.trim().split(/\s+/);
    if (kind === 'v') p.push(...rest.slice(0, 3).map(Number));
    if (kind === 'f') f.push(...rest.slice(0, 3).map((x) => Number(x.split('/')[0]) - 1));
  }
  return { positions: Float32Array.from(p), faces: Uint32Array.from(f) };
}

function ellipsoid(axes: Vec3, up: 'y' | 'z', front: Vec3) {
  const path = join(mkdtempSync(join(tmpdir(), 'filigree-geometry-')), 'e.obj');
  writeEllipsoidObj(path, axes, up, front);
  const mesh = readObj(path);
  const normals = new Float32Array(mesh.positions.length);
  vertexNormals(mesh.positions, mesh.faces, normals);
  return { ...mesh, normals };
}

// Signed volume: positive when the faces wind outwards.
function volume(positions: Float32Array, faces: Uint32Array): number {
  let v = 0;
  const at = (i: number) => new THREE.Vector3().fromArray(positions, 3 * i);
  for (let f = 0; f < faces.length; f += 3) v += at(faces[f]).dot(at(faces[f + 1]).cross(at(faces[f + 2]))) / 6;
  return v;
}

describe('vertexNormals', () => {
  it('equals three.js computeVertexNormals', () => {
    const { positions, faces, normals } = ellipsoid([1, 0.6, 3], 'z', [1, 0, 0]);
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    geometry.setIndex(new THREE.BufferAttribute(faces, 1));
    geometry.computeVertexNormals();
    const expected = geometry.getAttribute('normal').array;
    for (let i = 0; i < normals.length; ++i) expect(normals[i]).toBeCloseTo(expected[i], 5);
  });
});

describe('principalAxes', () => {
  it('finds the eigenvectors of a rotated diagonal matrix, largest first', () => {
    const r = new THREE.Matrix3().setFromMatrix4(new THREE.Matrix4().makeRotationFromEuler(new THREE.Euler(0.3, -0.7, 1.1)));
    const d = new THREE.Matrix3().set(5, 0, 0, 0, 1, 0, 0, 0, 3);
    const m = r.clone().multiply(d).multiply(r.clone().transpose());
    const rowMajor = [0, 1, 2].flatMap((i) => [0, 1, 2].map((j) => m.elements[3 * j + i]));
    const { values, vectors } = principalAxes(rowMajor);
    expect(values[0]).toBeCloseTo(5, 9);
    expect(values[1]).toBeCloseTo(3, 9);
    expect(values[2]).toBeCloseTo(1, 9);
    const column = (k: number) => new THREE.Vector3(r.elements[3 * k], r.elements[3 * k + 1], r.elements[3 * k + 2]);
    expect(Math.abs(new THREE.Vector3(...vectors[0]).dot(column(0)))).toBeCloseTo(1, 9);
    expect(Math.abs(new THREE.Vector3(...vectors[1]).dot(column(2)))).toBeCloseTo(1, 9);
  });
});

describe('frameMesh', () => {
  it('the test ellipsoids wind outwards', () => {
    const { positions, faces } = ellipsoid([1, 0.6, 3], 'z', [1, 0, 0]);
    expect(volume(positions, faces)).toBeGreaterThan(0);
  });

  it('frames a Z-up body from the side most normals face', () => {
    const { positions, normals } = ellipsoid([1, 0.6, 3], 'z', [1, 0, 0]);
    const f = frameMesh(positions, normals);
    expect(f.upAxis).toBe('z');
    expect(f.up).toEqual([0, 0, 1]);
    expect(f.front).toEqual([1, 0, 0]);
    expect(f.halfHeight).toBeCloseTo(3, 5);
    expect(f.halfWidth).toBeCloseTo(0.6, 2);
  });

  it('frames a Y-up body from the side most normals face', () => {
    const { positions, normals } = ellipsoid([1, 3, 0.6], 'y', [0, 0, -1]);
    const f = frameMesh(positions, normals);
    expect(f.upAxis).toBe('y');
    expect(f.front).toEqual([0, 0, -1]);
    expect(f.halfHeight).toBeCloseTo(3, 5);
  });

  it('takes a flat mesh lying in xy as Z-up, and a round one as Y-up from +z', () => {
    const flat = ellipsoid([3, 2.5, 0.3], 'z', [0, -1, 0]);
    expect(frameMesh(flat.positions, flat.normals).upAxis).toBe('z');
    // A sphere sampled evenly: no clear front, the convention.
    const round = ellipsoid([1, 1, 1], 'y', [0, 0, 1]);
    const f = frameMesh(round.positions, round.normals);
    expect(f.upAxis).toBe('y');
    expect(f.front).toEqual([0, 0, 1]);
  });
});

describe('fitDistance', () => {
  it('puts the box at the asked fraction of the binding dimension', () => {
    const d = fitDistance({ halfWidth: 1, halfHeight: 3, halfDepth: 0.5 }, 40, 4 / 3, 0.8);
    // Height binds: 3 / ((d − 0.5)·tan 20°) = 0.8.
    expect(3 / ((d - 0.5) * Math.tan((20 * Math.PI) / 180))).toBeCloseTo(0.8, 9);
    const wide = fitDistance({ halfWidth: 3, halfHeight: 1, halfDepth: 0 }, 40, 0.5, 0.8);
    expect(3 / (wide * Math.tan((20 * Math.PI) / 180) * 0.5)).toBeCloseTo(0.8, 9);
  });
});

describe('coarseIndex', () => {
  it('stands in for a dense mesh with fewer triangles over its own vertices, none degenerate', () => {
    const { positions, faces } = ellipsoid([1, 0.6, 3], 'z', [1, 0, 0]);  // 2256 triangles
    expect(coarseIndex(positions, faces, 2000)).toBeNull();  // small enough as it is
    const coarse = coarseIndex(positions, faces, 400)!;
    const triangles = coarse.length / 3;
    expect(triangles).toBeGreaterThanOrEqual(200);
    expect(triangles).toBeLessThan(faces.length / 3);
    const n = positions.length / 3;
    for (let f = 0; f < coarse.length; f += 3) {
      const [a, b, c] = [coarse[f], coarse[f + 1], coarse[f + 2]];
      expect(a < n && b < n && c < n).toBe(true);
      expect(a !== b && b !== c && a !== c).toBe(true);
    }
    // It still wraps the body: its signed volume is most of the mesh's.
    expect(volume(positions, coarse)).toBeGreaterThan(0.8 * volume(positions, faces));
  });
});

describe('falloff', () => {
  it('is 1 at the point, smooth, 0 at and beyond the radius', () => {
    expect(falloff(0, 2)).toBe(1);
    expect(falloff(1, 2)).toBeCloseTo(0.5, 12);
    expect(falloff(2, 2)).toBe(0);
    expect(falloff(5, 2)).toBe(0);
    expect(falloff(1, 0)).toBe(0);
    for (let d = 0; d < 2; d += 0.1) expect(falloff(d + 0.1, 2)).toBeLessThanOrEqual(falloff(d, 2));
  });
});

describe('reconnect policy', () => {
  it('backs off exponentially to a cap, with jitter between half and all of it', () => {
    expect(retryDelay(1, 0, () => 0)).toBe(125);
    expect(retryDelay(1, 0, () => 1)).toBe(250);
    expect(retryDelay(3, 0, () => 1)).toBe(1000);
    expect(retryDelay(10, 0, () => 1)).toBe(SHORT_CAP_MS);
    expect(retryDelay(10, 0, () => 0)).toBe(SHORT_CAP_MS / 2);
    // After a minute without the server, retries thin out.
    expect(retryDelay(30, 120_000, () => 1)).toBe(LONG_CAP_MS);
  });

  it('stops only for a session that is gone or a refused token', () => {
    for (const code of [Code.NotFound, Code.PermissionDenied, Code.Unauthenticated]) {
      expect(isFinal(new ConnectError('x', code))).toBe(true);
    }
    for (const code of [Code.Unavailable, Code.Unknown, Code.Internal, Code.Canceled, Code.DeadlineExceeded, Code.Aborted]) {
      expect(isFinal(new ConnectError('x', code))).toBe(false);
    }
    expect(isFinal(null)).toBe(false);
    expect(isFinal(new TypeError('Failed to fetch'))).toBe(false);
  });
});

describe('firstHit', () => {
  // Two unit squares facing +z, at z = 0 and z = −1, as four triangles.
  const positions = new Float32Array([0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, -1, 1, 0, -1, 1, 1, -1, 0, 1, -1]);
  const faces = new Uint32Array([0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7]);

  it('finds the nearest triangle along the ray, from either side, with its barycentric weights', () => {
    const hit = firstHit(positions, faces, [0.9, 0.2, 5], [0, 0, -1]);
    expect(hit?.face).toBe(0);
    expect(hit!.t).toBeCloseTo(5);
    expect(1 - hit!.u - hit!.v).toBeCloseTo(0.1);  // a weight per corner: (0.9, 0.2) is 0.7 of corner 1
    expect(hit!.u).toBeCloseTo(0.7);
    expect(firstHit(positions, faces, [0.2, 0.9, -5], [0, 0, 1])?.face).toBe(3);  // from behind: the far square first
    expect(firstHit(positions, faces, [2, 2, 5], [0, 0, -1])).toBeNull();
    expect(firstHit(positions, faces, [0.5, 0.5, 5], [0, 0, 1])).toBeNull();  // pointing away
  });
});
