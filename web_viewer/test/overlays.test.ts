// The overlays' pure parts: the stretch of a triangle, the region colours,
// the GetOverlays polling rhythm and the one-call-in-flight sender.
import { create } from '@bufbuild/protobuf';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';

import { OverlaysSchema, type Overlays } from '../src/gen/filigree/v1/filigree_pb';
import { LatestSender } from '../src/latest-sender';
import { MIN_INTERVAL_MS, OverlayFeed } from '../src/overlay-feed';
import { CUT_GREY, regionColor, regionColors } from '../src/overlay-regions';
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

describe('region colours', () => {
  it('paints cut vertices neutral grey', () => {
    expect(regionColor(0)).toEqual(CUT_GREY);
    const [r, g, b] = CUT_GREY;
    expect(r).toBe(g);
    expect(g).toBe(b);
  });

  it('gives each region its own, saturated colour, the same every time', () => {
    const colours = Array.from({ length: 40 }, (_, r) => regionColor(r + 1));
    expect(Array.from({ length: 40 }, (_, r) => regionColor(r + 1))).toEqual(colours);
    for (const [r, g, b] of colours) expect(Math.max(r, g, b) - Math.min(r, g, b)).toBeGreaterThan(0.2);
    // Neighbouring numbers differ clearly.
    for (let i = 1; i < colours.length; ++i) {
      const distance = Math.hypot(...colours[i].map((c, k) => c - colours[i - 1][k]));
      expect(distance).toBeGreaterThan(0.2);
    }
  });

  it('fills a colour per vertex, equal labels equal colours', () => {
    const out = new Float32Array(12);
    regionColors([0, 3, 3, 0], out);
    expect(Array.from(out.subarray(3, 6))).toEqual(Array.from(out.subarray(6, 9)));
    expect(Array.from(out.subarray(0, 3))).toEqual(Array.from(out.subarray(9, 12)));
    expect(out[0]).toBe(out[1]);
    expect(Array.from(out.subarray(0, 3))).not.toEqual(Array.from(out.subarray(3, 6)));
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
