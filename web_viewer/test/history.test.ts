// The pure parts of working together: gesture ids, what the history list
// and the undo answers say, and what a presence message shows.
import { create } from '@bufbuild/protobuf';
import { describe, expect, it } from 'vitest';

import {
  HistoryEntry_Kind, Participant_Role, PresenceSchema, UndoResponse_Outcome, UndoResponseSchema,
} from '../src/gen/filigree/v1/filigree_pb';
import { newGestureId } from '../src/gesture';
import { describeEntry, diffText, historyKey, keptPhrase, kindName, sentence, undoText } from '../src/history';
import { activity, MAX_MARKERS, presenceKey, presentParticipants, spread } from '../src/presence-layer';
import type { HistoryLine } from '../src/pipeline-protocol';

const line = (extra: Partial<HistoryLine>): HistoryLine => ({
  seq: 1, kind: HistoryEntry_Kind.POSE, author: 'web-aaaaaa', startTime: 1, endTime: 2, vertices: 10, target: 0, undone: false,
  gestureId: 5n, version: 3n, ...extra,
});

describe('gesture ids', () => {
  it('are fresh 64-bit values, never 0', () => {
    const ids = new Set(Array.from({ length: 100 }, () => newGestureId()));
    expect(ids.size).toBe(100);
    for (const id of ids) expect(id > 0n && id < 1n << 64n).toBe(true);
    let calls = 0;
    const zeroFirst = (b: Uint8Array) => {
      if (calls++ > 0) b[7] = 1;
      return b;
    };
    expect(newGestureId(zeroFirst)).toBe(1n);
  });
});

describe('history lines', () => {
  it('say what each kind of entry did', () => {
    expect(describeEntry(line({ vertices: 1 }))).toBe('moved 1 base vertex');
    expect(describeEntry(line({ vertices: 1234 }))).toBe('moved 1,234 base vertices');
    expect(describeEntry(line({ kind: HistoryEntry_Kind.HANDLES, vertices: 0 }))).toBe('changed handles');
    expect(describeEntry(line({ kind: HistoryEntry_Kind.THRESHOLD }))).toBe('changed the threshold');
    expect(describeEntry(line({ kind: HistoryEntry_Kind.RESTORE, target: 2, vertices: 3 }), [{ id: 2n, name: 'before' }]))
      .toBe('restored checkpoint “before” (3 base vertices)');
    expect(describeEntry(line({ kind: HistoryEntry_Kind.UNDO, target: 7, vertices: 2 }))).toBe('undid #7 (2 base vertices)');
    expect(describeEntry(line({ kind: HistoryEntry_Kind.REDO, target: 7, vertices: 0 }))).toBe('redid #7');
    expect([0, 1, 2, 3, 4, 5].map(kindName)).toEqual(['pose', 'handles', 'threshold', 'restore', 'undo', 'redo']);
  });

  it('are keyed by what is shown', () => {
    const lines = (entries: HistoryLine[]) => ({ entries, checkpoints: [], firstSeq: 1, bytes: 0 });
    expect(historyKey(lines([line({})]))).toBe(historyKey(lines([line({ gestureId: 9n })])));
    expect(historyKey(lines([line({})]))).not.toBe(historyKey(lines([line({ undone: true })])));
    expect(historyKey(lines([line({})]))).not.toBe(historyKey(lines([line({ vertices: 11 })])));
  });
});

describe('undo answers in plain words', () => {
  const answer = (outcome: UndoResponse_Outcome, conflicts: [string, number[]][] = []) => create(UndoResponseSchema, {
    outcome, conflicts: conflicts.map(([author, baseVertices]) => ({ author, baseVertices })),
  });

  it('name whose later work was kept', () => {
    expect(keptPhrase(answer(UndoResponse_Outcome.PARTIAL, [['Ben', [4]]]).conflicts, 'me')).toBe('Ben\'s later change on 1 vertex');
    expect(keptPhrase(answer(UndoResponse_Outcome.PARTIAL, [['Ben', [4, 5]], ['Ann', [1]], ['Ben', [9]]]).conflicts, 'me'))
      .toBe('Ben\'s later change on 3 vertices and Ann\'s later change on 1 vertex');
    expect(keptPhrase(answer(UndoResponse_Outcome.CONFLICT, [['Ben', []]]).conflicts, 'me')).toBe('Ben\'s later threshold');
    expect(keptPhrase(answer(UndoResponse_Outcome.CONFLICT, [['', [1]]]).conflicts, 'me')).toBe('someone else\'s later change on 1 vertex');
  });

  it('for every outcome', () => {
    const target = line({ vertices: 10 });
    expect(undoText(answer(UndoResponse_Outcome.DONE), false, 'me', target)).toBe('Undid your change to 10 base vertices.');
    expect(undoText(answer(UndoResponse_Outcome.DONE), true, 'me')).toBe('Redid your latest change.');
    expect(undoText(answer(UndoResponse_Outcome.PARTIAL, [['Ben', [4]]]), false, 'me', target))
      .toBe('Undid your change on 9 of 10 base vertices. Kept Ben\'s later change on 1 vertex.');
    expect(undoText(answer(UndoResponse_Outcome.CONFLICT, [['Ben', [1, 2]]]), false, 'me', target))
      .toBe('Nothing undone: others changed all of it since. Kept Ben\'s later change on 2 vertices.');
    expect(undoText(answer(UndoResponse_Outcome.NOTHING), true, 'me')).toBe('Nothing of yours to redo.');
  });

  it('compare a checkpoint', () => {
    expect(diffText({ baseVertices: [1, 2, 3], maxDistance: 0.012345, thresholdDiffers: false }, 2))
      .toBe('3 base vertices differ, max distance 0.0123 (0.6 % of the mesh\'s size).');
    expect(diffText({ baseVertices: [], maxDistance: 0, thresholdDiffers: true }, 2)).toBe('0 base vertices differ; the threshold differs.');
    expect(sentence('restored checkpoint \'a\' (3 base vertices)')).toBe('Restored checkpoint \'a\' (3 base vertices).');
  });
});

describe('presence', () => {
  const presence = create(PresenceSchema, {
    participants: [
      { clientName: 'web-bbbbbb', role: Participant_Role.EDITOR, colour: '#3CB44B', touching: [1, 2, 3], handleVertices: [9],
        hasPointer: true, pointerX: 1, pointerY: 2, pointerZ: 3, pointerVertex: 44 },
      { clientName: 'web-aaaaaa', role: Participant_Role.VIEWER, colour: '#e6194b', hasPointer: true, pointerVertex: 1 },
      { clientName: 'cli', role: Participant_Role.EDITOR, colour: 'bad', idleSeconds: 125 },
    ],
  });

  it('lists this page first, then by name, with colours, roles and what each does', () => {
    const shown = presentParticipants(presence, 'web-aaaaaa');
    expect(shown.map((p) => [p.name, p.role, p.you, p.colour])).toEqual([
      ['web-aaaaaa', 'viewer', true, '#e6194b'], ['cli', 'editor', false, '#9aa3ad'], ['web-bbbbbb', 'editor', false, '#3cb44b'],
    ]);
    expect(shown[2].pointer).toEqual({ x: 1, y: 2, z: 3, vertex: 44 });
    expect(activity(shown[2])).toBe('touching 3 base vertices, 1 handle, pointing');
    // Most of a mesh of 4 base vertices: the mesh as a whole (no dots for it).
    expect(activity(shown[2], 4)).toBe('moving most of the mesh (3 base vertices), 1 handle, pointing');
    expect(activity(shown[2], 6)).toBe('touching 3 base vertices, 1 handle, pointing');
    expect(activity(shown[0])).toBe('');  // one's own pointer is not news
    expect(activity(shown[1])).toBe('idle 2 min');
    expect(presenceKey(shown)).toBe(presenceKey(presentParticipants(presence, 'web-aaaaaa')));
  });

  it('draws at most MAX_MARKERS dots a participant, evenly spread', () => {
    const many = Array.from({ length: 10_000 }, (_, i) => i);
    const picked = spread(many, MAX_MARKERS);
    expect(picked.length).toBe(MAX_MARKERS);
    expect(picked[0]).toBe(0);
    expect(picked[MAX_MARKERS - 1]).toBeGreaterThan(9990);
    expect(Array.from(spread([5, 6], 10))).toEqual([5, 6]);
  });
});
