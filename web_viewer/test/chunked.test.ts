// FRAME_FORMAT_CHUNKED: chunks encoded here the way the server encodes them
// (draco3d's encoder: sequential, explicit quantization), decoded and applied
// by src/frame.ts (KeyedDeltas), and the page's mailbox and worker shares.
import { create } from '@bufbuild/protobuf';
import draco3d from 'draco3d';
import { beforeAll, describe, expect, it } from 'vitest';

import {
  applyDeltaRanges, applyDeltas, decodeAndApply, decodeDeltas, framesOfState, FrameError, isChunked, isKeyframe,
  KeyedDeltas, largestDelta, presentCounts, unionOfRanges, type ChunkedFrameData, type DeltaChunkData,
  type DracoDecoderModule,
} from '../src/frame';
import { DeltaChunkSchema, FrameSchema } from '../src/gen/filigree/v1/filigree_pb';
import { FrameMailbox } from '../src/mailbox';
import { encodeChunks, encodeDeltas, quantizationBound, runsOf, type EncodedChunk } from './encode';

let draco: DracoDecoderModule;
beforeAll(async () => {
  draco = (await draco3d.createDecoderModule({})) as DracoDecoderModule;
});

const N = 1839;     // bunny_small's vertex count
const CHUNK = 500;  // four ranges: 0+500, 500+500, 1000+500, 1500+339
const BITS = 14;

// Deltas that differ per vertex (as in frame.test.ts), scaled, so that a
// vertex taken from the wrong place or frame shows.
function twist(count: number, scale = 1): Float32Array {
  const d = new Float32Array(3 * count);
  for (let i = 0; i < count; ++i) {
    const a = (i / count) * 2 * Math.PI;
    d[3 * i] = scale * (0.05 * Math.cos(a) - 0.01);
    d[3 * i + 1] = scale * 0.1 * (i / count);
    d[3 * i + 2] = scale * -0.03 * Math.sin(3 * a);
  }
  return d;
}

// `base` with the vertices `moved` names displaced (a new frame's exact deltas).
function moveSome(base: Float32Array, moved: (v: number) => boolean): Float32Array {
  const d = base.slice();
  for (let v = 0; v < d.length / 3; ++v) {
    if (moved(v)) { d[3 * v] += 0.02; d[3 * v + 1] -= 0.01 * (v % 7); d[3 * v + 2] += 0.005; }
  }
  return d;
}

function worstError(a: Float32Array, b: Float32Array): number {
  let worst = 0;
  for (let i = 0; i < a.length; ++i) worst = Math.max(worst, Math.abs(a[i] - b[i]));
  return worst;
}

const frame = (version: number, keyframe: number, chunks: DeltaChunkData[], vertexCount = N): ChunkedFrameData =>
  ({ version: BigInt(version), keyframeVersion: BigInt(keyframe), vertexCount, chunks });

// A KeyedDeltas holding keyframe 5 of `deltas`.
async function holding(deltas: Float32Array): Promise<KeyedDeltas> {
  const keyed = new KeyedDeltas(N);
  decodeAndApply(draco, keyed, frame(5, 5, await encodeChunks(deltas, CHUNK, BITS)));
  return keyed;
}

describe('chunked keyframes', () => {
  it('decode to the deltas of a single buffer, within the quantization bound', async () => {
    const exact = twist(N);
    const single = decodeDeltas(draco, await encodeDeltas(exact, BITS), N);
    const chunks = await encodeChunks(exact, CHUNK, BITS);
    expect(chunks.map((c) => [c.firstVertex, c.vertexCount, c.runs.length])).toEqual(
      [[0, 500, 0], [500, 500, 0], [1000, 500, 0], [1500, 339, 0]]);
    const keyed = new KeyedDeltas(N);
    const changed = decodeAndApply(draco, keyed, frame(5, 5, chunks));
    expect(changed).toEqual([{ first: 0, count: N }]);
    expect(keyed.keyframeVersion).toBe(5n);
    // Each chunk is quantized over its own (smaller) range: within the whole frame's bound.
    const bound = quantizationBound(exact, BITS);
    expect(worstError(keyed.deltas, exact)).toBeLessThanOrEqual(bound);
    expect(worstError(keyed.deltas, single)).toBeLessThanOrEqual(2 * bound);
  });

  it('accept a generated Frame as it comes off the wire', async () => {
    const chunks = await encodeChunks(twist(N), CHUNK, BITS);
    const wire = create(FrameSchema, {
      version: 3n, keyframeVersion: 3n, vertexCount: N,
      chunks: chunks.map((c) => create(DeltaChunkSchema, { ...c, quantizationBits: BITS })),
    });
    expect(isChunked(wire)).toBe(true);
    expect(isKeyframe(wire)).toBe(true);
    const keyed = new KeyedDeltas(N);
    decodeAndApply(draco, keyed, wire);
    expect(keyed.keyframeVersion).toBe(3n);
  });

  it('read a chunk without bytes as zeros', async () => {
    const exact = twist(N);
    exact.fill(0, 3 * 500, 3 * 1000);
    const chunks = await encodeChunks(exact, CHUNK, BITS);
    expect(chunks[1].deltas.length).toBe(0);
    const keyed = new KeyedDeltas(N);
    decodeAndApply(draco, keyed, frame(5, 5, chunks));
    expect(keyed.deltas.subarray(3 * 500, 3 * 1000).every((v) => v === 0)).toBe(true);
    expect(worstError(keyed.deltas, exact)).toBeLessThanOrEqual(quantizationBound(exact, BITS));
  });

  it('replace the keyframe held, and what a sparse frame had written', async () => {
    const keyed = await holding(twist(N));
    const moved = (v: number) => v >= 600 && v < 650;
    decodeAndApply(draco, keyed, frame(6, 5, await encodeChunks(moveSome(twist(N), moved), CHUNK, BITS, moved)));
    const next = twist(N, -2);
    const changed = decodeAndApply(draco, keyed, frame(9, 9, await encodeChunks(next, CHUNK, BITS)));
    expect(changed).toEqual([{ first: 0, count: N }]);
    expect(keyed.keyframeVersion).toBe(9n);
    expect(worstError(keyed.deltas, next)).toBeLessThanOrEqual(quantizationBound(next, BITS));
  });
});

describe('sparse frames', () => {
  it('applied to their keyframe equal the full frame', async () => {
    const key = twist(N);
    const keyed = await holding(key);
    const keyframeDecoded = keyed.deltas.slice();
    // Present: a run inside chunk 0, one across the boundary of chunks 1 and 2, one vertex in chunk 3.
    const moved = (v: number) => (v >= 100 && v < 130) || (v >= 980 && v < 1020) || v === 1600;
    const full = moveSome(key, moved);
    const chunks = await encodeChunks(full, CHUNK, BITS, moved);
    expect(chunks.map((c) => [c.firstVertex, c.runs])).toEqual(
      [[0, [100, 30]], [500, [480, 20]], [1000, [0, 20]], [1500, [100, 1]]]);

    const positions = new Float32Array(3 * N);
    const rest = twist(N, 10);  // any rest positions
    applyDeltas(rest, keyed.deltas, positions);
    const changed = decodeAndApply(draco, keyed, frame(6, 5, chunks));
    expect(keyed.keyframeVersion).toBe(5n);
    expect(worstError(keyed.deltas, full)).toBeLessThanOrEqual(quantizationBound(full, BITS));
    for (let v = 0; v < N; ++v) {
      if (moved(v)) continue;  // the others are the keyframe's, bit for bit
      for (let k = 0; k < 3; ++k) expect(keyed.deltas[3 * v + k]).toBe(keyframeDecoded[3 * v + k]);
    }
    // The live positions follow by rewriting the chunks' ranges only.
    expect(changed).toEqual([{ first: 0, count: N }]);  // the four chunk ranges, merged
    applyDeltaRanges(rest, keyed.deltas, positions, changed);
    const expected = new Float32Array(3 * N);
    applyDeltas(rest, keyed.deltas, expected);
    expect(positions).toEqual(expected);
  });

  it('after another sparse frame restore the vertices the first one changed, and only their ranges', async () => {
    const key = twist(N);
    const keyed = await holding(key);
    const keyframeDecoded = keyed.deltas.slice();
    const rest = twist(N, 10);
    const positions = new Float32Array(3 * N);
    applyDeltas(rest, keyed.deltas, positions);

    const first = (v: number) => v >= 40 && v < 90;     // chunk 0
    const second = (v: number) => v >= 1100 && v < 1120;  // chunk 2
    const changed1 = decodeAndApply(draco, keyed, frame(6, 5, await encodeChunks(moveSome(key, first), CHUNK, BITS, first)));
    expect(changed1).toEqual([{ first: 0, count: 500 }]);
    applyDeltaRanges(rest, keyed.deltas, positions, changed1);
    expect(keyed.deltas[3 * 50]).not.toBe(keyframeDecoded[3 * 50]);

    const full2 = moveSome(key, second);
    const changed2 = decodeAndApply(draco, keyed, frame(7, 5, await encodeChunks(full2, CHUNK, BITS, second)));
    // Chunk 0 restored, chunk 2 written; chunks 1 and 3 untouched.
    expect(changed2).toEqual([{ first: 0, count: 500 }, { first: 1000, count: 500 }]);
    applyDeltaRanges(rest, keyed.deltas, positions, changed2);
    for (let v = 0; v < N; ++v) {
      if (second(v)) continue;
      for (let k = 0; k < 3; ++k) expect(keyed.deltas[3 * v + k]).toBe(keyframeDecoded[3 * v + k]);
    }
    expect(worstError(keyed.deltas, full2)).toBeLessThanOrEqual(quantizationBound(full2, BITS));
    const expected = new Float32Array(3 * N);
    applyDeltas(rest, keyed.deltas, expected);
    expect(positions).toEqual(expected);

    // A sparse frame with no chunks (nothing moved from the keyframe) is the keyframe.
    const changed3 = decodeAndApply(draco, keyed, frame(8, 5, []));
    expect(changed3).toEqual([{ first: 1000, count: 500 }]);
    expect(keyed.deltas).toEqual(keyframeDecoded);
  });

  it('relative to a keyframe other than the one held are refused, changing nothing', async () => {
    const key = twist(N);
    const keyed = await holding(key);
    const before = keyed.deltas.slice();
    const moved = (v: number) => v < 10;
    const chunks = await encodeChunks(moveSome(key, moved), CHUNK, BITS, moved);
    expect(() => decodeAndApply(draco, keyed, frame(8, 7, chunks)))
      .toThrow(new FrameError('the frame is relative to keyframe 7, but the keyframe held is 5'));
    expect(keyed.deltas).toEqual(before);
    expect(keyed.keyframeVersion).toBe(5n);
    // Before any keyframe only keyframe 0, the rest mesh, is held.
    expect(() => decodeAndApply(draco, new KeyedDeltas(N), frame(8, 7, chunks))).toThrow(/keyframe held is 0/);
  });
});

describe('malformed chunked frames', () => {
  let valid: EncodedChunk[];
  let keyed: KeyedDeltas;
  let before: Float32Array;
  beforeAll(async () => {
    keyed = await holding(twist(N));
    before = keyed.deltas.slice();
    const moved = (v: number) => v % 3 === 0;
    valid = await encodeChunks(moveSome(twist(N), moved), CHUNK, BITS, moved);
  });
  const refused = (chunks: DeltaChunkData[], message: RegExp, version = 6, keyframe = 5, vertexCount = N) => {
    expect(() => decodeAndApply(draco, keyed, frame(version, keyframe, chunks, vertexCount))).toThrow(FrameError);
    expect(() => decodeAndApply(draco, keyed, frame(version, keyframe, chunks, vertexCount))).toThrow(message);
    expect(keyed.deltas).toEqual(before);
    expect(keyed.keyframeVersion).toBe(5n);
  };

  it('refuses runs past their range, and an odd number of runs', () => {
    refused([{ ...valid[0], runs: [400, 50, 40, 20] }], /chunk 0 \(vertices 0\+500\) has runs covering 510 vertices/);
    refused([{ ...valid[0], runs: [1, 2, 3] }], /chunk 0 .* odd number of runs/);
  });

  it('refuses ranges out of the mesh, overlapping or out of order', () => {
    refused([{ ...valid[3], vertexCount: 340 }], /chunk 0 \(vertices 1500\+340\) reaches past the mesh's 1839 vertices/);
    refused([valid[0], { ...valid[1], firstVertex: 499 }], /chunk 1 \(vertices 499\+500\) overlaps or precedes/);
    refused([valid[1], valid[0]], /chunk 1 \(vertices 0\+500\) overlaps or precedes/);
  });

  it('refuses a buffer whose points are not the present vertices', () => {
    // Chunk 1's buffer holds 167 points (every third vertex of 500..999); runs naming 166 or 168 do not fit.
    const runs = valid[1].runs;
    expect(presentCounts([valid[1]], N)).toEqual([167]);
    refused([{ ...valid[1], runs: runs.slice(0, -2) }], /chunk 0 \(vertices 500\+500\) has 167 points for 166 vertices/);
    refused([{ ...valid[1], runs: [] }], /has 167 points for 500 vertices/);
  });

  it('refuses a keyframe that does not list every vertex in whole chunks', async () => {
    const whole = await encodeChunks(twist(N), CHUNK, BITS);
    refused(whole.slice(1), /keyframe 9 does not list every one of the 1839 vertices/, 9, 9);
    refused([...whole.slice(0, 3), { ...whole[3], runs: [0, 339] }], /keyframe 9 does not list every/, 9, 9);
  });

  it('refuses a frame of another vertex count, and bytes that are not Draco', () => {
    refused(valid, /a frame of 1840 vertices for a mesh of 1839/, 6, 5, 1840);
    refused([{ ...valid[0], deltas: new TextEncoder().encode('not a draco chunk') }],
      /the deltas of chunk 0 \(vertices 0\+500\) are not a Draco buffer/);
  });

  it('refuses decoded values that do not fit the runs', () => {
    expect(() => keyed.apply(frame(6, 5, [valid[0]]), [new Float32Array(3)]))
      .toThrow(/has 167 present vertices, and 1 were decoded/);
    expect(() => keyed.apply(frame(6, 5, [valid[0]]), [])).toThrow(/0 decoded chunks for a frame of 1/);
    expect(keyed.deltas).toEqual(before);
  });
});

describe('chunked frame helpers', () => {
  it('tells chunked frames from single ones', () => {
    expect(isChunked(create(FrameSchema, { version: 4n, deltas: new Uint8Array(10) }))).toBe(false);
    // Nothing moved since keyframe 3: no chunks, and chunked all the same.
    expect(isChunked(create(FrameSchema, { version: 4n, keyframeVersion: 3n }))).toBe(true);
    expect(isKeyframe(create(FrameSchema, { version: 4n, keyframeVersion: 3n }))).toBe(false);
  });

  it('lists a state\'s keyframe before its frame', () => {
    const key = create(FrameSchema, { version: 3n, keyframeVersion: 3n });
    const sparse = create(FrameSchema, { version: 4n, keyframeVersion: 3n });
    expect(framesOfState({ frame: sparse, keyframe: key })).toEqual([key, sparse]);
    expect(framesOfState({ frame: key })).toEqual([key]);
    expect(framesOfState({ frame: key, keyframe: null })).toEqual([key]);  // grpc-js with defaults
  });

  it('writes runs of present vertices', () => {
    expect(runsOf([true, true])).toEqual([]);
    expect(runsOf([false, true, true, false, false, true, false])).toEqual([1, 2, 2, 1]);
    expect(runsOf([true, false])).toEqual([0, 1]);
  });

  it('merges vertex ranges', () => {
    const a = [{ first: 0, count: 10 }, { first: 30, count: 5 }];
    const b = [{ first: 10, count: 5 }, { first: 32, count: 10 }];
    expect(unionOfRanges(a, b)).toEqual([{ first: 0, count: 15 }, { first: 30, count: 12 }]);
    expect(unionOfRanges([], [{ first: 4, count: 2 }])).toEqual([{ first: 4, count: 2 }]);
  });

  it('measures the largest delta', () => {
    expect(largestDelta(Float32Array.from([0.5, -2, 1]))).toBe(2);
    expect(largestDelta(new Float32Array(0))).toBe(0);
  });
});

describe('FrameMailbox', () => {
  type F = { v: number; key: boolean };
  const mailbox = () => new FrameMailbox<F>((f) => f.key);
  const drain = (m: FrameMailbox<F>) => {
    const out: number[] = [];
    for (let f = m.take(); f !== null; f = m.take()) out.push(f.v);
    return out;
  };

  it('keeps the newest frame, and a keyframe until it is taken', () => {
    const m = mailbox();
    expect(m.put({ v: 1, key: false })).toBe(0);
    expect(m.put({ v: 2, key: true })).toBe(1);   // supersedes frame 1
    expect(m.put({ v: 3, key: false })).toBe(0);  // keyframe 2 stays
    expect(m.put({ v: 4, key: false })).toBe(1);  // supersedes frame 3
    expect(m.hasKeyframe).toBe(true);
    expect(drain(m)).toEqual([2, 4]);
  });

  it('drops an older keyframe for a newer one', () => {
    const m = mailbox();
    m.put({ v: 2, key: true });
    m.put({ v: 3, key: false });
    expect(m.put({ v: 5, key: true })).toBe(2);
    expect(drain(m)).toEqual([5]);
    m.put({ v: 6, key: false });
    m.clear();
    expect(m.take()).toBeNull();
  });
});
