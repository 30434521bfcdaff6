// A rest mesh in parts (GetRestMesh): the arrays continue from part to part,
// positions, then faces, then uploaded_ids, a part possibly spanning two; the
// parts must add up to the announced counts, no more, no less.
import { describe, expect, it } from 'vitest';

import { RestAssembler, RestPartsError, type RestPart } from '../src/rest-parts';

// A mesh of n vertices and f faces, its arrays cut into parts of `size` values.
function mesh(n: number, f: number) {
  const positions = Array.from({ length: 3 * n }, (_, i) => i * 0.5);
  const faces = Array.from({ length: 3 * f }, (_, i) => (i * 7) % n);
  const uploadedIds = Array.from({ length: n }, (_, i) => n - 1 - i);
  return { positions, faces, uploadedIds };
}

function parts(m: ReturnType<typeof mesh>, size: number): RestPart[] {
  const all = [...m.positions.map((v) => ['p', v] as const), ...m.faces.map((v) => ['f', v] as const),
    ...m.uploadedIds.map((v) => ['u', v] as const)];
  const out: RestPart[] = [];
  for (let at = 0; at < all.length; at += size) {
    const slice = all.slice(at, at + size);
    out.push({
      positions: slice.filter(([k]) => k === 'p').map(([, v]) => v),
      faces: slice.filter(([k]) => k === 'f').map(([, v]) => v),
      uploadedIds: slice.filter(([k]) => k === 'u').map(([, v]) => v),
    });
  }
  return out;
}

describe('a rest mesh in parts', () => {
  it('assembles parts that end one array and start the next, counting progress', () => {
    const m = mesh(10, 7);
    const assembler = new RestAssembler(10, 7);
    expect(assembler.total).toBe(30 + 21 + 10);
    const fractions: number[] = [];
    const split = parts(m, 8);  // 8 does not divide 30 or 21: parts span arrays
    expect(split.some((p) => p.positions.length > 0 && p.faces.length > 0)).toBe(true);
    expect(split.some((p) => p.faces.length > 0 && p.uploadedIds.length > 0)).toBe(true);
    for (const part of split) {
      assembler.push(part);
      fractions.push(assembler.fraction);
    }
    assembler.finish();
    expect(Array.from(assembler.positions)).toEqual(m.positions);
    expect(Array.from(assembler.faces)).toEqual(m.faces);
    expect(Array.from(assembler.uploadedIds)).toEqual(m.uploadedIds);
    expect(assembler.parts).toBe(split.length);
    expect(fractions.at(-1)).toBe(1);
    expect(fractions).toEqual([...fractions].sort((a, b) => a - b));
  });

  it('refuses parts that hold more than the announced counts', () => {
    const m = mesh(4, 2);
    const assembler = new RestAssembler(4, 2);
    for (const part of parts(m, 5)) assembler.push(part);
    expect(() => assembler.push({ positions: [], faces: [0, 1, 2], uploadedIds: [] })).toThrow(RestPartsError);
    expect(() => new RestAssembler(4, 2).push({ positions: new Array(13).fill(0), faces: [], uploadedIds: [] }))
      .toThrow(/holds more than its 4 vertices and 2 faces/);
  });

  it('refuses an end that holds less: too few positions, faces or uploaded ids', () => {
    const m = mesh(4, 2);
    const all = parts(m, 4);
    for (const drop of [0, all.length - 3, all.length - 1]) {
      const assembler = new RestAssembler(4, 2);
      all.filter((_, i) => i !== drop).forEach((p) => assembler.push(p));
      expect(() => assembler.finish()).toThrow(/arrived incomplete/);
    }
    // No part at all.
    expect(() => new RestAssembler(4, 2).finish()).toThrow(/0 parts hold 0 vertices, 0 faces/);
  });

  it('takes a mesh without uploaded ids, and refuses a face naming a vertex it does not have', () => {
    const withoutIds = new RestAssembler(3, 1);
    withoutIds.push({ positions: new Array(9).fill(1), faces: [0, 1, 2], uploadedIds: [] });
    withoutIds.finish();
    const bad = new RestAssembler(3, 1);
    bad.push({ positions: new Array(9).fill(1), faces: [0, 1, 3], uploadedIds: [0, 1, 2] });
    expect(() => bad.finish()).toThrow(/face 0 names vertex 3 of 3/);
  });
});
