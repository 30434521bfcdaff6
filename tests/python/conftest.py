"""Fixtures of the Python client's tests: a filigree-server started here on
an ephemeral loopback port (FILIGREE_SERVER), stopped after each module."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent.parent / "data"


class Server:
    def __init__(self, binary: str) -> None:
        self.data_dir = tempfile.mkdtemp(prefix="filigree_pytest_")
        self.process = subprocess.Popen(
            [binary, "--listen", "127.0.0.1:0", "--data-dir", self.data_dir, "--log-level", "warn"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.process.stdout.readline()  # the server prints it once it listens
        if not line.startswith("listening on "):
            self.stop()
            raise RuntimeError(f"filigree-server did not start: {line!r} {self.process.stderr.read()}")
        self.address = line.split()[-1]

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(timeout=60)
        shutil.rmtree(self.data_dir, ignore_errors=True)


@pytest.fixture(scope="module")
def server():
    s = Server(os.environ["FILIGREE_SERVER"])
    yield s
    s.stop()


@pytest.fixture(scope="module")
def client(server):
    import filigree

    with filigree.Client(server.address) as c:
        yield c


@pytest.fixture
def session(client):
    import filigree

    s = client.create_session(DATA / "bunny_small.obj", options=filigree.SessionOptions(base_vertices=150),
                              client_name="pytest")
    yield s
    s.free()


@pytest.fixture
def diagonal(session):
    p = session.rest_positions
    import numpy as np

    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
