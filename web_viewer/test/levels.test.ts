// Levels of detail: the level's mesh (DetailLevel.mesh) encoded here as the
// server encodes it and decoded by src/levels.ts; the mapping between level
// indices and original ids; a level's frames applied to the level's rest
// positions matching the full mesh's at the same ids; and the page's choice
// of a budget (src/detail.ts: the address, the panel's label and levels, Auto).
import draco3d from 'draco3d';
import { beforeAll, describe, expect, it } from 'vitest';

import {
  AUTO_ABOVE, AutoDetail, BLOCK_MS, BUSY_BUDGET, detailLabel, IDLE_MS, levelChoices, MIN_BUDGET, parseDetail, REFINE_AFTER_MS,
  SETTLE_MS, type DetailSample,
} from '../src/detail';
import { applyDeltas, decodeAndApply, FrameError, KeyedDeltas, type DracoDecoderModule } from '../src/frame';
import {
  decodeLevelMesh, facesOnLevel, gather1, gather3, levelIndexOf, levelIndices, levelOfPoints, levelVerticesFor,
  type DracoMeshModule,
} from '../src/levels';
import { encodeChunks, encodeDeltas, encodeLevelMesh, quantizationBound } from './encode';

let draco: DracoDecoderModule & DracoMeshModule;
beforeAll(async () => {
  draco = (await draco3d.createDecoderModule({})) as DracoDecoderModule & DracoMeshModule;
});

// A W×H grid (the full mesh) and a level of it: the vertices of even row and
// column, triangulated as a grid of their own.
const W = 21;
const H = 17;
const N = W * H;
function grid(w: number, h: number, at: (x: number, y: number) => number): Uint32Array {
  const faces: number[] = [];
  for (let y = 0; y + 1 < h; ++y) {
    for (let x = 0; x + 1 < w; ++x) faces.push(at(x, y), at(x + 1, y), at(x + 1, y + 1), at(x, y), at(x + 1, y + 1), at(x, y + 1));
  }
  return Uint32Array.from(faces);
}
const fullRest = Float32Array.from({ length: 3 * N }, (_, i) => {
  const v = Math.floor(i / 3);
  return [v % W, Math.floor(v / W), 0.1 * Math.sin(v)][i % 3];
});
const LW = (W + 1) / 2;
const LH = (H + 1) / 2;
const levelIds = Uint32Array.from({ length: LW * LH }, (_, i) => 2 * (i % LW) + 2 * W * Math.floor(i / LW));
const levelFaces = grid(LW, LH, (x, y) => y * LW + x);
const K = levelIds.length;

// Faces over original ids as oriented triangles: each rotated to start at
// its smallest id, then sorted (Edgebreaker reorders faces and corners).
function orientedFaces(ids: ArrayLike<number>, faces: ArrayLike<number>): string[] {
  const out: string[] = [];
  for (let f = 0; f < faces.length; f += 3) {
    const t = [ids[faces[f]], ids[faces[f + 1]], ids[faces[f + 2]]];
    const m = t.indexOf(Math.min(...t));
    out.push([t[m], t[(m + 1) % 3], t[(m + 2) % 3]].join(','));
  }
  return out.sort();
}

describe('the level\'s mesh (DetailLevel.mesh)', () => {
  it('decodes the ids ascending and the faces, oriented as encoded, over them', async () => {
    const bytes = await encodeLevelMesh(levelIds, levelFaces);
    expect(bytes[8]).toBe(1);  // Edgebreaker, as the server encodes it
    const level = decodeLevelMesh(draco, bytes, K, levelFaces.length / 3, N);
    expect(Array.from(level.ids)).toEqual(Array.from(levelIds));
    expect(orientedFaces(level.ids, level.faces)).toEqual(orientedFaces(levelIds, levelFaces));
    // Another encoding of the same mesh reads the same.
    const sequential = decodeLevelMesh(draco, await encodeLevelMesh(levelIds, levelFaces, 'sequential'), K, levelFaces.length / 3, N);
    expect(Array.from(sequential.ids)).toEqual(Array.from(levelIds));
    expect(orientedFaces(sequential.ids, sequential.faces)).toEqual(orientedFaces(levelIds, levelFaces));
  });

  it('takes points in any order, a vertex split into several points, as the distinct ids ascending', () => {
    // Points: ids 40, 3, 9, 40 again (a split vertex), 8; faces over points.
    const level = levelOfPoints(Uint32Array.from([40, 3, 9, 40, 8]), Uint32Array.from([1, 4, 2, 3, 2, 4, 0, 1, 2]), 100);
    expect(Array.from(level.ids)).toEqual([3, 8, 9, 40]);
    expect(Array.from(level.faces)).toEqual([0, 1, 2, 3, 2, 1, 3, 0, 2]);
    expect(() => levelOfPoints(Uint32Array.from([1, 2, 100]), Uint32Array.from([0, 1, 2]), 100)).toThrow(/past the mesh/);
    expect(() => levelOfPoints(Uint32Array.from([1, 2, 3]), Uint32Array.from([0, 1, 3]), 100)).toThrow(/names point 3/);
  });

  it('refuses other counts than announced, a point cloud, what is no Draco, an id past the mesh', async () => {
    const bytes = await encodeLevelMesh(levelIds, levelFaces);
    expect(() => decodeLevelMesh(draco, bytes, K + 1, levelFaces.length / 3, N)).toThrow(/vertices, announced/);
    expect(() => decodeLevelMesh(draco, bytes, K, levelFaces.length / 3 - 1, N)).toThrow(/faces, announced/);
    const cloud = await encodeDeltas(new Float32Array(30).fill(1), 12);
    expect(() => decodeLevelMesh(draco, cloud, 10, 0, N)).toThrow(/not a mesh/);
    expect(() => decodeLevelMesh(draco, new Uint8Array([1, 2, 3]), K, 0, N)).toThrow(FrameError);
    expect(() => decodeLevelMesh(draco, bytes, K, levelFaces.length / 3, levelIds[K - 1])).toThrow(/past the mesh/);
  });
});

describe('level indices and original ids', () => {
  it('maps each way, −1 for a vertex the level lacks', () => {
    levelIds.forEach((id, i) => expect(levelIndexOf(levelIds, id)).toBe(i));
    expect(levelIndexOf(levelIds, 1)).toBe(-1);
    expect(levelIndexOf(levelIds, N + 5)).toBe(-1);
    expect(levelIndexOf(null, 7, N)).toBe(7);
    expect(levelIndexOf(null, N, N)).toBe(-1);
    expect(Array.from(levelIndices(levelIds, Uint32Array.from([0, 1, 2 * W + 2])))).toEqual([0, -1, LW + 1]);
  });

  it('gathers the full mesh\'s values at the level\'s vertices', () => {
    const rest = gather3(fullRest, levelIds);
    levelIds.forEach((id, i) => expect(Array.from(rest.subarray(3 * i, 3 * i + 3))).toEqual(Array.from(fullRest.subarray(3 * id, 3 * id + 3))));
    const region = Uint32Array.from({ length: N }, (_, v) => v % 5);
    expect(Array.from(gather1(region, levelIds, new Uint32Array(K)))).toEqual(Array.from(levelIds, (id) => id % 5));
  });

  it('keeps the cut\'s triangles whose corners the level holds, over level indices', () => {
    const cut = Uint32Array.from([0, 2, 2 * W, /* */ 0, 1, W, /* */ 2, 4, 2 * W + 2]);
    expect(Array.from(facesOnLevel(levelIds, cut))).toEqual([0, 1, LW, 1, 2, LW + 1]);
  });

  it('picks the level a budget gets as the server does', () => {
    const base = 300;
    const n = 1_000_000;
    expect(levelVerticesFor(65_536, base, n)).toBe(65_536);
    expect(levelVerticesFor(100_000, base, n)).toBe(65_536);     // down to a power of two
    expect(levelVerticesFor(200, base, n)).toBe(base);            // below the base: the base
    expect(levelVerticesFor(400, base, n)).toBe(base);            // 256 is below the base too
    expect(levelVerticesFor(512, base, n)).toBe(512);
    expect(levelVerticesFor(n, base, n)).toBe(n);                 // the mesh or more: full
    expect(levelVerticesFor(2 ** 31, base, n)).toBe(n);
    expect(levelVerticesFor(999_999, base, n)).toBe(524_288);
  });
});

describe('a level\'s frames', () => {
  // Full deltas that differ per vertex, so that a vertex taken from the wrong place shows.
  const fullDeltas = Float32Array.from({ length: 3 * N }, (_, i) => 0.2 * Math.sin(0.37 * i) + 0.01 * (i % 7));

  it('applied to the level\'s rest positions, match the full frame\'s positions at the same ids', async () => {
    const BITS = 14;
    const levelDeltas = gather3(fullDeltas, levelIds);
    const keyed = new KeyedDeltas(K);
    decodeAndApply(draco, keyed, { version: 3n, keyframeVersion: 3n, vertexCount: K, chunks: await encodeChunks(levelDeltas, 16, BITS) });
    const levelPositions = new Float32Array(3 * K);
    applyDeltas(gather3(fullRest, levelIds), keyed.deltas, levelPositions);
    const full = new Float32Array(3 * N);
    applyDeltas(fullRest, fullDeltas, full);
    let worst = 0;
    levelIds.forEach((id, i) => {
      for (let k = 0; k < 3; ++k) worst = Math.max(worst, Math.abs(levelPositions[3 * i + k] - full[3 * id + k]));
    });
    // Each chunk is quantized over its own values: the whole range bounds every chunk's step.
    expect(worst).toBeLessThanOrEqual(quantizationBound(levelDeltas, BITS));
    // Read by level index as if it were an original id, the same positions are far off.
    let wrong = 0;
    for (let i = 1; i < K; ++i) wrong = Math.max(wrong, Math.abs(levelPositions[3 * i] - full[3 * i]));
    expect(wrong).toBeGreaterThan(1);
  });
});

describe('the detail the page asks for', () => {
  it('reads detail= of the address', () => {
    expect(parseDetail(undefined)).toEqual({ mode: 'auto', start: null });
    expect(parseDetail('auto')).toEqual({ mode: 'auto', start: null });
    expect(parseDetail('auto:2048')).toEqual({ mode: 'auto', start: 2048 });
    expect(parseDetail('Full')).toEqual({ mode: 'full' });
    expect(parseDetail('65536')).toEqual({ mode: 'fixed', budget: 65536 });
    expect(parseDetail('0')).toHaveProperty('error');
    expect(parseDetail('-3')).toHaveProperty('error');
    expect(parseDetail('lots')).toHaveProperty('error');
  });

  it('labels the level drawn and offers the levels between the base and the mesh', () => {
    expect(detailLabel(65_536, 1_000_000)).toBe('Detail: 65,536 of 1,000,000 vertices');
    expect(levelChoices(1_000_000, 20_000)).toEqual([32_768, 65_536, 131_072, 262_144, 524_288]);
    expect(levelChoices(1_000_000, 100, 3)).toEqual([131_072, 262_144, 524_288]);
    expect(levelChoices(10_242, 204)).toEqual([256, 512, 1024, 2048, 4096, 8192]);
    expect(levelChoices(1000, 1000)).toEqual([]);
  });
});

describe('Auto', () => {
  const n = 1_000_000;
  const base = 20_000;
  // A session driven at 10 frames/s from t = 0, the page keeping up unless told.
  const sample = (now: number, extra: Partial<DetailSample> = {}): DetailSample => ({
    now, lastArrivalAt: now - 50, arrivedPerSecond: 10, appliedPerSecond: 10, drawnPerSecond: 10, interacting: false, ...extra,
  });

  it('asks a large mesh for a coarse level while frames stream, and full detail once they stop', () => {
    const auto = new AutoDetail(n, base);
    expect(auto.budget).toBe(BUSY_BUDGET);
    expect(auto.update(sample(1000))).toBe(BUSY_BUDGET);
    // The last frame arrived at 2000: still busy just before IDLE_MS, full detail after.
    expect(auto.update(sample(2000 + IDLE_MS - 10, { lastArrivalAt: 2000 }))).toBe(BUSY_BUDGET);
    expect(auto.update(sample(2000 + IDLE_MS + 10, { lastArrivalAt: 2000 }))).toBe(n);
    expect(auto.reason).toBe('idle');
    // A new frame: the coarse level again.
    expect(auto.update(sample(5000))).toBe(BUSY_BUDGET);
    expect(auto.reason).toBe('busy');
    // A drag keeps it busy even before its frames come.
    expect(auto.update(sample(9000, { lastArrivalAt: 5000 }))).toBe(n);
    expect(auto.update(sample(9010, { lastArrivalAt: 5000, interacting: true }))).toBe(BUSY_BUDGET);
  });

  it('goes coarser while the page falls behind, down to a floor, and not at once after a switch', () => {
    const auto = new AutoDetail(n, base);
    auto.levelShown(0);
    const behind = { appliedPerSecond: 6 };
    expect(auto.update(sample(SETTLE_MS - 10, behind))).toBe(BUSY_BUDGET);  // the statistics still describe the old level
    expect(auto.update(sample(SETTLE_MS + 10, behind))).toBe(BUSY_BUDGET / 2);
    expect(auto.reason).toBe('behind');
    let t = SETTLE_MS + 10;
    for (let i = 0; i < 5; ++i) {
      auto.levelShown(t);
      t += SETTLE_MS + 10;
      auto.update(sample(t, { drawnPerSecond: 3 }));  // drawing too few
    }
    expect(auto.budget).toBe(MIN_BUDGET);
  });

  it('goes one step finer after keeping up a while, but not back to a level it left for falling behind', () => {
    const auto = new AutoDetail(n, base);
    auto.levelShown(0);
    auto.update(sample(SETTLE_MS + 10, { appliedPerSecond: 5 }));
    expect(auto.budget).toBe(BUSY_BUDGET / 2);
    auto.levelShown(SETTLE_MS + 10);
    // Keeping up: within BLOCK_MS it stays (65,536 was left for falling behind) …
    for (let t = 2 * SETTLE_MS; t < BLOCK_MS; t += 500) expect(auto.update(sample(t))).toBe(BUSY_BUDGET / 2);
    // … after it, one step finer once it has kept up REFINE_AFTER_MS.
    let t = BLOCK_MS + SETTLE_MS;
    while (auto.update(sample(t)) === BUSY_BUDGET / 2) t += 500;
    expect(auto.budget).toBe(BUSY_BUDGET);
    expect(auto.reason).toBe('keeping up');
    expect(t).toBeLessThanOrEqual(BLOCK_MS + SETTLE_MS + REFINE_AFTER_MS + 500);
  });

  it('keeps a mesh under AUTO_ABOVE at full detail, unless the address names a start', () => {
    const small = new AutoDetail(AUTO_ABOVE - 1, 1000);
    expect(small.budget).toBe(AUTO_ABOVE - 1);
    small.levelShown(0);
    expect(small.update(sample(10_000, { appliedPerSecond: 1, drawnPerSecond: 1 }))).toBe(AUTO_ABOVE - 1);
    const started = new AutoDetail(10_242, 204, 2048);
    expect(started.budget).toBe(2048);
    expect(started.update(sample(100, { lastArrivalAt: null }))).toBe(10_242);  // nothing streams: full
    expect(started.update(sample(200))).toBe(2048);
  });
});
