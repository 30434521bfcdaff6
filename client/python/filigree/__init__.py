"""Filigree's Python client: upload a detailed mesh, drive its base mesh, and
get back the full-resolution deformation as numpy arrays.

    import filigree
    with filigree.Client("127.0.0.1:50051") as client:
        with client.create_session("bunny.obj") as session, session.drive("me") as driver:
            pose = session.base_positions.copy()
            pose[:, 1] += 0.01
            frame = driver.wait_for_pose(driver.send(pose))
            print(frame.version, frame.positions.shape)

Built on libfiligree.so (the C API): frames are decoded by the same code as
the C++ client's. Set FILIGREE_LIBRARY to its path when it is not installed.
"""

from ._library import library_path
from .client import DUAL_QUATERNION, LINEAR_BLEND, Client, SessionOptions
from .errors import (DeadlineExceeded, FailedPrecondition, FiligreeError, InvalidArgument, NotFound,
                     PermissionDenied, ResourceExhausted, Status, StreamEnded, Unauthenticated, Unavailable)
from .history import Checkpoint, CheckpointDiff, Conflict, EditOutcome, History, HistoryEntry
from .history_export import HistoryExport, HistoryState
from .presence import Participant, Presence, PresenceWatcher
from .session import Clip, Joint, Session
from .streams import JOINTS_LOCAL_TRS, JOINTS_MODEL_MATRIX, Change, Driver, Frame, Level, Watcher

__version__ = "0.1.0"


def library_version() -> str:
    """The version of the loaded libfiligree.so."""
    from ._library import lib

    return lib.filigree_version_string().decode()


__all__ = [
    "Client", "SessionOptions", "Session", "Joint", "Clip", "Driver", "Watcher", "Frame", "Level", "Change",
    "FiligreeError", "Status", "InvalidArgument", "NotFound", "PermissionDenied", "Unauthenticated",
    "Unavailable", "ResourceExhausted", "DeadlineExceeded", "FailedPrecondition", "StreamEnded", "LINEAR_BLEND", "DUAL_QUATERNION",
    "JOINTS_LOCAL_TRS", "JOINTS_MODEL_MATRIX", "library_path", "library_version",
    "History", "HistoryEntry", "Checkpoint", "CheckpointDiff", "EditOutcome", "Conflict", "Presence", "Participant",
    "PresenceWatcher", "HistoryExport", "HistoryState",
]
