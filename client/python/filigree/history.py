"""A session's edit history: entries, checkpoints, and what an undo, a redo
or a restore did. Read through the C API (filigree_history_read, …)."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from . import _library
from ._library import check, lib, read_string

# HistoryEntry.kind, by the contract's numbers.
_KINDS = ("pose", "handles", "threshold", "restore", "undo", "redo")
# EditOutcome.result, by the C API's numbers (filigree_edit_result).
_RESULTS = ("done", "partial", "conflict", "nothing")


@dataclass(frozen=True)
class HistoryEntry:
    """One accepted change. `kind`: "pose" (poses, partial poses or joints),
    "handles", "threshold", "restore" (a checkpoint restored: `target` is its
    id), "undo" or "redo" (of entry `target`). `base_vertices`: the base
    vertices it changed (base order). Times are Unix seconds."""

    seq: int
    kind: str
    author: str
    start_time: float
    end_time: float
    base_vertices: np.ndarray
    target: int
    undone: bool
    gesture_id: int
    version: int


@dataclass(frozen=True)
class Checkpoint:
    """A named pose and threshold (Session.checkpoint): `after_entry` is the
    newest history entry it includes (0: none)."""

    id: int
    name: str
    author: str
    time: float
    version: int
    after_entry: int


@dataclass(frozen=True)
class History:
    """The history, oldest first, and the checkpoints. Entries below
    `first_seq` were dropped to keep the history within the server's bounds."""

    entries: list[HistoryEntry]
    checkpoints: list[Checkpoint]
    first_seq: int
    bytes: int


@dataclass(frozen=True)
class Conflict:
    """Another author's later change on base vertices an undo, redo or
    restore would have changed: those vertices keep their work."""

    author: str
    entry: int
    base_vertices: np.ndarray


@dataclass(frozen=True)
class EditOutcome:
    """What an undo, a redo or a restore did. `result`: "done" (every vertex
    restored), "partial" (but the conflicts' vertices), "conflict" (every
    vertex conflicts: nothing changed) or "nothing" (nothing to undo or
    redo). `entry`: the change undone or redone (a restore: the new entry);
    `recorded`: the entry this made (0 if nothing changed); frames with a
    version above `accepted_at_version` include the result."""

    result: str
    entry: int
    recorded: int
    accepted_at_version: int
    message: str
    conflicts: list[Conflict] = field(default_factory=list)

    @property
    def changed(self) -> bool:
        return self.recorded != 0


@dataclass(frozen=True)
class CheckpointDiff:
    """The current base pose against a checkpoint's: the base vertices that
    differ, the largest and the RMS distance (over every base vertex, in the
    mesh's units), and whether the threshold differs."""

    checkpoint: int
    version: int
    base_vertices: np.ndarray
    max_distance: float
    rms_distance: float
    threshold_differs: bool


def _indexed_uint32(function, handle, index: int) -> np.ndarray:
    """A uint32 array of element `index` of a (handle, index, buffer, capacity, required) function."""
    required = ctypes.c_size_t(0)
    status = function(handle, index, None, 0, ctypes.byref(required))
    if status not in (0, 101):  # 101: FILIGREE_ERROR_BUFFER_TOO_SMALL, the size query answered
        check(status)
    out = np.empty(required.value, dtype=np.uint32)
    if required.value:
        check(function(handle, index, out.ctypes.data_as(_library._U32), out.size, None))
    return out


def checkpoint_of(c: _library.Checkpoint, name: str, author: str) -> Checkpoint:
    return Checkpoint(c.id, name, author, c.time, c.version, c.after_entry)


def read_history(session_handle, token: Optional[bytes], newest: int) -> History:
    handle = ctypes.c_void_p()
    check(lib.filigree_history_read(session_handle, token, int(newest), ctypes.byref(handle)))
    try:
        info = _library.HistoryInfo()
        check(lib.filigree_history_info_get(handle, ctypes.byref(info)))
        entries = []
        for i in range(info.entry_count):
            e = _library.HistoryEntry()
            check(lib.filigree_history_entry_get(handle, i, ctypes.byref(e)))
            kind = _KINDS[e.kind] if 0 <= e.kind < len(_KINDS) else f"kind {e.kind}"
            entries.append(HistoryEntry(e.seq, kind, read_string(lib.filigree_history_entry_author, handle, i),
                                        e.start_time, e.end_time,
                                        _indexed_uint32(lib.filigree_history_entry_vertices, handle, i), e.target,
                                        bool(e.undone), e.gesture_id, e.version))
        checkpoints = []
        for i in range(info.checkpoint_count):
            c = _library.Checkpoint()
            check(lib.filigree_history_checkpoint_get(handle, i, ctypes.byref(c)))
            checkpoints.append(checkpoint_of(c, read_string(lib.filigree_history_checkpoint_name, handle, i),
                                             read_string(lib.filigree_history_checkpoint_author, handle, i)))
        return History(entries, checkpoints, info.first_seq, info.bytes)
    finally:
        lib.filigree_history_free(handle)


def _parse_conflicts(text: str) -> list[Conflict]:
    out = []
    for line in text.splitlines():
        author, entry, vertices = line.rsplit("\t", 2)
        out.append(Conflict(author, int(entry), np.array(vertices.split(), dtype=np.uint32)))
    return out


def edit_outcome(session_handle, outcome: _library.EditOutcome) -> EditOutcome:
    """The EditOutcome of the call that just filled `outcome` through this session handle."""
    result = _RESULTS[outcome.result] if 0 <= outcome.result < len(_RESULTS) else "nothing"
    return EditOutcome(result, outcome.entry, outcome.recorded, outcome.accepted_at_version,
                       read_string(lib.filigree_session_edit_message, session_handle),
                       _parse_conflicts(read_string(lib.filigree_session_edit_conflicts, session_handle)))


def diff_checkpoint(session_handle, token: Optional[bytes], checkpoint: int) -> CheckpointDiff:
    diff = _library.CheckpointDiff()
    required = ctypes.c_size_t(0)
    check(lib.filigree_diff_checkpoint(session_handle, token, int(checkpoint), ctypes.byref(diff), None, 0,
                                       ctypes.byref(required)))
    vertices = np.empty(0, dtype=np.uint32)
    while required.value:
        # The vertices with room for them: another read, whose numbers are
        # the ones kept (the pose may have changed in between; then again).
        vertices = np.empty(required.value, dtype=np.uint32)
        status = lib.filigree_diff_checkpoint(session_handle, token, int(checkpoint), ctypes.byref(diff),
                                              vertices.ctypes.data_as(_library._U32), vertices.size,
                                              ctypes.byref(required))
        if status != 101:  # FILIGREE_ERROR_BUFFER_TOO_SMALL: more differ now
            check(status)
            vertices = vertices[:diff.vertex_count]
            break
    return CheckpointDiff(diff.checkpoint, diff.version, vertices, diff.max_distance, diff.rms_distance,
                          bool(diff.threshold_differs))
