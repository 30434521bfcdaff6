"""Drive and Watch streams. A background thread of the C library reads and
decodes each stream; these objects poll it (never waiting for the network)
or wait for the next frame, and iterate over frames."""

from __future__ import annotations

import contextlib
import ctypes
import math
import numbers
import random
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterator, Optional, Sequence

import numpy as np

from . import _library
from ._library import FrameInfo, check, lib, read_string, token_bytes
from .errors import DeadlineExceeded, FiligreeError
from .handle_stream import HandleStream

if TYPE_CHECKING:  # only for annotations: session.py imports this module
    from .session import Session

JOINTS_LOCAL_TRS = 0  # 10 floats per joint: translation xyz, quaternion xyzw, scale xyz
JOINTS_MODEL_MATRIX = 1  # 16 floats per joint: 4×4 model matrix, column-major

# Blocking waits go to the library in slices, so that Ctrl-C gets through.
_WAIT_SLICE_MS = 250


@dataclass(frozen=True)
class Change:
    """Who changed the session: a participant's newest pose id and how many
    base vertices its poses (or handles) moved."""

    client_name: str
    pose_id: int
    vertex_count: int


@dataclass(frozen=True)
class Level:
    """A level of detail: a mesh of `vertex_count` (k) vertices of the
    detailed mesh. Level vertex i is session vertex `original_ids[i]`
    (ascending), at rest at `rest_positions[i]`; `faces` (f × 3 uint32)
    index the level's vertices. At full detail (`full_detail`, k = n) it is
    the session's rest mesh: ids 0…n-1, the rest faces."""

    vertex_count: int
    original_ids: np.ndarray
    faces: np.ndarray
    rest_positions: np.ndarray
    full_detail: bool


@dataclass
class Frame:
    """A decoded frame: `positions` is the posed detailed mesh (n × 3
    float32, session order), within `max_error` of the server's. A clip's
    frames (Session.play_clip) number the newest sample they include in
    `pose_id` and give its clip time, in seconds, in `clip_seconds` (0 for
    other streams and for a frame that includes no sample). A watcher's
    frames at a level of detail (Session.watch(max_vertices=…)) hold the
    level's vertices only: `positions` is k × 3, vertex i at session vertex
    `level.original_ids[i]`; `level` is the Level of the frame (a
    full-detail one for frames of the whole mesh)."""

    version: int
    pose_id: int
    positions: np.ndarray
    encoded_bytes: int
    max_error: float
    keyframe: bool
    frames_received: int
    changes: list[Change] = field(default_factory=list)
    clip_seconds: float = 0.0
    level: Optional[Level] = None


def _wait(function, handle, timeout: Optional[float]) -> bool:
    """Calls a C wait (handle, timeout_ms) in slices until it succeeds (True)
    or `timeout` seconds passed (False; None: no limit); other failures raise."""
    deadline = None if timeout is None else time.monotonic() + timeout
    while True:
        left = _WAIT_SLICE_MS
        if deadline is not None:
            left = min(left, max(0, int((deadline - time.monotonic()) * 1000)))
        try:
            check(function(handle, left))
            return True
        except DeadlineExceeded:
            if deadline is not None and time.monotonic() >= deadline:
                return False


def _number(name: str, value: float, at_least_zero: bool) -> float:
    """`value` as a float, or ValueError naming `name` when it is not finite
    (or, with `at_least_zero`, negative): the server's rules for a clip's
    playback. TypeError for what is no number (e.g. a token passed by
    position where start_seconds now is; its value is not repeated)."""
    if not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, not a {type(value).__name__}")
    number = float(value)
    if not math.isfinite(number) or (at_least_zero and number < 0.0):
        rule = "finite and >= 0" if at_least_zero else "finite"
        raise ValueError(f"{name} must be {rule}, not {value!r}")
    return number


def _uint32_array(function, handle) -> np.ndarray:
    """A uint32 array out of a (handle, buffer, capacity, required) function."""
    required = ctypes.c_size_t(0)
    status = function(handle, None, 0, ctypes.byref(required))
    if status not in (0, 101):  # 101: FILIGREE_ERROR_BUFFER_TOO_SMALL, the size query answered
        check(status)
    out = np.empty(required.value, dtype=np.uint32)
    if required.value:
        check(function(handle, out.ctypes.data_as(_library._U32), out.size, None))
    return out


def _parse_changes(text: str) -> list[Change]:
    out = []
    for line in text.splitlines():
        name, pose_id, count = line.rsplit("\t", 2)
        out.append(Change(name, int(pose_id), int(count)))
    return out


class _Stream(HandleStream[Frame]):
    """What drivers and watchers share: polling, waiting and iterating."""

    _what = "stream"
    _poll = _info = _wait_frame = _reconnects = _changes = _close = _free = None  # the C functions, set by subclasses
    _clip_seconds = None  # a watcher's only: drivers play no clips
    _level_count = _level_ids = _level_faces = None  # a watcher's only: levels of detail

    def __init__(self, session: Session, handle: ctypes.c_void_p, at_level: bool = False) -> None:
        super().__init__(session, handle)  # the session's meshes size the frames
        self._n = session.vertex_count
        self._at_level = at_level  # opened with a vertex budget: frames of k <= n vertices
        self._level: Optional[Level] = None  # of the latest frame polled
        self._end_raised = False  # why the stream ended was raised already (close() need not again)

    def _check_stream(self, status: int) -> None:
        try:
            check(status)
        except DeadlineExceeded:
            raise
        except FiligreeError:
            self._end_raised = True
            raise

    def poll(self, out: Optional[np.ndarray] = None) -> Optional[Frame]:
        """The newest frame if it is newer than the last one polled, else
        None (frames in between are skipped). Never waits. `out`: an n × 3
        (or 3n) float32 C-contiguous array to decode into (no allocation);
        at a level of detail the frame fills its first k × 3 values and its
        `positions` are a view of them. Raises StreamEnded (or why it
        failed) once the stream ended and its last frame was polled."""
        if out is None:
            out = np.empty((self._n, 3), dtype=np.float32)
        elif out.dtype != np.float32 or not out.flags.c_contiguous or out.size != 3 * self._n:
            raise ValueError(f"out must be a C-contiguous float32 array of {3 * self._n} values")
        version, pose_id, updated = ctypes.c_uint64(), ctypes.c_uint64(), ctypes.c_int()
        self._check_stream(type(self)._poll(self.handle, out.ctypes.data_as(_library._F), out.size, ctypes.byref(version),
                               ctypes.byref(pose_id), ctypes.byref(updated)))
        if not updated.value:
            return None
        info = FrameInfo()
        check(type(self)._info(self.handle, ctypes.byref(info)))
        clip_seconds = ctypes.c_double(0.0)
        if type(self)._clip_seconds is not None:
            check(type(self)._clip_seconds(self.handle, ctypes.byref(clip_seconds)))
        level = self._polled_level()
        positions = out
        if level.vertex_count != self._n:  # the level's vertices, the first 3k values
            positions = out[:level.vertex_count] if out.ndim == 2 else out[:3 * level.vertex_count]
        return Frame(version.value, pose_id.value, positions, info.encoded_bytes, info.max_error, bool(info.keyframe),
                     info.frames_received, self.changes(), clip_seconds.value, level)

    def _full_level(self) -> Level:
        s = self._session
        return Level(s.vertex_count, np.arange(s.vertex_count, dtype=np.uint32), s.rest_faces, s.rest_positions, True)

    def _polled_level(self) -> Level:
        """The level of the frame just polled: read from the library when
        its vertex count (which identifies a level) changed."""
        count = self._n
        if type(self)._level_count is not None:
            k = ctypes.c_size_t(0)
            check(type(self)._level_count(self.handle, ctypes.byref(k)))
            count = k.value
        if self._level is None or self._level.vertex_count != count:
            if count == self._n:
                self._level = self._full_level()
            else:
                ids = _uint32_array(type(self)._level_ids, self.handle)
                faces = _uint32_array(type(self)._level_faces, self.handle).reshape(-1, 3)
                rest = self._session.rest_positions[ids]
                for array in (ids, faces, rest):
                    array.flags.writeable = False  # shared by the frames of the level
                self._level = Level(count, ids, faces, rest, False)
        return self._level

    @property
    def level(self) -> Optional[Level]:
        """The level of detail of the latest frame polled (None before the first)."""
        return self._level

    @property
    def reconnects(self) -> int:
        """How many times the stream has begun to reconnect by itself after
        its server went away (a restart, a failover). A driver re-sends the
        poses no frame acknowledged; a watcher resumes after its last frame."""
        count = ctypes.c_uint64()
        check(type(self)._reconnects(self.handle, ctypes.byref(count)))
        return count.value

    def changes(self) -> list[Change]:
        """Who changed what in the frames up to the latest polled one (since the poll before)."""
        return _parse_changes(read_string(type(self)._changes, self.handle))

    def wait_frame(self, timeout: Optional[float] = None) -> bool:
        """Waits until poll() has a new frame (True) or `timeout` seconds
        passed (False; None: no limit). Raises StreamEnded (or why it
        failed) when the stream ends without one."""
        try:
            return _wait(type(self)._wait_frame, self.handle, timeout)
        except FiligreeError:  # the stream ended (a timeout returns False)
            self._end_raised = True
            raise

    def next_frame(self, timeout: Optional[float] = None, out: Optional[np.ndarray] = None) -> Frame:
        """Waits for the next frame and returns it; DeadlineExceeded after `timeout` seconds."""
        if not self.wait_frame(timeout):
            raise DeadlineExceeded(4, f"no new frame within {timeout} s")
        frame = self.poll(out)
        assert frame is not None  # wait_frame said one was waiting
        return frame

    def next(self) -> Frame:
        """Iteration yields frames as they come (the newest when several wait), until the stream ends."""
        return self.next_frame()

    def __exit__(self, exc_type, *exc) -> None:
        """Closes the stream; a failure is raised unless it was raised before."""
        try:
            if exc_type is None and self._handle:
                try:
                    self.close()
                except FiligreeError:
                    if not self._end_raised:
                        raise
        finally:
            self.free()


class Driver(_Stream):
    """A Drive stream: send poses of the base mesh, receive the frames that
    include them (`Frame.pose_id` is the newest of yours included). Pose ids
    increase; send() numbers them itself when not given."""

    _poll = lib.filigree_driver_poll
    _info = lib.filigree_driver_frame_info
    _wait_frame = lib.filigree_driver_wait_frame
    _reconnects = lib.filigree_driver_reconnects
    _changes = lib.filigree_driver_changes
    _close = lib.filigree_driver_close
    _free = lib.filigree_driver_free

    def __init__(self, session: Session, client_name: str, token: Optional[str]) -> None:
        handle = ctypes.c_void_p()
        check(lib.filigree_driver_open(session.handle, token_bytes(token), client_name.encode(), ctypes.byref(handle)))
        super().__init__(session, handle)
        self._m = session.base_vertex_count
        self.last_pose_id = 0
        self._gesture_id = 0
        self._gestures = random.getrandbits(48)  # gesture() numbers them from here: unlike another driver's

    def _next_id(self, pose_id: Optional[int]) -> int:
        self.last_pose_id = self.last_pose_id + 1 if pose_id is None else int(pose_id)
        return self.last_pose_id

    @property
    def gesture_id(self) -> int:
        """The gesture the poses sent from now on belong to: poses of one
        nonzero id are one history entry, undone as one (Session.undo). 0
        (the default): none; the server then joins poses less than 0.5 s apart."""
        return self._gesture_id

    @gesture_id.setter
    def gesture_id(self, value: int) -> None:
        if not isinstance(value, numbers.Integral) or not 0 <= value < 2**64:
            raise ValueError(f"gesture_id must be an integer in [0, 2**64), not {value!r}")
        check(lib.filigree_driver_set_gesture(self.handle, int(value)))
        self._gesture_id = int(value)

    @contextlib.contextmanager
    def gesture(self) -> Iterator[int]:
        """The poses sent inside `with driver.gesture():` are one gesture (a
        new id, yielded), one history entry; afterwards none again."""
        self._gestures += 1
        self.gesture_id = self._gestures
        try:
            yield self._gestures
        finally:
            if self._handle:
                self.gesture_id = 0

    def _set_gesture(self, gesture_id: Optional[int]) -> None:
        if gesture_id is not None and gesture_id != self._gesture_id:
            self.gesture_id = gesture_id

    def send(self, positions: np.ndarray, pose_id: Optional[int] = None, gesture_id: Optional[int] = None) -> int:
        """A full pose: every base vertex (m × 3). Returns its pose id.
        `gesture_id` (None: keep the current one) sets `gesture_id` first."""
        p = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1)
        self._set_gesture(gesture_id)
        pid = self._next_id(pose_id)
        check(lib.filigree_driver_send_positions(self.handle, pid, p.ctypes.data_as(_library._F), p.size))
        return pid

    def send_partial(self, indices: Sequence[int] | np.ndarray, positions: np.ndarray,
                     pose_id: Optional[int] = None, gesture_id: Optional[int] = None) -> int:
        """Base vertices indices[k] move to positions[k]; the others stay."""
        i = np.ascontiguousarray(indices, dtype=np.uint32).reshape(-1)
        p = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1)
        self._set_gesture(gesture_id)
        pid = self._next_id(pose_id)
        check(lib.filigree_driver_send_partial(self.handle, pid, i.ctypes.data_as(_library._U32), i.size,
                                               p.ctypes.data_as(_library._F), p.size))
        return pid

    def send_joints(self, values: np.ndarray, joints: Optional[Sequence[int]] = None, space: int = JOINTS_LOCAL_TRS,
                    pose_id: Optional[int] = None, gesture_id: Optional[int] = None) -> int:
        """A skeletal pose: 10 (JOINTS_LOCAL_TRS) or 16 (JOINTS_MODEL_MATRIX)
        floats per joint, for `joints` or all joints in order."""
        v = np.ascontiguousarray(values, dtype=np.float32).reshape(-1)
        j = None if joints is None else np.ascontiguousarray(joints, dtype=np.uint32).reshape(-1)
        self._set_gesture(gesture_id)
        pid = self._next_id(pose_id)
        check(lib.filigree_driver_send_joints(self.handle, pid, int(space),
                                              None if j is None else j.ctypes.data_as(_library._U32),
                                              0 if j is None else j.size, v.ctypes.data_as(_library._F), v.size))
        return pid

    def wait_for_pose(self, pose_id: int, timeout: Optional[float] = 30.0) -> Frame:
        """Frames until one includes `pose_id` (or a later pose of yours)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            frame = self.next_frame(left)
            if frame.pose_id >= pose_id:
                return frame


class Watcher(_Stream):
    """A Watch stream (or a clip playing): the session's frames as they are computed."""

    _poll = lib.filigree_watcher_poll
    _info = lib.filigree_watcher_frame_info
    _clip_seconds = lib.filigree_watcher_clip_seconds
    _wait_frame = lib.filigree_watcher_wait_frame
    _reconnects = lib.filigree_watcher_reconnects
    _changes = lib.filigree_watcher_changes
    _close = lib.filigree_watcher_close
    _free = lib.filigree_watcher_free
    _level_count = lib.filigree_watcher_level_vertex_count
    _level_ids = lib.filigree_watcher_level_original_ids
    _level_faces = lib.filigree_watcher_level_faces

    @classmethod
    def open(cls, session: Session, after_version: int, token: Optional[str], max_vertices: int = 0) -> "Watcher":
        if not isinstance(max_vertices, numbers.Integral) or not 0 <= max_vertices < 2**32:
            raise ValueError(f"max_vertices must be an integer in [0, 2**32), not {max_vertices!r}")
        options = _library.WatchOptions(after_version=int(after_version), max_vertices=int(max_vertices))
        handle = ctypes.c_void_p()
        check(lib.filigree_watcher_open_with(session.handle, token_bytes(token), ctypes.byref(options),
                                             _library.NULL_CALLBACK, None, ctypes.byref(handle)))
        return cls(session, handle, at_level=max_vertices > 0)

    def set_detail(self, max_vertices: int) -> int:
        """Moves a watcher opened with a vertex budget to the level of
        `max_vertices` (>= 1, rounded as Session.watch's) and returns its
        vertex count k; frames of that level follow the ones in flight
        (poll until `frame.level.vertex_count` is k). FailedPrecondition for
        a watcher opened at full detail or a clip's."""
        if not isinstance(max_vertices, numbers.Integral) or not 1 <= max_vertices < 2**32:
            raise ValueError(f"max_vertices must be an integer in [1, 2**32), not {max_vertices!r}")
        count = ctypes.c_uint32(0)
        check(lib.filigree_watcher_set_detail(self.handle, int(max_vertices), ctypes.byref(count)))
        return count.value

    @classmethod
    def play(cls, session: Session, clip: str, speed: float, loop: bool, start_seconds: float, max_rate: float,
             token: Optional[str]) -> "Watcher":
        options = _library.ClipPlayback(speed=_number("speed", speed, at_least_zero=True), loop=int(bool(loop)),
                                        start_seconds=_number("start_seconds", start_seconds, at_least_zero=False),
                                        max_rate=_number("max_rate", max_rate, at_least_zero=True))
        handle = ctypes.c_void_p()
        check(lib.filigree_play_clip_with(session.handle, token_bytes(token), clip.encode(), ctypes.byref(options),
                                          _library.NULL_CALLBACK, None, ctypes.byref(handle)))
        return cls(session, handle)

    def wait(self, timeout: Optional[float] = None) -> bool:
        """Waits for the stream to end (e.g. a clip to finish): True once it
        ended normally, False after `timeout` seconds; raises if it failed."""
        return _wait(lib.filigree_watcher_wait, self.handle, timeout)
