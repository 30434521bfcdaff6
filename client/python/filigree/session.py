"""A session: its meshes and skeleton, and what can be done to it."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from . import _library
from ._library import check, lib, read_string, token_bytes
from .history import CheckpointDiff, EditOutcome, History, checkpoint_of, diff_checkpoint, edit_outcome, read_history
from .history import Checkpoint as HistoryCheckpoint
from .history_export import HistoryExport
from .presence import PresenceWatcher
from .streams import Driver, Watcher


@dataclass(frozen=True)
class Joint:
    """A joint of the skeleton (parents before children; parent -1: a root).
    `rest` is the rest local transform: translation xyz, rotation quaternion
    xyzw, scale xyz."""

    name: str
    parent: int
    rest: np.ndarray


@dataclass(frozen=True)
class Clip:
    """An animation clip of a skinned upload."""

    name: str
    duration: float


def _array(function, handle, ctype, dtype, columns: int) -> np.ndarray:
    required = ctypes.c_size_t(0)
    status = function(handle, None, 0, ctypes.byref(required))
    if status not in (0, 101):
        check(status)
    out = np.empty(required.value, dtype=dtype)
    if required.value:
        check(function(handle, out.ctypes.data_as(ctypes.POINTER(ctype)), out.size, None))
    out = out.reshape(-1, columns) if columns > 1 else out
    out.flags.writeable = False  # the session's copy: users copy before editing
    return out


class Session:
    """A session made (Client.create_session, which holds both tokens) or
    joined (Client.join, with one token). Meshes are numpy arrays: positions
    (k, 3) float32, faces (f, 3) uint32. The rest mesh is what frames carry
    (n vertices, session order); the base mesh is what poses move (m
    vertices). Use as a context manager, or call free(): the session goes
    on on the server until end()."""

    def __init__(self, handle: ctypes.c_void_p, client) -> None:
        self._handle = handle
        self._client = client  # keeps the connection's Python object alive
        self.id: str = read_string(lib.filigree_session_id, handle)
        self.editor_token: str = read_string(lib.filigree_session_editor_token, handle)
        self.viewer_token: str = read_string(lib.filigree_session_viewer_token, handle)
        count = ctypes.c_size_t(0)
        check(lib.filigree_session_vertex_count(handle, ctypes.byref(count)))
        self.vertex_count: int = count.value
        check(lib.filigree_session_base_vertex_count(handle, ctypes.byref(count)))
        self.base_vertex_count: int = count.value
        self.rest_positions = _array(lib.filigree_session_rest_positions, handle, ctypes.c_float, np.float32, 3)
        self.rest_faces = _array(lib.filigree_session_rest_faces, handle, ctypes.c_uint32, np.uint32, 3)
        self.uploaded_ids = _array(lib.filigree_session_uploaded_ids, handle, ctypes.c_uint32, np.uint32, 1)
        self.base_positions = _array(lib.filigree_session_base_positions, handle, ctypes.c_float, np.float32, 3)
        self.base_faces = _array(lib.filigree_session_base_faces, handle, ctypes.c_uint32, np.uint32, 3)
        self.base_original_ids = _array(lib.filigree_session_base_original_ids, handle, ctypes.c_uint32, np.uint32, 1)
        self.joints: list[Joint] = self._joints()
        self.clips: list[Clip] = self._clips()

    def _joints(self) -> list[Joint]:
        count = ctypes.c_size_t(0)
        check(lib.filigree_session_joint_count(self._handle, ctypes.byref(count)))
        joints = []
        for j in range(count.value):
            parent = ctypes.c_int32(0)
            check(lib.filigree_session_joint_parent(self._handle, j, ctypes.byref(parent)))
            rest = np.empty(10, dtype=np.float32)
            check(lib.filigree_session_joint_rest(self._handle, j, rest.ctypes.data_as(_library._F), 10, None))
            joints.append(Joint(read_string(lib.filigree_session_joint_name, self._handle, j), parent.value, rest))
        return joints

    def _clips(self) -> list[Clip]:
        count = ctypes.c_size_t(0)
        check(lib.filigree_session_clip_count(self._handle, ctypes.byref(count)))
        clips = []
        for c in range(count.value):
            seconds = ctypes.c_double(0)
            check(lib.filigree_session_clip_duration(self._handle, c, ctypes.byref(seconds)))
            clips.append(Clip(read_string(lib.filigree_session_clip_name, self._handle, c), seconds.value))
        return clips

    @property
    def handle(self) -> ctypes.c_void_p:
        if not self._handle:
            raise ValueError("the session handle was freed")
        return self._handle

    # ------------------------------------------------------------ streams

    def drive(self, client_name: str = "filigree-python", token: Optional[str] = None) -> "Driver":
        """Opens a Drive stream (editor token; None: the session's)."""
        return Driver(self, client_name, token)

    def watch(self, after_version: int = 0, token: Optional[str] = None, max_vertices: int = 0) -> "Watcher":
        """Opens a Watch stream (either token): frames newer than `after_version`.
        It reconnects by itself when the server restarts or fails over (for up
        to 60 s), from the last frame it decoded. `max_vertices` > 0 asks
        for a level of detail: frames of a coarser mesh of at most that many
        vertices (rounded down to a power of two; the base below its size,
        the full mesh at or above n), each with its `level`;
        Watcher.set_detail changes it."""
        return Watcher.open(self, after_version, token, max_vertices)

    def play_clip(self, clip: str, speed: float = 1.0, loop: bool = False, start_seconds: float = 0.0,
                  max_rate: float = 0.0, token: Optional[str] = None) -> "Watcher":
        """Plays one of `clips` on the server: a Watcher over its frames,
        which ends after the last sample unless `loop`. The first sample is
        at clip time `start_seconds`; `speed` is the playback rate (0 means
        1); `max_rate` bounds the samples per second (0: as fast as frames
        compute, up to 60). Each frame's `clip_seconds` is the clip time of
        the newest sample it includes. ValueError for a speed or max_rate
        that is negative or not finite, or a start_seconds not finite."""
        return Watcher.play(self, clip, speed, loop, start_seconds, max_rate, token)

    # ------------------------------------------------------------ editing

    def set_handles(self, vertices: Sequence[int] | np.ndarray, targets: np.ndarray,
                    client_name: str = "filigree-python", token: Optional[str] = None, gesture_id: int = 0) -> int:
        """Replaces `client_name`'s handles: rest vertex vertices[k] (session
        order) should go to targets[k] (k × 3). Empty arrays remove them.
        Returns every participant's handle count. Calls of one drag share a
        nonzero `gesture_id`: one history entry, undone as one (0: calls less
        than 0.5 s apart are one entry)."""
        ids = np.ascontiguousarray(vertices, dtype=np.uint32).reshape(-1)
        points = np.ascontiguousarray(targets, dtype=np.float32).reshape(-1)
        total = ctypes.c_uint32(0)
        check(lib.filigree_set_handles_in_gesture(self.handle, token_bytes(token), client_name.encode(),
                                                  int(gesture_id),
                                                  ids.ctypes.data_as(_library._U32) if ids.size else None, ids.size,
                                                  points.ctypes.data_as(_library._F) if points.size else None,
                                                  points.size, ctypes.byref(total)))
        return total.value

    def set_threshold(self, threshold: float, whole_mesh: bool = False, token: Optional[str] = None) -> None:
        """Sets the cut's performance threshold T (whole_mesh: T = ∞)."""
        check(lib.filigree_set_threshold(self.handle, token_bytes(token), float(threshold), int(bool(whole_mesh))))

    def end(self, token: Optional[str] = None) -> None:
        """Ends the session on the server for everyone (editor token)."""
        check(lib.filigree_close_session(self.handle, token_bytes(token)))

    # ------------------------------------------------------------ working together

    def history(self, newest: int = 0, token: Optional[str] = None) -> History:
        """The history, oldest first, and the checkpoints (either token);
        `newest` > 0: only the newest that many entries."""
        return read_history(self.handle, token_bytes(token), newest)

    def undo(self, client_name: str = "filigree-python", force: bool = False,
             token: Optional[str] = None) -> EditOutcome:
        """Undoes `client_name`'s latest change not undone (editor token), on
        the base vertices nobody else changed since: the others' later work
        stays (`conflicts`) unless `force`. Never another author's change."""
        outcome = _library.EditOutcome()
        check(lib.filigree_undo(self.handle, token_bytes(token), client_name.encode(), int(bool(force)),
                                ctypes.byref(outcome)))
        return edit_outcome(self.handle, outcome)

    def redo(self, client_name: str = "filigree-python", force: bool = False,
             token: Optional[str] = None) -> EditOutcome:
        """Redoes `client_name`'s latest undone change (since its last new one)."""
        outcome = _library.EditOutcome()
        check(lib.filigree_redo(self.handle, token_bytes(token), client_name.encode(), int(bool(force)),
                                ctypes.byref(outcome)))
        return edit_outcome(self.handle, outcome)

    def checkpoint(self, name: str, client_name: str = "filigree-python",
                   token: Optional[str] = None) -> HistoryCheckpoint:
        """Names the current pose and threshold (editor token; `name`: 1 to
        200 bytes). history().checkpoints lists them."""
        made = _library.Checkpoint()
        check(lib.filigree_create_checkpoint(self.handle, token_bytes(token), name.encode(), client_name.encode(),
                                             ctypes.byref(made)))
        return checkpoint_of(made, name, client_name)

    def restore(self, checkpoint: int | HistoryCheckpoint, client_name: str = "filigree-python",
                token: Optional[str] = None) -> EditOutcome:
        """Goes back to a checkpoint (its id, or the Checkpoint): itself a
        history entry of `client_name`, so undo() takes it back. NotFound:
        no such checkpoint."""
        outcome = _library.EditOutcome()
        check(lib.filigree_restore_checkpoint(self.handle, token_bytes(token), _checkpoint_id(checkpoint),
                                              client_name.encode(), ctypes.byref(outcome)))
        return edit_outcome(self.handle, outcome)

    def diff(self, checkpoint: int | HistoryCheckpoint, token: Optional[str] = None) -> CheckpointDiff:
        """The current base pose against a checkpoint's (either token)."""
        return diff_checkpoint(self.handle, token_bytes(token), _checkpoint_id(checkpoint))

    def presence(self, client_name: str = "filigree-python", token: Optional[str] = None) -> PresenceWatcher:
        """Who is here and what they touch: a stream of Presence snapshots
        (iterate it), on which `client_name` is listed while it is open."""
        return PresenceWatcher(self, client_name, token)

    def set_presence(self, pointer: Optional[Sequence[float] | np.ndarray] = None, vertex: int = 0,
                     client_name: str = "filigree-python", token: Optional[str] = None) -> None:
        """Sets `client_name`'s pointer, shown in the others' presence: x y z
        on the mesh and the detailed-mesh vertex nearest it. None clears it."""
        at = None
        if pointer is not None:
            at = np.ascontiguousarray(pointer, dtype=np.float32).reshape(-1)
            if at.size != 3:
                raise ValueError(f"pointer must be x y z, not {at.size} values")
        check(lib.filigree_set_presence(self.handle, token_bytes(token), client_name.encode(),
                                        at.ctypes.data_as(_library._F) if at is not None else None, int(vertex)))

    def export_history(self, from_entry: int = 0, to_entry: int = 0, token: Optional[str] = None) -> HistoryExport:
        """The state after each history entry from `from_entry` to `to_entry`
        (0: the oldest kept, the newest), oldest first: an iterator of
        HistoryState (base pose, and the detailed mesh deformed at full
        detail). At most 2000 entries at a time."""
        return HistoryExport(self, from_entry, to_entry, token)

    # ------------------------------------------------------------ lifetime

    def free(self) -> None:
        """Releases the handle (the session goes on on the server). Idempotent."""
        if self._handle:
            lib.filigree_session_free(self._handle)
            self._handle = None

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc) -> None:
        self.free()

    def __del__(self) -> None:
        self.free()

    def __repr__(self) -> str:
        return f"Session({self.id!r}, {self.vertex_count} vertices, base {self.base_vertex_count})"


def _checkpoint_id(checkpoint: int | HistoryCheckpoint) -> int:
    return int(checkpoint.id if isinstance(checkpoint, HistoryCheckpoint) else checkpoint)
