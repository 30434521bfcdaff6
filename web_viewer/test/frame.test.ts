import draco3d from 'draco3d';
import { beforeAll, describe, expect, it } from 'vitest';

import { applyDeltas, decodeDeltas, FrameError, type DracoDecoderModule } from '../src/frame';
import { encodeDeltas, KD_TREE, quantizationBound } from './encode';

let draco: DracoDecoderModule;
beforeAll(async () => {
  draco = (await draco3d.createDecoderModule({})) as DracoDecoderModule;
});

// Deltas that differ per vertex (a twist and a lift), so that a decoder that
// reordered points would fail vertex by vertex.
function twist(count: number): Float32Array {
  const d = new Float32Array(3 * count);
  for (let i = 0; i < count; ++i) {
    const a = (i / count) * 2 * Math.PI;
    d[3 * i] = 0.05 * Math.cos(a) - 0.01;
    d[3 * i + 1] = 0.1 * (i / count);
    d[3 * i + 2] = -0.03 * Math.sin(3 * a);
  }
  return d;
}

function worstError(a: Float32Array, b: Float32Array): number {
  let worst = 0;
  for (let i = 0; i < a.length; ++i) worst = Math.max(worst, Math.abs(a[i] - b[i]));
  return worst;
}

describe('decodeDeltas', () => {
  it('decodes a sequential point cloud vertex by vertex within the quantization bound', async () => {
    const exact = twist(1839);
    for (const bits of [8, 14, 20]) {
      const decoded = decodeDeltas(draco, await encodeDeltas(exact, bits), 1839);
      expect(decoded).toBeInstanceOf(Float32Array);
      expect(decoded.length).toBe(3 * 1839);
      expect(worstError(decoded, exact)).toBeLessThanOrEqual(quantizationBound(exact, bits));
    }
  });

  it('decodes an empty buffer as all zeros', () => {
    const decoded = decodeDeltas(draco, new Uint8Array(0), 5);
    expect(Array.from(decoded)).toEqual(new Array(15).fill(0));
  });

  it('reads a buffer that is a view into a larger one', async () => {
    const exact = twist(100);
    const bytes = await encodeDeltas(exact, 16);
    const padded = new Uint8Array(bytes.length + 7);
    padded.set(bytes, 3);
    const decoded = decodeDeltas(draco, padded.subarray(3, 3 + bytes.length), 100);
    expect(worstError(decoded, exact)).toBeLessThanOrEqual(quantizationBound(exact, 16));
  });

  it('refuses a vertex count that does not match the frame', async () => {
    const bytes = await encodeDeltas(twist(10), 12);
    expect(() => decodeDeltas(draco, bytes, 11)).toThrow(/10 points for 11 vertices/);
  });

  it('refuses a kd-tree encoded cloud, whose points are reordered', async () => {
    const bytes = await encodeDeltas(twist(50), 12, KD_TREE);
    expect(() => decodeDeltas(draco, bytes, 50)).toThrow(/encoding method 1, not sequential/);
  });

  it('refuses bytes that are not Draco, and a truncated buffer', async () => {
    expect(() => decodeDeltas(draco, new TextEncoder().encode('not a draco frame'), 3)).toThrow(FrameError);
    const bytes = await encodeDeltas(twist(200), 14);
    expect(() => decodeDeltas(draco, bytes.subarray(0, 20), 200)).toThrow(FrameError);
  });
});

describe('applyDeltas', () => {
  it('writes rest + delta into the live positions, in place', () => {
    const rest = Float32Array.from([0, 1, 2, 3, 4, 5]);
    const deltas = Float32Array.from([0.5, -1, 0, 0.25, 0, -5]);
    const positions = new Float32Array(6);
    const same = positions;
    applyDeltas(rest, deltas, positions);
    expect(positions).toBe(same);
    expect(Array.from(positions)).toEqual([0.5, 0, 2, 3.25, 4, 0]);
    expect(Array.from(rest)).toEqual([0, 1, 2, 3, 4, 5]);
  });

  it('replaces the previous frame rather than accumulating', () => {
    const rest = Float32Array.from([1, 1, 1]);
    const positions = rest.slice();
    applyDeltas(rest, Float32Array.from([1, 2, 3]), positions);
    applyDeltas(rest, Float32Array.from([0, 0, -1]), positions);
    expect(Array.from(positions)).toEqual([1, 1, 0]);
  });

  it('refuses deltas for another vertex count', () => {
    expect(() => applyDeltas(new Float32Array(6), new Float32Array(9), new Float32Array(6))).toThrow(FrameError);
  });
});
