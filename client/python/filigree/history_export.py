"""A session's history as states: the base pose after each entry and the
detailed mesh it deforms to, decoded by the C library."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional

import numpy as np

from . import _library
from ._library import check, lib, read_string, token_bytes
from .handle_stream import HandleStream

if TYPE_CHECKING:
    from .session import Session


@dataclass(frozen=True)
class HistoryState:
    """The session after history entry `entry` (by `author`, at Unix time
    `time`, the session's `version` then): `base_pose` (m × 3, base order:
    what a replay submits) and `positions` (n × 3, session order: the
    detailed mesh deformed at full detail, T = 0), within `max_error`."""

    entry: int
    author: str
    time: float
    version: int
    base_pose: np.ndarray
    positions: np.ndarray
    max_error: float


class HistoryExport(HandleStream[HistoryState]):
    """The states of a range of the history, oldest first (Session.export_history).
    Iterate it; each state is deformed by the server as it is read. Use as a
    context manager (or close()) to stop early."""

    _what = "export"
    _close = staticmethod(lambda handle: lib.filigree_history_export_close(handle))
    _free = staticmethod(lambda handle: lib.filigree_history_export_free(handle))

    def __init__(self, session: "Session", from_entry: int, to_entry: int, token: Optional[str]) -> None:
        handle = ctypes.c_void_p()
        check(lib.filigree_export_history(session.handle, token_bytes(token), int(from_entry), int(to_entry),
                                          ctypes.byref(handle)))
        super().__init__(session, handle)

    def next(self) -> HistoryState:
        """Blocks for the next state. Raises StreamEnded once every state was
        read (or why the stream failed: InvalidArgument for a range the
        server refused)."""
        s = self._session
        positions = np.empty((s.vertex_count, 3), dtype=np.float32)
        base_pose = np.empty((s.base_vertex_count, 3), dtype=np.float32)
        state = _library.HistoryState()
        check(lib.filigree_history_export_next(self.handle, positions.ctypes.data_as(_library._F), positions.size,
                                               None, ctypes.byref(state)))
        check(lib.filigree_history_export_base_pose(self.handle, base_pose.ctypes.data_as(_library._F),
                                                    base_pose.size, None))
        return HistoryState(state.entry, read_string(lib.filigree_history_export_author, self.handle), state.time,
                            state.version, base_pose, positions, state.max_error)
