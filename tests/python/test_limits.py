"""Resource limits of one server: streams per session."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

import filigree

DATA = Path(__file__).resolve().parent.parent / "data"


def test_a_session_serves_at_most_max_streams_per_session():
    data_dir = tempfile.mkdtemp(prefix="filigree_limits_")
    server = subprocess.Popen([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--data-dir", data_dir,
                               "--log-level", "warn", "--max-streams-per-session", "2"],
                              stdout=subprocess.PIPE, text=True)
    try:
        address = server.stdout.readline().split()[-1]
        with filigree.Client(address) as client:
            session = client.create_session(DATA / "bunny_small.obj",
                                            options=filigree.SessionOptions(base_vertices=150))
            first, second = session.watch(), session.watch()
            first.next_frame(30)
            second.next_frame(30)
            third = session.watch()
            with pytest.raises(filigree.ResourceExhausted, match="--max-streams-per-session"):
                third.next_frame(30)
            driver = session.drive("over")
            driver.send(session.base_positions)
            with pytest.raises(filigree.ResourceExhausted):
                driver.next_frame(30)
            # A stream that ends gives its place back (the server learns of
            # the end after the client; bounded wait, as any client would).
            first.free()
            deadline = time.monotonic() + 30
            while True:
                again = session.watch()
                try:
                    again.next_frame(30)
                    break
                except filigree.ResourceExhausted:
                    again.free()
                    assert time.monotonic() < deadline, "a closed stream's place never came back"
                    time.sleep(0.05)
            again.free()
            # Other sessions are not affected.
            other = client.create_session(DATA / "bunny_small.obj", options=filigree.SessionOptions(base_vertices=150))
            with other.watch() as watcher:
                watcher.next_frame(30)
            for stream in (second, third, driver):
                stream.free()
    finally:
        server.terminate()
        server.wait(timeout=60)
        shutil.rmtree(data_dir, ignore_errors=True)
