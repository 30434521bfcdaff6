"""Secrets stay secret: a server logging at debug level through a whole
session (create, join, a refused token, drive, handles, watch, close) never
writes a token; the CLI takes tokens only from a file or the environment."""

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


def test_tokens_never_reach_the_log():
    data_dir = tempfile.mkdtemp(prefix="filigree_secrets_")
    log_path = Path(data_dir) / "server.log"
    with open(log_path, "w") as log:
        server = subprocess.Popen([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--data-dir",
                                   str(Path(data_dir) / "store"), "--log-level", "debug"],
                                  stdout=subprocess.PIPE, stderr=log, text=True)
        try:
            address = server.stdout.readline().split()[-1]
            with filigree.Client(address) as client:
                session = client.create_session(DATA / "bunny_small.obj",
                                                options=filigree.SessionOptions(base_vertices=150))
                secrets = [session.editor_token, session.viewer_token]
                with pytest.raises(filigree.NotFound):
                    client.join(session.id, session.viewer_token[::-1])  # a wrong token, refused
                with client.join(session.id, session.viewer_token) as viewer, viewer.watch() as watcher:
                    with session.drive("secrets") as driver:
                        pose = session.base_positions + np.float32(0.01)
                        frame = driver.wait_for_pose(driver.send(pose), 30)
                    session.set_handles([0], session.rest_positions[:1], client_name="secrets")
                    while watcher.next_frame(30).version <= frame.version:
                        pass
                session.end()
        finally:
            server.terminate()
            server.wait(timeout=60)
    text = log_path.read_text()
    shutil.rmtree(data_dir, ignore_errors=True)
    assert session.id in text, "the debug log covers the session (it names it)"
    for secret in secrets:
        assert secret not in text, "a token is in the server's log"
    # Nor a prefix of one long enough to matter (a truncated token is still a leak).
    for secret in secrets:
        assert secret[:12] not in text


def test_the_cli_takes_no_token_argument(server, session):
    cli = os.environ["FILIGREE_CLI"]
    refused = subprocess.run([cli, "watch", "--server", server.address, "--session", session.id,
                              "--token", session.viewer_token, "--frames", "1"],
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode != 0 and "--token" in refused.stderr
    env = {k: v for k, v in os.environ.items() if k != "FILIGREE_TOKEN"}
    missing = subprocess.run([cli, "watch", "--server", server.address, "--session", session.id, "--frames", "1"],
                             env=env, capture_output=True, text=True, timeout=60)
    assert missing.returncode != 0 and "FILIGREE_TOKEN" in missing.stderr
    with tempfile.NamedTemporaryFile("w", suffix=".token") as token_file:
        token_file.write(session.viewer_token + "\n")
        token_file.flush()
        from_file = subprocess.run([cli, "watch", "--server", server.address, "--session", session.id,
                                    "--token-file", token_file.name, "--frames", "1"],
                                   env=env, capture_output=True, text=True, timeout=60)
    assert from_file.returncode == 0, from_file.stderr
    assert session.viewer_token not in from_file.stdout + from_file.stderr
