// The participants layer's pure parts: colours by name, when a frame calls
// for GetHandles, what an answer shows, and the asking (one call in flight,
// rate-limited, newest wins).
import { create } from '@bufbuild/protobuf';
import { Code, ConnectError } from '@connectrpc/connect';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';

import { FrameSchema, SessionHandlesSchema } from '../src/gen/filigree/v1/filigree_pb';
import {
  HandlesFeed, MIN_INTERVAL_MS, nameHash, namesOther, othersOf, PALETTE, participantColour, participantsKey, prefersDarkText,
} from '../src/participants';

const answer = (participants: [string, [number, number, number, number][]][], version = 1) =>
  create(SessionHandlesSchema, {
    version: BigInt(version),
    participants: participants.map(([clientName, handles]) => ({
      clientName, handles: handles.map(([vertex, x, y, z]) => ({ vertex, x, y, z })),
    })),
  });

describe('participant colours', () => {
  it('are FNV-1a of the name\'s UTF-8 bytes into the server\'s palette: the same on every page and on the server', () => {
    expect(nameHash('')).toBe(0x811c9dc5);
    expect(nameHash('a')).toBe(0xe40c292c);        // the FNV-1a test vectors
    expect(nameHash('foobar')).toBe(0xbf9cf968);
    expect(nameHash('Émilie')).toBe(0xc0ddaba7);   // UTF-8 bytes, as server/session_presence.cpp hashes them
    // What the server's participant_colour gives these names (computed apart).
    expect(participantColour('web-3fa9c1').css).toBe('#f58231');
    expect(participantColour('cli-bend').css).toBe('#9a6324');
    expect(participantColour('Émilie').css).toBe('#9a6324');
    for (const name of ['web-3fa9c1', 'cli-bend', 'Émilie']) {
      expect(participantColour(name)).toBe(PALETTE[nameHash(name) % PALETTE.length]);
    }
  });

  it('spread over the whole palette, with label text that reads on each', () => {
    const used = new Set(Array.from({ length: 200 }, (_, i) => participantColour(`web-${i.toString(16).padStart(6, '0')}`).css));
    expect(used.size).toBe(PALETTE.length);
    expect(PALETTE.map((p) => p.css)).toEqual(['#e6194b', '#3cb44b', '#4363d8', '#f58231', '#911eb4', '#bfef45', '#f032e6', '#9a6324']);
    expect(PALETTE.filter((p) => !p.darkText).map((p) => p.css)).toEqual(['#e6194b', '#4363d8', '#911eb4', '#9a6324']);
    expect(prefersDarkText('#ffffff')).toBe(true);
    expect(prefersDarkText('#000000')).toBe(false);
  });
});

describe('namesOther', () => {
  const frame = (...names: string[]) => create(FrameSchema, { changes: names.map((clientName) => ({ clientName })) });

  it('is true when a change names another client', () => {
    expect(namesOther(frame(), 'web-aaaaaa')).toBe(false);
    expect(namesOther(frame('web-aaaaaa'), 'web-aaaaaa')).toBe(false);
    expect(namesOther(frame('web-aaaaaa', 'web-bbbbbb'), 'web-aaaaaa')).toBe(true);
    expect(namesOther(frame('cli-bend'), 'web-aaaaaa')).toBe(true);
    expect(namesOther(frame(''), 'web-aaaaaa')).toBe(true);
  });
});

describe('othersOf', () => {
  it('leaves out this page and empty sets, sorts by name, colours each', () => {
    const shown = othersOf(answer([
      ['web-zzzzzz', [[4, 1, 2, 3]]],
      ['web-aaaaaa', [[1, 0, 0, 0]]],      // this page: drawn by handles.ts
      ['cli', []],
      ['web-bbbbbb', [[7, 0.5, 0, 0], [9, 0, 0.25, 0]]],
    ]), 'web-aaaaaa');
    expect(shown.map((p) => [p.name, p.handles.length])).toEqual([['web-bbbbbb', 2], ['web-zzzzzz', 1]]);
    expect(shown[1].handles).toEqual([{ vertex: 4, x: 1, y: 2, z: 3 }]);
    expect(shown[0].colour).toBe(participantColour('web-bbbbbb').css);
  });

  it('gives equal keys for equal answers only', () => {
    const key = (a: ReturnType<typeof answer>) => participantsKey(othersOf(a, 'me'));
    expect(key(answer([['b', [[1, 0, 0, 0]]], ['a', [[2, 1, 1, 1]]]], 5)))
      .toBe(key(answer([['a', [[2, 1, 1, 1]]], ['b', [[1, 0, 0, 0]]]], 6)));
    expect(key(answer([['a', [[2, 1, 1, 1]]]]))).not.toBe(key(answer([['a', [[2, 1, 1, 1.5]]]])));
    expect(key(answer([['a', [[2, 1, 1, 1]]]]))).not.toBe(key(answer([['b', [[2, 1, 1, 1]]]])));
    expect(key(answer([]))).toBe('');
  });
});

describe('HandlesFeed', () => {
  beforeEach(() => { vi.useFakeTimers(); });
  afterEach(() => { vi.useRealTimers(); });

  it('asks at once, one call in flight, at most every MIN_INTERVAL_MS, requests meanwhile making one more ask', async () => {
    let now = 0;
    const calls: ((value: number) => void)[] = [];
    const fetch = vi.fn(() => new Promise<number>((resolve) => { calls.push(resolve); }));
    const got: number[] = [];
    const feed = new HandlesFeed(fetch, (n) => got.push(n), (e) => { throw e; }, () => now);
    expect(feed.idle).toBe(true);

    feed.request();                  // on join: at once
    expect(fetch).toHaveBeenCalledTimes(1);
    feed.request();                  // frames while it runs: one more ask, after it
    feed.request();
    expect(fetch).toHaveBeenCalledTimes(1);
    expect(feed.idle).toBe(false);

    now = 100;
    calls[0](1);
    await vi.advanceTimersByTimeAsync(0);
    expect(got).toEqual([1]);
    expect(fetch).toHaveBeenCalledTimes(1);  // too soon after the first
    now = MIN_INTERVAL_MS;
    await vi.advanceTimersByTimeAsync(MIN_INTERVAL_MS);
    expect(fetch).toHaveBeenCalledTimes(2);
    calls[1](2);
    await vi.runAllTimersAsync();
    expect(got).toEqual([1, 2]);
    expect(fetch).toHaveBeenCalledTimes(2);  // nothing asked since: no call
    expect(feed.idle).toBe(true);

    now = 10_000;
    feed.request();                  // long after: at once
    expect(fetch).toHaveBeenCalledTimes(3);
    calls[2](3);
    await vi.runAllTimersAsync();
    expect(got).toEqual([1, 2, 3]);
  });

  it('goes on after an error, and stops for good when the server lacks the call', async () => {
    let now = 0;
    const results: (number | Error)[] = [new ConnectError('down', Code.Unavailable), 7,
      new ConnectError('no', Code.Unimplemented)];
    const fetch = vi.fn(async () => {
      const r = results.shift()!;
      if (r instanceof Error) throw r;
      return r;
    });
    const got: number[] = [];
    const errors: Code[] = [];
    const feed = new HandlesFeed(fetch, (n) => got.push(n), (e) => {
      errors.push((e as ConnectError).code);
      return (e as ConnectError).code === Code.Unimplemented;
    }, () => now);
    for (let k = 0; k < 3; ++k) {
      feed.request();
      await vi.runAllTimersAsync();
      now += MIN_INTERVAL_MS;
    }
    expect(errors).toEqual([Code.Unavailable, Code.Unimplemented]);
    expect(got).toEqual([7]);
    feed.request();
    await vi.runAllTimersAsync();
    expect(fetch).toHaveBeenCalledTimes(3);
  });
});
