"""Who is in a session and what they touch: a presence stream read by the C
library's background thread, polled or iterated here."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional

import numpy as np

from . import _library
from ._library import check, lib, read_string, token_bytes
from .errors import DeadlineExceeded
from .history import _indexed_uint32
from .handle_stream import HandleStream
from .streams import _wait

if TYPE_CHECKING:
    from .session import Session


@dataclass(frozen=True)
class Participant:
    """Someone in the session: `role` "viewer" or "editor", `colour`
    "#rrggbb" (fixed for a name), `touching` the base vertices of their
    latest change (while under 10 s old), `handle_vertices` the detailed-mesh
    vertices of their handles, `pointer` where they point (x y z, None when
    they do not) and the detailed-mesh vertex nearest it, `idle_seconds`
    since their last change, pointer move or join."""

    client_name: str
    role: str
    colour: str
    touching: np.ndarray
    handle_vertices: np.ndarray
    pointer: Optional[np.ndarray]
    pointer_vertex: Optional[int]
    idle_seconds: float


@dataclass(frozen=True)
class Presence:
    """Everyone present, by name, at the session's `version`."""

    version: int
    participants: list[Participant]

    def get(self, client_name: str) -> Optional[Participant]:
        """The participant named `client_name`, or None."""
        return next((p for p in self.participants if p.client_name == client_name), None)

    def __contains__(self, client_name: str) -> bool:
        return self.get(client_name) is not None


class PresenceWatcher(HandleStream["Presence"]):
    """A presence stream (Session.presence): the current presence first,
    then a new one whenever it changes (at most every 100 ms). Its
    client_name is listed as present while it is open. Iterate it, or poll;
    use as a context manager (or close())."""

    _what = "presence stream"
    _close = staticmethod(lambda handle: lib.filigree_presence_close(handle))
    _free = staticmethod(lambda handle: lib.filigree_presence_free(handle))

    def __init__(self, session: "Session", client_name: str, token: Optional[str]) -> None:
        handle = ctypes.c_void_p()
        check(lib.filigree_presence_open(session.handle, token_bytes(token), client_name.encode(),
                                         ctypes.byref(handle)))
        super().__init__(session, handle)

    def poll(self) -> Optional[Presence]:
        """The newest presence if it is newer than the last one polled, else
        None. Never waits. Raises StreamEnded (or why it failed) once the
        stream ended and its last presence was polled."""
        version, updated = ctypes.c_uint64(), ctypes.c_int()
        check(lib.filigree_presence_poll(self.handle, ctypes.byref(version), ctypes.byref(updated)))
        if not updated.value:
            return None
        count = ctypes.c_size_t(0)
        check(lib.filigree_presence_participant_count(self.handle, ctypes.byref(count)))
        return Presence(version.value, [self._participant(i) for i in range(count.value)])

    def _participant(self, i: int) -> Participant:
        q = _library.Participant()
        check(lib.filigree_presence_participant_get(self.handle, i, ctypes.byref(q)))
        pointer = np.array(q.pointer[:], dtype=np.float32) if q.has_pointer else None
        return Participant(read_string(lib.filigree_presence_participant_name, self.handle, i),
                           "editor" if q.role == 1 else "viewer", f"#{q.colour:06x}",
                           _indexed_uint32(lib.filigree_presence_participant_touching, self.handle, i),
                           _indexed_uint32(lib.filigree_presence_participant_handles, self.handle, i), pointer,
                           q.pointer_vertex if q.has_pointer else None, q.idle_seconds)

    def wait(self, timeout: Optional[float] = None) -> bool:
        """Waits until poll() has a new presence (True) or `timeout` seconds
        passed (False; None: no limit). Raises StreamEnded (or why it
        failed) when the stream ends without one."""
        return _wait(lib.filigree_presence_wait, self.handle, timeout)

    def next(self, timeout: Optional[float] = None) -> Presence:
        """Waits for the next presence; DeadlineExceeded after `timeout` seconds."""
        if not self.wait(timeout):
            raise DeadlineExceeded(4, f"no new presence within {timeout} s")
        presence = self.poll()
        assert presence is not None  # wait() said one was waiting
        return presence
