// The pure parts of the page: address parsing, statistics, change lines and
// the base-mesh overlay's geometry.
import { create } from '@bufbuild/protobuf';
import { describe, expect, it } from 'vitest';

import { changeLines } from '../src/changes';
import { FrameSchema, FrameStatsSchema } from '../src/gen/filigree/v1/filigree_pb';
import { gatherVertices, uniqueEdges } from '../src/overlays';
import { readParams, tokenOutOfQuery } from '../src/params';
import { StatsTracker, statsRows } from '../src/stats';

const frame = (version: number, extra: object = {}) =>
  create(FrameSchema, { version: BigInt(version), vertexCount: 4, deltas: new Uint8Array(10), ...extra });

describe('readParams', () => {
  const origin = 'http://127.0.0.1:8080';
  it('reads session and token, with the page origin as the default server', () => {
    expect(readParams('?session=abc&token=t1', origin)).toEqual({
      kind: 'ok', params: { sessionId: 'abc', token: 't1', serverUrl: 'http://127.0.0.1:8080' },
    });
  });
  it('takes another server, without a trailing slash', () => {
    const r = readParams('?session=abc&token=t1&server=http://10.0.0.2:9000/', origin);
    expect(r.kind === 'ok' && r.params.serverUrl).toBe('http://10.0.0.2:9000');
  });
  it('asks for usage without a session, and says what is missing otherwise', () => {
    expect(readParams('', origin)).toEqual({ kind: 'usage' });
    expect(readParams('?session=abc', origin)).toMatchObject({ kind: 'error', message: expect.stringMatching(/token/) });
    expect(readParams('?session=a&token=t&server=ftp://x', origin)).toMatchObject({ kind: 'error' });
  });
});

describe('tokens in the fragment', () => {
  const origin = 'http://127.0.0.1:8080';
  it('reads the token from the fragment, preferring it to the query', () => {
    expect(readParams('?session=abc', origin, '#token=t2')).toMatchObject({ kind: 'ok', params: { token: 't2' } });
    expect(readParams('?session=abc&token=t1', origin, '#token=t2')).toMatchObject({ kind: 'ok', params: { token: 't2' } });
    expect(readParams('', origin, '#session=abc&token=t3')).toMatchObject({ kind: 'ok', params: { sessionId: 'abc', token: 't3' } });
  });

  it('moves a token from the query into the fragment', () => {
    expect(tokenOutOfQuery('http://h:1/?session=abc&token=t1')).toBe('http://h:1/?session=abc#token=t1');
    expect(tokenOutOfQuery('http://h:1/?session=abc&token=t1#token=t2')).toBe('http://h:1/?session=abc#token=t2');
    expect(tokenOutOfQuery('http://h:1/?session=abc#token=t2')).toBeNull();
  });
});

describe('StatsTracker: what was drawn', () => {
  const times = { decodeMs: 1, applyMs: 1, normalsMs: 1, stretchMs: 0 };
  it('counts frames arrived, applied and drawn apart, and how far the drawing is behind', () => {
    const stats = new StatsTracker();
    for (let v = 1; v <= 6; ++v) stats.frameArrived(frame(v), 1000 + 10 * v);
    stats.frameApplied(times, 0.5, 1070);
    stats.frameDrawn(3n, 4, 1075);
    stats.frameDrawn(3n, 4, 1080);  // a redraw of the same version (an orbit): not a frame drawn
    const s = stats.snapshot(1100);
    expect(s.framesPerSecond).toBe(3);
    expect(s.appliedPerSecond).toBe(0.5);
    expect(s.drawnPerSecond).toBe(0.5);
    expect(s.behind).toBe(3);
    expect(s.drawMs).toBe(4);
    expect(s.pageMs).toBe(0.5);
    const rows = Object.fromEntries(statsRows(s));
    expect(rows['frames/s']).toBe('3.0 arrived, 0.5 applied, 0.5 drawn');
    expect(rows['behind by']).toBe('3 versions');
  });

  it('times own edits to the frame that includes them being drawn, several in flight', () => {
    const stats = new StatsTracker();
    const first = stats.poseSent(100);
    const second = stats.poseSent(110);
    first(5n);
    second(6n);
    stats.frameDrawn(6n, 1, 150);  // includes the first edit only
    expect(stats.snapshot(150).editToDrawnMs).toBe(50);
    stats.frameDrawn(7n, 1, 190);
    expect(stats.snapshot(190).editToDrawnMs).toBe(80);
  });
});

describe('StatsTracker', () => {
  it('measures the rate and the arrival interval', () => {
    const stats = new StatsTracker();
    stats.frameArrived(frame(1), 1000);
    stats.frameArrived(frame(2), 1040);
    stats.frameArrived(frame(3), 1060);
    const s = stats.snapshot(1100);
    expect(s.framesPerSecond).toBe(1.5);  // 3 frames in a 2 s window
    expect(s.lastIntervalMs).toBe(20);
    expect(s.meanIntervalMs).toBe(30);
    expect(s.bytesPerFrame).toBe(10);
    expect(s.bytesPerVertex).toBe(2.5);
    expect(stats.snapshot(10_000).framesPerSecond).toBe(0);
  });

  it('takes the mean interval over the window once older arrivals left it', () => {
    const stats = new StatsTracker();
    for (let t = 0; t <= 3000; t += 100) stats.frameArrived(frame(1 + t / 100), t);
    // At 3050 the window holds 1100…3000 (those before were trimmed, in place, by the rate).
    expect(stats.snapshot(3050).meanIntervalMs).toBe(100);
  });

  it('times an own pose to the first frame with a larger version than it was accepted at', () => {
    const stats = new StatsTracker();
    const accepted = stats.poseSent(100);
    stats.frameArrived(frame(7), 110);  // computed before the pose was merged
    accepted(7n);
    expect(stats.snapshot(120).roundTripMs).toBeNull();
    stats.frameArrived(frame(8), 135);
    expect(stats.snapshot(140).roundTripMs).toBe(35);
  });

  it('times a frame that overtook the SubmitPose answer', () => {
    const stats = new StatsTracker();
    const accepted = stats.poseSent(0);
    stats.frameArrived(frame(4), 12);
    accepted(3n);
    expect(stats.snapshot(20).roundTripMs).toBe(12);
  });

  it('shows T = ∞ for whole-mesh optimisation and the server stage times', () => {
    const stats = new StatsTracker();
    stats.frameArrived(frame(1, { stats: create(FrameStatsSchema, { threshold: Infinity, regions: 1, computeMs: 3.25 }) }), 0);
    const rows = Object.fromEntries(statsRows(stats.snapshot(0)));
    expect(rows['T']).toBe('∞ (whole mesh)');
    expect(rows['regions']).toMatch(/^1 /);
    expect(rows['server compute']).toMatch(/^3\.3 ms/);
    expect(rows['version']).toBe('1');
  });
});

describe('changeLines', () => {
  it('names each client, its pose and the base vertices it moved', () => {
    const f = frame(9, { changes: [{ clientName: 'blender-alice', poseId: 42n, vertexCount: 150 }, { poseId: 1n, vertexCount: 1 }] });
    expect(changeLines(f)).toEqual([
      { version: 9n, text: 'blender-alice: pose 42, 150 base vertices' },
      { version: 9n, text: '(unnamed client): pose 1, 1 base vertex' },
    ]);
  });

  it('tells handle edits (no pose) apart', () => {
    const f = frame(3, { changes: [{ clientName: 'web-1a2b3c', vertexCount: 2 }, { clientName: 'web-4d5e6f', vertexCount: 0 }] });
    expect(changeLines(f).map((l) => l.text)).toEqual(['web-1a2b3c: moved handles', 'web-4d5e6f: cleared its handles']);
  });
});

describe('base wireframe geometry', () => {
  it('lists each edge of the triangles once', () => {
    // Two triangles sharing the edge 1–2.
    const edges = uniqueEdges([0, 1, 2, 2, 1, 3]);
    const pairs = [];
    for (let i = 0; i < edges.length; i += 2) pairs.push(`${edges[i]}-${edges[i + 1]}`);
    expect(pairs.sort()).toEqual(['0-1', '0-2', '1-2', '1-3', '2-3']);
  });

  it('reads the base vertices out of the detailed positions by original id', () => {
    const positions = Float32Array.from([0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3]);
    const out = new Float32Array(6);
    gatherVertices(positions, [3, 1], out);
    expect(Array.from(out)).toEqual([3, 3, 3, 1, 1, 1]);
  });
});
