"""The connection to a Filigree server, and the calls that make or join sessions."""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Union

from ._library import ConnectOptions, CSessionOptions, check, lib
from .session import Session

LINEAR_BLEND = 0
DUAL_QUATERNION = 1

_FORMATS = {".obj": "obj", ".ply": "ply", ".off": "off", ".gltf": "gltf", ".glb": "glb"}


@dataclass
class SessionOptions:
    """How the server preprocesses an upload; zeros mean its defaults."""

    base_vertices: int = 0  # target base size in vertices
    base_ratio: float = 0.0  # or as a fraction of the vertices
    threshold: float = 0.0  # the cut's performance threshold T
    whole_mesh: bool = False  # T = ∞: whole-mesh optimisation
    quantization_bits: int = 0  # frame deltas, 8…24; 0: chosen per frame
    skinning: int = LINEAR_BLEND  # skinned glTF: LINEAR_BLEND or DUAL_QUATERNION

    def _c(self) -> CSessionOptions:
        return CSessionOptions(self.base_vertices, self.base_ratio, self.threshold, int(self.whole_mesh),
                               self.quantization_bits, self.skinning)


class Client:
    """A channel to a server ("127.0.0.1:50051"), plaintext unless a TLS
    argument is given (PEM bytes; no root_certificates: the system's roots).
    Connects lazily: a server that is down fails the first call with
    Unavailable. A context manager; sessions and streams made from it keep
    the connection alive after close()."""

    def __init__(self, target: str, *, root_certificates: Optional[bytes] = None,
                 certificate_chain: Optional[bytes] = None, private_key: Optional[bytes] = None,
                 tls: bool = False, decode_threads: int = 0, api_key: Optional[str] = None) -> None:
        handle = ctypes.c_void_p()
        options = None
        if tls or root_certificates or certificate_chain or private_key:
            options = ConnectOptions(root_certificates, certificate_chain, private_key)
        check(lib.filigree_connect(target.encode(), ctypes.byref(options) if options else None, ctypes.byref(handle)))
        self._handle = handle
        self.target = target
        if decode_threads:
            check(lib.filigree_client_set_decode_threads(handle, decode_threads))
        if api_key:  # for a server started with --api-keys: needed to create sessions
            check(lib.filigree_client_set_api_key(handle, api_key.encode()))

    @property
    def handle(self) -> ctypes.c_void_p:
        if not self._handle:
            raise ValueError("the client was closed")
        return self._handle

    def create_session(self, mesh: Union[str, os.PathLike, bytes], *, format: Optional[str] = None,
                       options: Optional[SessionOptions] = None, client_name: str = "filigree-python") -> Session:
        """Uploads a mesh (a path, or a file's bytes with `format`: obj, ply,
        off, gltf or glb) and waits while the server preprocesses it. The
        session holds the editor and viewer tokens."""
        if isinstance(mesh, (bytes, bytearray, memoryview)):
            if not format:
                raise ValueError("give the format of mesh bytes: obj, ply, off, gltf or glb")
            data = bytes(mesh)
        else:
            path = Path(mesh)
            format = format or _FORMATS.get(path.suffix.lower())
            if not format:
                raise ValueError(f"{path}: unknown mesh format; give format=")
            data = path.read_bytes()
        handle = ctypes.c_void_p()
        c_options = options._c() if options else None
        check(lib.filigree_create_session(self.handle, data, len(data), format.encode(),
                                          ctypes.byref(c_options) if c_options else None, client_name.encode(),
                                          ctypes.byref(handle)))
        return Session(handle, self)

    def join(self, session_id: str, token: str) -> Session:
        """Joins someone's session with its editor or viewer token."""
        handle = ctypes.c_void_p()
        check(lib.filigree_join(self.handle, session_id.encode(), token.encode(), ctypes.byref(handle)))
        return Session(handle, self)

    def close(self) -> None:
        """Releases the handle. Idempotent."""
        if self._handle:
            lib.filigree_client_free(self._handle)
            self._handle = None

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()
