"""Streams survive a server restart on their own: the C++ client library's
Watch stream (under the C API and this package) reconnects after
UNAVAILABLE, from the last version it saw, and decodes on; its Drive stream
reconnects and re-sends the poses no frame acknowledged."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

import filigree

DATA = Path(__file__).resolve().parent.parent / "data"


class RestartableServer:
    """A server with a data directory, stopped (SIGTERM) and started again on
    the same address: its sessions are restored from disk."""

    def __init__(self) -> None:
        self.data_dir = tempfile.mkdtemp(prefix="filigree_restart_")
        self.process, self.address = self._start("127.0.0.1:0")

    def _start(self, listen: str) -> tuple[subprocess.Popen, str]:
        process = subprocess.Popen([os.environ["FILIGREE_SERVER"], "--listen", listen, "--data-dir", self.data_dir,
                                    "--log-level", "warn"], stdout=subprocess.PIPE, text=True)
        line = process.stdout.readline()
        assert line.startswith("listening on "), line
        return process, line.split()[-1]

    def stop(self) -> None:
        self.process.terminate()
        assert self.process.wait(timeout=60) == 0  # drained: its streams ended UNAVAILABLE

    def start_again(self) -> None:
        self.process, again = self._start(self.address)
        assert again == self.address

    def close(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=60)
        shutil.rmtree(self.data_dir, ignore_errors=True)


@pytest.fixture
def server():
    s = RestartableServer()
    yield s
    s.close()


def new_session(server: RestartableServer) -> tuple[filigree.Client, filigree.Session, float]:
    client = filigree.Client(server.address)
    session = client.create_session(DATA / "bunny_small.obj", options=filigree.SessionOptions(base_vertices=150))
    diagonal = float(np.linalg.norm(np.ptp(session.rest_positions, axis=0)))
    return client, session, diagonal


def test_a_watcher_survives_a_server_restart(server):
    client, session, diagonal = new_session(server)
    watcher = session.watch()
    before = watcher.next_frame(30)
    server.stop()
    server.start_again()
    # Someone drives the session on the new process; the old watcher sees it.
    with filigree.Client(server.address).join(session.id, session.editor_token) as editor, editor.drive("after") as d:
        moved = editor.base_positions + np.float32(0.1 * diagonal)
        answer = d.wait_for_pose(d.send(moved), 30)
    frame = watcher.next_frame(60)
    while frame.version < answer.version:
        frame = watcher.next_frame(60)
    assert frame.version == answer.version > before.version
    assert watcher.reconnects >= 1
    assert np.abs(frame.positions - answer.positions).max() <= 2 * answer.max_error + 1e-6 * diagonal
    watcher.free()
    session.free()
    client.close()


def test_a_driver_survives_a_server_restart_and_resends_what_was_not_acknowledged(server):
    client, session, diagonal = new_session(server)
    driver = session.drive("engine")
    first = driver.wait_for_pose(driver.send(session.base_positions + np.float32(0.05 * diagonal)), 30)
    assert driver.reconnects == 0
    server.stop()
    # Sent while no server runs: accepted, kept until a frame acknowledges it.
    moved = session.base_positions + np.float32(0.1 * diagonal)
    pose_id = driver.send(moved)
    server.start_again()
    answer = driver.wait_for_pose(pose_id, 60)
    assert answer.pose_id == pose_id and answer.version > first.version
    assert driver.reconnects >= 1
    # The frame is that pose's: the same translation on every vertex.
    shift = answer.positions - session.rest_positions
    assert np.abs(shift - np.float32(0.1 * diagonal)).max() <= answer.max_error + 1e-6 * diagonal
    driver.close()
    driver.free()
    session.free()
    client.close()
