"""What the C library's stream handles share in Python (presence, history
export): the handle, iteration until the stream ends, close and free, and
use as a context manager."""

from __future__ import annotations

import ctypes
from typing import Callable, ClassVar, Generic, Iterator, TypeVar

from ._library import check
from .errors import StreamEnded

T = TypeVar("T")


class HandleStream(Generic[T]):
    """A stream read through a C handle. Subclasses set `_what` (for the
    freed-handle error), `_close` and `_free` (the C functions) and next()."""

    _what: ClassVar[str]
    _close: ClassVar[Callable[[ctypes.c_void_p], int]]
    _free: ClassVar[Callable[[ctypes.c_void_p], None]]

    def __init__(self, session: object, handle: ctypes.c_void_p) -> None:
        self._session = session  # keeps the connection's Python objects alive
        self._handle = handle

    @property
    def handle(self) -> ctypes.c_void_p:
        if not self._handle:
            raise ValueError(f"the {self._what} was freed")
        return self._handle

    def next(self) -> T:
        raise NotImplementedError

    def __iter__(self) -> Iterator[T]:
        while True:
            try:
                yield self.next()
            except StreamEnded:
                return

    def close(self) -> None:
        """Ends the stream; raises if it had failed. Idempotent."""
        check(type(self)._close(self.handle))

    def free(self) -> None:
        """Ends the stream if open and releases the handle. Idempotent."""
        if self._handle:
            type(self)._free(self._handle)
            self._handle = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.free()

    def __del__(self) -> None:
        self.free()
