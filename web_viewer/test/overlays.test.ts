// The overlays' pure parts: the stretch of a triangle, the regions and the cut for drawing,
// the GetOverlays polling rhythm and the one-call-in-flight sender.
import { create } from '@bufbuild/protobuf';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';

import { OverlaysSchema, type Overlays } from '../src/gen/filigree/v1/filigree_pb';
import { LatestSender } from '../src/latest-sender';
import { MIN_INTERVAL_MS, OverlayFeed } from '../src/overlay-feed';
import { colourRegions, cutForDrawing, edgeSet, PALETTE, regionBoundaryEdges, regionVertexColours } from '../src/overlay-build';
import { l2Stretch, STRETCH_RED, stretchColor, TriangleStretch } from '../src/stretch';

// One triangle, not in a coordinate plane, so that the 3-D layout matters.
const REST = [0.2, -0.1, 0.3, 1.4, 0.2, -0.2, 0.1, 0.9, 0.8];
const FACE = [0, 1, 2];

function stretchOf(current: number[]): { l2: number; sv: [number, number] } {
  const stretch = new TriangleStretch(REST, FACE);
  const out = new Float32Array(1);
  stretch.l2(current, out);
  return { l2: out[0], sv: stretch.singularValues(current, 0) };
}

// A rotation about an axis, then a translation: a rigid motion.
function rigid(points: number[]): number[] {
  const [c, s] = [Math.cos(0.7), Math.sin(0.7)];
  const out = [];
  for (let i = 0; i < points.length; i += 3) {
    const [x, y, z] = points.slice(i, i + 3);
    out.push(c * x - s * z + 3, y - 2, s * x + c * z + 0.5);
  }
  return out;
}

describe('triangle stretch', () => {
  it('is 1 for the rest shape and any rigid motion of it', () => {
    for (const current of [REST, rigid(REST)]) {
      const { l2, sv } = stretchOf(current);
      expect(l2).toBeCloseTo(1, 5);
      expect(sv[0]).toBeCloseTo(1, 5);
      expect(sv[1]).toBeCloseTo(1, 5);
    }
  });

  it('is s for a uniform scale by s', () => {
    for (const s of [0.5, 2, 3.25]) {
      const { l2, sv } = stretchOf(rigid(REST.map((v) => s * v)));
      expect(l2).toBeCloseTo(s, 5);
      expect(sv).toEqual([expect.closeTo(s, 5), expect.closeTo(s, 5)]);
    }
  });

  it('gives a shear its singular values', () => {
    // x += k·y on the unit right triangle: J = [[1, k], [0, 1]], Γ·γ = 1 and
    // Γ² + γ² = 2 + k², so Γ = (k + √(k² + 4)) / 2 and L2 = √(1 + k²/2).
    const k = 0.8;
    const stretch = new TriangleStretch([0, 0, 0, 1, 0, 0, 0, 1, 0], FACE);
    const [big, small] = stretch.singularValues([0, 0, 0, 1, 0, 0, k, 1, 0], 0);
    expect(big).toBeCloseTo((k + Math.sqrt(k * k + 4)) / 2, 6);
    expect(small).toBeCloseTo(1 / big, 6);
    const out = new Float32Array(1);
    stretch.l2([0, 0, 0, 1, 0, 0, k, 1, 0], out);
    expect(out[0]).toBeCloseTo(Math.sqrt(1 + k * k / 2), 6);
    expect(out[0]).toBeCloseTo(l2Stretch(big, small), 6);
  });

  it('treats a degenerate rest triangle as unstretched', () => {
    const stretch = new TriangleStretch([0, 0, 0, 1, 0, 0, 2, 0, 0], FACE);
    const out = new Float32Array(1);
    stretch.l2([0, 0, 0, 1, 0, 0, 0, 5, 0], out);
    expect(out[0]).toBe(1);
  });

  it('colours |L2 − 1| from blue to red', () => {
    const near = (c: number[]) => c.map((v) => expect.closeTo(v, 6));
    const [blue, red] = [stretchColor(1), stretchColor(1 + STRETCH_RED)];
    expect(blue[2]).toBeGreaterThan(blue[0]);
    expect(red[0]).toBeGreaterThan(red[2]);
    expect(stretchColor(1 - STRETCH_RED)).toEqual(near(red));  // shrinking is as bad as stretching
    expect(stretchColor(10)).toEqual(near(red));               // clamped
    const half = stretchColor(1 + STRETCH_RED / 2);
    for (let k = 0; k < 3; ++k) expect(half[k]).toBeCloseTo((blue[k] + red[k]) / 2, 6);
  });
});

describe('regions for drawing', () => {
  // Two triangles per region, in a strip: regions 1-2-3 each touch the next;
  // vertex 0 is a cut vertex.
  const faces = [0, 1, 2, 1, 2, 3, 2, 3, 4, 3, 4, 5, 4, 5, 6, 5, 6, 7];
  const regionOf = [0, 1, 1, 2, 2, 3, 3, 3];

  it('colours neighbouring regions differently from a bounded palette', () => {
    const colour = colourRegions(regionOf, faces);
    expect(colour[1]).not.toBe(colour[2]);
    expect(colour[2]).not.toBe(colour[3]);
    // Thousands of regions still use only the palette.
    const many = Array.from({ length: 3000 }, (_, v) => 1 + Math.floor(v / 2));
    const strip = Array.from({ length: 3 * 2998 }, (_, k) => Math.floor(k / 3) + (k % 3));
    const colours = colourRegions(many, strip);
    expect(Math.max(...colours)).toBeLessThan(PALETTE.length);
    for (let f = 0; f < strip.length; f += 3) {
      const [a, b] = [many[strip[f]], many[strip[f + 2]]];
      if (a !== b) expect(colours[a]).not.toBe(colours[b]);
    }
  });

  it('paints cut vertices grey and each region its palette colour', () => {
    const out = new Float32Array(3 * regionOf.length);
    const colour = colourRegions(regionOf, faces);
    regionVertexColours(regionOf, colour, out);
    expect(out[0]).toBe(out[1]);  // grey: r = g = b
    expect(out[1]).toBe(out[2]);
    expect(Array.from(out.subarray(3, 6))).toEqual(Array.from(out.subarray(6, 9)));  // one region, one colour
  });

  it('outlines where regions meet: edges whose ends are in two different regions, each once', () => {
    const edges = Array.from(regionBoundaryEdges(regionOf, faces));
    const pairs = [];
    for (let k = 0; k < edges.length; k += 2) pairs.push([edges[k], edges[k + 1]].sort((a, b) => a - b).join('-'));
    expect(pairs.sort()).toEqual(['1-3', '2-3', '2-4', '3-5', '4-5', '4-6']);  // not 0-1, 0-2: vertex 0 is a cut vertex
  });
});

describe('the cut for drawing', () => {
  it('draws coarse triangles as their non-mesh edges and tints refined triangles', () => {
    // The detailed mesh: a fan of 4 triangles around vertex 4 in the square 0-1-2-3.
    const mesh = [0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4];
    const fine = edgeSet(mesh, 5);
    // A cut: two detailed triangles kept, the other half as one coarse triangle 2-3-0.
    const cut = cutForDrawing([0, 1, 4, 1, 2, 4, 2, 3, 0], fine, 5);
    expect(cut.refinedTriangles).toBe(2);
    expect(Array.from(cut.refined)).toEqual([1, 1, 1, 0, 1]);
    const edges = Array.from(cut.coarse);
    expect(edges.length).toBe(2);  // 0-2 only: 2-3 and 3-0 are mesh edges
    expect(edges.sort()).toEqual([0, 2]);
  });
});

describe('OverlayFeed', () => {
  beforeEach(() => { vi.useFakeTimers(); });
  afterEach(() => { vi.useRealTimers(); });

  const overlays = (version: number, ready = true) =>
    create(OverlaysSchema, { ready, version: BigInt(version), regionCount: version });

  it('asks once per frame while wanted, at most every MIN_INTERVAL_MS, and hands on ready answers', async () => {
    let now = 0;
    const answers: Overlays[] = [overlays(1, false), overlays(2), overlays(3)];
    const fetch = vi.fn(async () => answers.shift()!);
    const got: number[] = [];
    const feed = new OverlayFeed(fetch, (o) => got.push(Number(o.version)), (e) => { throw e; }, () => now);

    feed.frameArrived();
    await vi.runAllTimersAsync();
    expect(fetch).not.toHaveBeenCalled();  // nobody shows a server overlay

    feed.setWanted(true);                   // asks at once: not ready yet
    await vi.runAllTimersAsync();
    expect(fetch).toHaveBeenCalledTimes(1);
    expect(got).toEqual([]);

    now = 50;
    feed.frameArrived();                    // the frame the ask brought: too soon, waits for the interval
    feed.frameArrived();                    // frames in between are one ask
    await vi.advanceTimersByTimeAsync(0);
    expect(fetch).toHaveBeenCalledTimes(1);
    now = MIN_INTERVAL_MS;
    await vi.runAllTimersAsync();
    expect(fetch).toHaveBeenCalledTimes(2);
    expect(got).toEqual([2]);

    await vi.runAllTimersAsync();
    expect(fetch).toHaveBeenCalledTimes(2); // no frame, no ask

    feed.setWanted(false);
    now = 10_000;
    feed.frameArrived();
    await vi.runAllTimersAsync();
    expect(fetch).toHaveBeenCalledTimes(2);
  });
});

describe('LatestSender', () => {
  it('keeps one call in flight and sends the newest value when it ends', async () => {
    const sent: number[] = [];
    const finish: (() => void)[] = [];
    const sender = new LatestSender<number>((v) => {
      sent.push(v);
      return new Promise((done) => finish.push(done));
    });
    sender.push(1);
    sender.push(2);
    sender.push(3);
    expect(sent).toEqual([1]);
    finish.shift()!();
    await vi.waitFor(() => expect(sent).toEqual([1, 3]));
    expect(sender.idle).toBe(false);
    finish.shift()!();
    await vi.waitFor(() => expect(sender.idle).toBe(true));
    expect(sent).toEqual([1, 3]);
  });
});
