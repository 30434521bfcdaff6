"""Loads libfiligree.so (the C API, include/filigree/filigree.h) and declares
its functions for ctypes. Every frame is decoded by that library: this
package adds no second implementation of the wire format."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from typing import Optional
from ctypes import POINTER, c_char_p, c_double, c_float, c_int, c_int32, c_int64, c_size_t, c_uint32, c_uint64, c_void_p

_SONAME = "libfiligree.so.0"


class ConnectOptions(ctypes.Structure):
    _fields_ = [("pem_root_certs", c_char_p), ("pem_cert_chain", c_char_p), ("pem_private_key", c_char_p)]


class CSessionOptions(ctypes.Structure):
    _fields_ = [
        ("base_vertices", c_uint32),
        ("base_ratio", c_double),
        ("threshold", c_double),
        ("whole_mesh", c_int32),
        ("quantization_bits", c_uint32),
        ("skinning", c_int32),
    ]


class FrameInfo(ctypes.Structure):
    _fields_ = [
        ("version", c_uint64),
        ("pose_id", c_uint64),
        ("encoded_bytes", c_uint64),
        ("frames_received", c_uint64),
        ("max_error", c_float),
        ("keyframe", c_int32),
    ]


class ClipPlayback(ctypes.Structure):
    _fields_ = [("speed", c_double), ("loop", c_int32), ("start_seconds", c_double), ("max_rate", c_double)]


class WatchOptions(ctypes.Structure):
    _fields_ = [("after_version", c_uint64), ("max_vertices", c_uint32)]


class EditOutcome(ctypes.Structure):
    _fields_ = [("result", c_int32), ("conflict_count", c_uint32), ("entry", c_uint64), ("recorded", c_uint64),
                ("accepted_at_version", c_uint64), ("conflict_vertex_count", c_uint64)]


class Checkpoint(ctypes.Structure):
    _fields_ = [("id", c_uint64), ("time", c_double), ("version", c_uint64), ("after_entry", c_uint64)]


class CheckpointDiff(ctypes.Structure):
    _fields_ = [("checkpoint", c_uint64), ("version", c_uint64), ("vertex_count", c_uint64), ("max_distance", c_double),
                ("rms_distance", c_double), ("threshold_differs", c_int32)]


class HistoryInfo(ctypes.Structure):
    _fields_ = [("entry_count", c_uint64), ("checkpoint_count", c_uint64), ("first_seq", c_uint64), ("bytes", c_uint64)]


class HistoryEntry(ctypes.Structure):
    _fields_ = [("seq", c_uint64), ("kind", c_int32), ("undone", c_int32), ("start_time", c_double),
                ("end_time", c_double), ("target", c_uint64), ("gesture_id", c_uint64), ("version", c_uint64),
                ("vertex_count", c_uint64)]


class Participant(ctypes.Structure):
    _fields_ = [("role", c_int32), ("colour", c_uint32), ("has_pointer", c_int32), ("pointer", c_float * 3),
                ("pointer_vertex", c_uint32), ("idle_seconds", c_double), ("touching_count", c_uint64),
                ("handle_count", c_uint64)]


class HistoryState(ctypes.Structure):
    _fields_ = [("entry", c_uint64), ("version", c_uint64), ("time", c_double), ("max_error", c_float)]


FrameCallback = ctypes.CFUNCTYPE(None, POINTER(c_float), c_size_t, c_uint64, c_void_p)

_P = c_void_p  # every handle is opaque
_F = POINTER(c_float)
_U32 = POINTER(c_uint32)
_SIZE = POINTER(c_size_t)

# name: (argument types, result type); the result is an int status unless given.
_SIGNATURES: dict[str, tuple[list, object]] = {
    "filigree_status_name": ([c_int], c_char_p),
    "filigree_version_string": ([], c_char_p),
    "filigree_last_error": ([], c_char_p),
    "filigree_connect": ([c_char_p, POINTER(ConnectOptions), POINTER(_P)], c_int),
    "filigree_client_set_decode_threads": ([_P, c_uint32], c_int),
    "filigree_client_set_api_key": ([_P, c_char_p], c_int),
    "filigree_client_last_error": ([_P], c_char_p),
    "filigree_client_free": ([_P], c_int),
    "filigree_create_session": ([_P, c_void_p, c_size_t, c_char_p, POINTER(CSessionOptions), c_char_p, POINTER(_P)], c_int),
    "filigree_join": ([_P, c_char_p, c_char_p, POINTER(_P)], c_int),
    "filigree_session_id": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_session_editor_token": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_session_viewer_token": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_session_vertex_count": ([_P, _SIZE], c_int),
    "filigree_session_base_vertex_count": ([_P, _SIZE], c_int),
    "filigree_session_rest_positions": ([_P, _F, c_size_t, _SIZE], c_int),
    "filigree_session_rest_faces": ([_P, _U32, c_size_t, _SIZE], c_int),
    "filigree_session_uploaded_ids": ([_P, _U32, c_size_t, _SIZE], c_int),
    "filigree_session_base_positions": ([_P, _F, c_size_t, _SIZE], c_int),
    "filigree_session_base_faces": ([_P, _U32, c_size_t, _SIZE], c_int),
    "filigree_session_base_original_ids": ([_P, _U32, c_size_t, _SIZE], c_int),
    "filigree_session_joint_count": ([_P, _SIZE], c_int),
    "filigree_session_joint_name": ([_P, c_size_t, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_session_joint_parent": ([_P, c_size_t, POINTER(c_int32)], c_int),
    "filigree_session_joint_rest": ([_P, c_size_t, _F, c_size_t, _SIZE], c_int),
    "filigree_session_clip_count": ([_P, _SIZE], c_int),
    "filigree_session_clip_name": ([_P, c_size_t, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_session_clip_duration": ([_P, c_size_t, POINTER(c_double)], c_int),
    "filigree_set_handles": ([_P, c_char_p, c_char_p, _U32, c_size_t, _F, c_size_t, _U32], c_int),
    "filigree_set_threshold": ([_P, c_char_p, c_double, c_int], c_int),
    "filigree_close_session": ([_P, c_char_p], c_int),
    "filigree_session_last_error": ([_P], c_char_p),
    "filigree_session_free": ([_P], c_int),
    "filigree_driver_open": ([_P, c_char_p, c_char_p, POINTER(_P)], c_int),
    "filigree_driver_send_positions": ([_P, c_uint64, _F, c_size_t], c_int),
    "filigree_driver_send_partial": ([_P, c_uint64, _U32, c_size_t, _F, c_size_t], c_int),
    "filigree_driver_send_joints": ([_P, c_uint64, c_int, _U32, c_size_t, _F, c_size_t], c_int),
    "filigree_driver_poll": ([_P, _F, c_size_t, POINTER(c_uint64), POINTER(c_uint64), POINTER(c_int)], c_int),
    "filigree_driver_frame_info": ([_P, POINTER(FrameInfo)], c_int),
    "filigree_driver_wait_frame": ([_P, c_int64], c_int),
    "filigree_driver_wait_for_pose": ([_P, c_uint64, c_int64], c_int),
    "filigree_driver_reconnects": ([_P, POINTER(c_uint64)], c_int),
    "filigree_driver_changes": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_driver_close": ([_P], c_int),
    "filigree_driver_last_error": ([_P], c_char_p),
    "filigree_driver_free": ([_P], c_int),
    "filigree_watcher_open": ([_P, c_char_p, c_uint64, FrameCallback, c_void_p, POINTER(_P)], c_int),
    "filigree_watcher_open_with": ([_P, c_char_p, POINTER(WatchOptions), FrameCallback, c_void_p, POINTER(_P)], c_int),
    "filigree_play_clip": ([_P, c_char_p, c_char_p, c_double, c_int, FrameCallback, c_void_p, POINTER(_P)], c_int),
    "filigree_play_clip_with": ([_P, c_char_p, c_char_p, POINTER(ClipPlayback), FrameCallback, c_void_p, POINTER(_P)],
                                c_int),
    "filigree_watcher_poll": ([_P, _F, c_size_t, POINTER(c_uint64), POINTER(c_uint64), POINTER(c_int)], c_int),
    "filigree_watcher_frame_info": ([_P, POINTER(FrameInfo)], c_int),
    "filigree_watcher_clip_seconds": ([_P, POINTER(c_double)], c_int),
    "filigree_watcher_wait_frame": ([_P, c_int64], c_int),
    "filigree_watcher_level_vertex_count": ([_P, _SIZE], c_int),
    "filigree_watcher_level_original_ids": ([_P, _U32, c_size_t, _SIZE], c_int),
    "filigree_watcher_level_faces": ([_P, _U32, c_size_t, _SIZE], c_int),
    "filigree_watcher_set_detail": ([_P, c_uint32, POINTER(c_uint32)], c_int),
    "filigree_watcher_reconnects": ([_P, POINTER(c_uint64)], c_int),
    "filigree_watcher_changes": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_watcher_wait": ([_P, c_int64], c_int),
    "filigree_watcher_close": ([_P], c_int),
    "filigree_watcher_last_error": ([_P], c_char_p),
    "filigree_watcher_free": ([_P], c_int),
    # working together: history, undo, checkpoints, presence, export, gestures
    "filigree_driver_set_gesture": ([_P, c_uint64], c_int),
    "filigree_set_handles_in_gesture": ([_P, c_char_p, c_char_p, c_uint64, _U32, c_size_t, _F, c_size_t, _U32], c_int),
    "filigree_undo": ([_P, c_char_p, c_char_p, c_int, POINTER(EditOutcome)], c_int),
    "filigree_redo": ([_P, c_char_p, c_char_p, c_int, POINTER(EditOutcome)], c_int),
    "filigree_session_edit_message": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_session_edit_conflicts": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_create_checkpoint": ([_P, c_char_p, c_char_p, c_char_p, POINTER(Checkpoint)], c_int),
    "filigree_restore_checkpoint": ([_P, c_char_p, c_uint64, c_char_p, POINTER(EditOutcome)], c_int),
    "filigree_diff_checkpoint": ([_P, c_char_p, c_uint64, POINTER(CheckpointDiff), _U32, c_size_t, _SIZE], c_int),
    "filigree_history_read": ([_P, c_char_p, c_uint32, POINTER(_P)], c_int),
    "filigree_history_info_get": ([_P, POINTER(HistoryInfo)], c_int),
    "filigree_history_entry_get": ([_P, c_size_t, POINTER(HistoryEntry)], c_int),
    "filigree_history_entry_author": ([_P, c_size_t, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_history_entry_vertices": ([_P, c_size_t, _U32, c_size_t, _SIZE], c_int),
    "filigree_history_checkpoint_get": ([_P, c_size_t, POINTER(Checkpoint)], c_int),
    "filigree_history_checkpoint_name": ([_P, c_size_t, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_history_checkpoint_author": ([_P, c_size_t, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_history_last_error": ([_P], c_char_p),
    "filigree_history_free": ([_P], c_int),
    "filigree_presence_open": ([_P, c_char_p, c_char_p, POINTER(_P)], c_int),
    "filigree_presence_poll": ([_P, POINTER(c_uint64), POINTER(c_int)], c_int),
    "filigree_presence_wait": ([_P, c_int64], c_int),
    "filigree_presence_participant_count": ([_P, _SIZE], c_int),
    "filigree_presence_participant_get": ([_P, c_size_t, POINTER(Participant)], c_int),
    "filigree_presence_participant_name": ([_P, c_size_t, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_presence_participant_touching": ([_P, c_size_t, _U32, c_size_t, _SIZE], c_int),
    "filigree_presence_participant_handles": ([_P, c_size_t, _U32, c_size_t, _SIZE], c_int),
    "filigree_presence_close": ([_P], c_int),
    "filigree_presence_last_error": ([_P], c_char_p),
    "filigree_presence_free": ([_P], c_int),
    "filigree_set_presence": ([_P, c_char_p, c_char_p, _F, c_uint32], c_int),
    "filigree_export_history": ([_P, c_char_p, c_uint64, c_uint64, POINTER(_P)], c_int),
    "filigree_history_export_next": ([_P, _F, c_size_t, _SIZE, POINTER(HistoryState)], c_int),
    "filigree_history_export_author": ([_P, c_char_p, c_size_t, _SIZE], c_int),
    "filigree_history_export_base_pose": ([_P, _F, c_size_t, _SIZE], c_int),
    "filigree_history_export_close": ([_P], c_int),
    "filigree_history_export_last_error": ([_P], c_char_p),
    "filigree_history_export_free": ([_P], c_int),
}


def library_path() -> str:
    """Where libfiligree.so is taken from: $FILIGREE_LIBRARY, else the
    system's library search (after `make install`: /usr/local/lib)."""
    explicit = os.environ.get("FILIGREE_LIBRARY")
    if explicit:
        return explicit
    return ctypes.util.find_library("filigree") or _SONAME


def _load() -> ctypes.CDLL:
    path = library_path()
    try:
        lib = ctypes.CDLL(path)
    except OSError as e:
        raise ImportError(
            f"filigree: cannot load the C library {path!r} ({e}); install it (`make install`) "
            "or set FILIGREE_LIBRARY to the path of libfiligree.so"
        ) from e
    for name, (argtypes, restype) in _SIGNATURES.items():
        try:
            function = getattr(lib, name)
        except AttributeError as e:
            raise ImportError(f"filigree: {path} has no {name}: it is older than this package") from e
        function.argtypes = argtypes
        function.restype = restype
    return lib


lib = _load()
NULL_CALLBACK = FrameCallback()


def check(status: int) -> None:
    """Raises the FiligreeError of a failed call (the calling thread's
    message, which the C API sets on every failure)."""
    if status != 0:
        from .errors import error_for

        raise error_for(status, (lib.filigree_last_error() or b"").decode("utf-8", "replace"))


def token_bytes(token: Optional[str]) -> Optional[bytes]:
    """A token for the C API: UTF-8, or None for the session's own."""
    return token.encode() if token is not None else None


def read_string(function, handle, *leading) -> str:
    """A string out of a (handle, …, buffer, capacity, required) function."""
    required = c_size_t(0)
    status = function(handle, *leading, None, 0, ctypes.byref(required))
    if status != 101:  # FILIGREE_ERROR_BUFFER_TOO_SMALL: the size query answered
        check(status)
    buffer = ctypes.create_string_buffer(required.value)
    check(function(handle, *leading, buffer, required.value, None))
    return buffer.value.decode("utf-8", "replace")
