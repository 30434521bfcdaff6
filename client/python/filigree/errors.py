"""Exceptions: every failed call raises a FiligreeError whose `status` is the
gRPC status code the server answered (or the client library's equivalent),
with the message that says what was wrong."""

from __future__ import annotations

import enum


class Status(enum.IntEnum):
    """filigree_status: 1…16 are gRPC's status codes, 100 and up the C API's."""

    OK = 0
    CANCELLED = 1
    UNKNOWN = 2
    INVALID_ARGUMENT = 3
    DEADLINE_EXCEEDED = 4
    NOT_FOUND = 5
    ALREADY_EXISTS = 6
    PERMISSION_DENIED = 7
    RESOURCE_EXHAUSTED = 8
    FAILED_PRECONDITION = 9
    ABORTED = 10
    OUT_OF_RANGE = 11
    UNIMPLEMENTED = 12
    INTERNAL = 13
    UNAVAILABLE = 14
    DATA_LOSS = 15
    UNAUTHENTICATED = 16
    INVALID_HANDLE = 100
    BUFFER_TOO_SMALL = 101
    NULL_ARGUMENT = 102
    OUT_OF_MEMORY = 103
    STREAM_ENDED = 104
    WRONG_THREAD = 105


class FiligreeError(Exception):
    """A call failed. `status` says how (a Status, gRPC's numbering), the
    message says what was wrong."""

    status: Status = Status.UNKNOWN

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        try:
            self.status = Status(status)
        except ValueError:
            self.status = Status.UNKNOWN
        self.message = message

    @property
    def code(self) -> int:
        """The status as an int (gRPC's code for 1…16)."""
        return int(self.status)

    def grpc_status_code(self):
        """The status as grpc.StatusCode (needs the grpcio package), or None
        for the C API's own codes (100 and up)."""
        import grpc  # optional: only for callers that mix this with grpcio

        for code in grpc.StatusCode:
            if code.value[0] == int(self.status):
                return code
        return None


class InvalidArgument(FiligreeError):
    """A malformed mesh or pose, wrong sizes, a bad index."""


class NotFound(FiligreeError):
    """An unknown or closed session, an unknown clip."""


class PermissionDenied(FiligreeError):
    """A wrong token, or a viewer's where an editor's is needed."""


class Unauthenticated(FiligreeError):
    """No credentials."""


class Unavailable(FiligreeError):
    """The server is down or restarting, or the session is moving: retry."""


class DeadlineExceeded(FiligreeError):
    """A wait timed out."""


class FailedPrecondition(FiligreeError):
    """E.g. joints for a session without a skeleton."""


class ResourceExhausted(FiligreeError):
    """Over a limit or quota (the message says which)."""


class StreamEnded(FiligreeError):
    """The stream ended normally: nothing more to send or receive."""


_BY_STATUS: dict[int, type[FiligreeError]] = {
    Status.INVALID_ARGUMENT: InvalidArgument,
    Status.NOT_FOUND: NotFound,
    Status.PERMISSION_DENIED: PermissionDenied,
    Status.UNAUTHENTICATED: Unauthenticated,
    Status.UNAVAILABLE: Unavailable,
    Status.DEADLINE_EXCEEDED: DeadlineExceeded,
    Status.FAILED_PRECONDITION: FailedPrecondition,
    Status.STREAM_ENDED: StreamEnded,
    Status.RESOURCE_EXHAUSTED: ResourceExhausted,
}


def error_for(status: int, message: str) -> FiligreeError:
    """The exception of the most specific class for `status`."""
    return _BY_STATUS.get(status, FiligreeError)(status, message)
