"""API keys (--api-keys): who may create and list sessions, and how much.
Keys are made with `filigree api-key` (the file keeps only their SHA-256);
quotas on sessions, vertices, uploads per minute and open streams answer
RESOURCE_EXHAUSTED saying which; a key lists only its own sessions; session
tokens work as before; SIGHUP reloads the file; no key reaches the log."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import threading
from pathlib import Path

import pytest

import filigree

DATA = Path(__file__).resolve().parent.parent / "data"
MESH = DATA / "bunny_small.obj"  # 1839 vertices
OPTIONS = filigree.SessionOptions(base_vertices=150)


def make_key(name: str, *quotas: str) -> tuple[str, str]:
    out = subprocess.run([os.environ["FILIGREE_CLI"], "api-key", name, *quotas], capture_output=True, text=True,
                         check=True, timeout=60).stdout
    fields = dict(line.split(": ", 1) for line in out.splitlines())
    return fields["key"], fields["line"]


class KeyedServer:
    def __init__(self, keys_file: Path, *extra: str) -> None:
        self.data_dir = tempfile.mkdtemp(prefix="filigree_keys_")
        self.process = subprocess.Popen([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--data-dir",
                                         self.data_dir, "--log-level", "debug", "--api-keys", str(keys_file), *extra],
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.process.stdout.readline()
        assert line.startswith("listening on "), line
        self.address = line.split()[-1]
        self.log: list[str] = []
        self.changed = threading.Condition()
        threading.Thread(target=self._read_log, daemon=True).start()

    def _read_log(self) -> None:
        for line in self.process.stderr:
            with self.changed:
                self.log.append(line)
                self.changed.notify_all()

    def wait_for_log(self, text: str, timeout: float = 30.0) -> None:
        with self.changed:
            assert self.changed.wait_for(lambda: any(text in line for line in self.log), timeout), text

    def stop(self) -> str:
        self.process.terminate()
        self.process.wait(timeout=60)
        shutil.rmtree(self.data_dir, ignore_errors=True)
        with self.changed:
            return "".join(self.log)


@pytest.fixture(scope="module")
def keyed():
    tmp = Path(tempfile.mkdtemp(prefix="filigree_keyfile_"))
    keys = {
        "alice": make_key("alice", "--sessions", "2", "--streams", "2"),
        "bob": make_key("bob"),
        "carol": make_key("carol", "--uploads-per-minute", "2"),
        "dave": make_key("dave", "--vertices", "1000"),
        "erin": make_key("erin", "--streams", "2"),
    }
    keys_file = tmp / "keys"
    keys_file.write_text("# name sha256 quotas\n" + "".join(line + "\n" for _, line in keys.values()))
    server = KeyedServer(keys_file)
    yield server, {name: key for name, (key, _) in keys.items()}, keys_file
    log = server.stop()
    for key, _ in keys.values():
        assert key not in log, "an API key is in the server's log"
    shutil.rmtree(tmp, ignore_errors=True)


def client(server, key=None):
    return filigree.Client(server.address, api_key=key)


def test_creating_needs_a_known_key(keyed):
    server, keys, _ = keyed
    with client(server) as anonymous, pytest.raises(filigree.Unauthenticated, match="API key"):
        anonymous.create_session(MESH, options=OPTIONS)
    with client(server, "fgk_" + "0" * 48) as stranger, pytest.raises(filigree.PermissionDenied):
        stranger.create_session(MESH, options=OPTIONS)


def test_quotas_of_sessions_uploads_and_vertices(keyed):
    server, keys, _ = keyed
    with client(server, keys["alice"]) as alice:
        held = [alice.create_session(MESH, options=OPTIONS) for _ in range(2)]
        with pytest.raises(filigree.ResourceExhausted, match="2 sessions"):
            alice.create_session(MESH, options=OPTIONS)
        held[0].end()  # ending one gives its place back
        held.append(alice.create_session(MESH, options=OPTIONS))
    with client(server, keys["carol"]) as carol:
        for _ in range(2):
            carol.create_session(MESH, options=OPTIONS).end()
        with pytest.raises(filigree.ResourceExhausted, match="uploads in the last minute"):
            carol.create_session(MESH, options=OPTIONS)
    with client(server, keys["dave"]) as dave, pytest.raises(filigree.ResourceExhausted, match="vertices"):
        dave.create_session(MESH, options=OPTIONS)


def test_streams_quota_counts_open_streams_of_the_keys_sessions(keyed):
    server, keys, _ = keyed
    with client(server, keys["erin"]) as erin:
        session = erin.create_session(MESH, options=OPTIONS)
        watcher = session.watch()
        watcher.next_frame(30)
        driver = session.drive("erin")
        driver.wait_for_pose(driver.send(session.base_positions), 30)  # both streams are open now
        third = session.watch()
        with pytest.raises(filigree.ResourceExhausted, match="2 streams"):
            third.next_frame(30)
        third.free()
        # A driver that is done (half-close, which returns once the server
        # ended the stream) gives its slot back.
        driver.close()
        driver.free()
        with session.watch() as again:
            again.next_frame(30)  # served: not RESOURCE_EXHAUSTED
        watcher.free()
        session.end()


def listed(server, key: str) -> set[str]:
    run = subprocess.run([os.environ["FILIGREE_CLI"], "sessions", "--server", server.address],
                         env={**os.environ, "FILIGREE_API_KEY": key}, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    return {line.split()[0] for line in run.stdout.splitlines()[1:] if line.strip()}


def test_a_key_lists_its_own_sessions_and_tokens_still_open_any(keyed):
    server, keys, _ = keyed
    with client(server, keys["bob"]) as bob:
        mine = bob.create_session(MESH, options=OPTIONS)
        assert mine.id in listed(server, keys["bob"])
        assert mine.id not in listed(server, keys["alice"])
        unlisted = subprocess.run([os.environ["FILIGREE_CLI"], "sessions", "--server", server.address],
                                  env={k: v for k, v in os.environ.items() if k != "FILIGREE_API_KEY"},
                                  capture_output=True, text=True, timeout=60)
        assert unlisted.returncode != 0 and "API key" in unlisted.stderr
        # The session token is what joins, whoever holds the key.
        with client(server) as anyone, anyone.join(mine.id, mine.viewer_token) as joined:
            assert joined.vertex_count == mine.vertex_count
        mine.end()


def test_sighup_reloads_the_keys(keyed):
    server, keys, keys_file = keyed
    key, line = make_key("frank")
    with client(server, key) as frank:
        with pytest.raises(filigree.PermissionDenied):
            frank.create_session(MESH, options=OPTIONS)
        keys_file.write_text(keys_file.read_text() + line + "\n")
        server.process.send_signal(signal.SIGHUP)
        server.wait_for_log("event=api_keys_reloaded keys=6")
        frank.create_session(MESH, options=OPTIONS).end()
    keys_file.write_text(keys_file.read_text() + "broken line\n")
    server.process.send_signal(signal.SIGHUP)
    server.wait_for_log("event=api_keys_reload_failed")
    with client(server, key) as frank:  # the keys in force stay
        frank.create_session(MESH, options=OPTIONS).end()


def test_sessions_evicted_from_memory_still_count_against_their_key():
    tmp = Path(tempfile.mkdtemp(prefix="filigree_keyfile_"))
    key, line = make_key("frank", "--sessions", "1")
    (tmp / "keys").write_text(line + "\n")
    # Idle sessions leave memory after 0.2 s (their records stay).
    server = KeyedServer(tmp / "keys", "--idle-timeout", "0.2")
    try:
        with client(server, key) as frank:
            first = frank.create_session(MESH, options=OPTIONS)
            server.wait_for_log(f"event=session_evicted session={first.id}")
            with pytest.raises(filigree.ResourceExhausted, match="1 sessions"):
                frank.create_session(MESH, options=OPTIONS)
            first.end()  # loaded again to be closed: its place comes back
            frank.create_session(MESH, options=OPTIONS)
    finally:
        server.stop()
        shutil.rmtree(tmp, ignore_errors=True)


def test_vertices_quota_at_its_boundary_counts_what_the_key_holds_and_reserves():
    # bunny_small has 1839 vertices after repair: a quota of exactly that
    # holds one session, one vertex less holds none, and a second session
    # would cross it. Four concurrent uploads under a quota for one and a
    # half: exactly one passes (check and reservation are one step, with
    # four preprocessing slots they overlap).
    tmp = Path(tempfile.mkdtemp(prefix="filigree_keyfile_"))
    keys = {"exact": make_key("exact", "--vertices", "1839"), "under": make_key("under", "--vertices", "1838"),
            "racing": make_key("racing", "--vertices", "2758")}
    (tmp / "keys").write_text("".join(line + "\n" for _, line in keys.values()))
    server = KeyedServer(tmp / "keys", "--preprocessing-slots", "4")
    try:
        with client(server, keys["exact"][0]) as exact:
            held = exact.create_session(MESH, options=OPTIONS)
            assert held.vertex_count == 1839
            with pytest.raises(filigree.ResourceExhausted, match="its sessions hold 1839"):
                exact.create_session(MESH, options=OPTIONS)
        with client(server, keys["under"][0]) as under, pytest.raises(filigree.ResourceExhausted, match="1838 vertices"):
            under.create_session(MESH, options=OPTIONS)
        outcomes: list[str] = []
        lock = threading.Lock()

        def upload() -> None:
            with client(server, keys["racing"][0]) as racing:
                try:
                    racing.create_session(MESH, options=OPTIONS)
                    outcome = "created"
                except filigree.ResourceExhausted:
                    outcome = "refused"
            with lock:
                outcomes.append(outcome)

        threads = [threading.Thread(target=upload) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        assert sorted(outcomes) == ["created", "refused", "refused", "refused"]
    finally:
        server.stop()
        shutil.rmtree(tmp, ignore_errors=True)


def test_a_revoked_keys_sessions_open_no_new_streams():
    # Revoking a key with SIGHUP lifted the streams quota of its sessions
    # (no key was taken for no limit); now they take no new stream at all.
    tmp = Path(tempfile.mkdtemp(prefix="filigree_keyfile_"))
    key, line = make_key("gone", "--streams", "1")
    keys_file = tmp / "keys"
    keys_file.write_text(line + "\n")
    server = KeyedServer(keys_file)
    try:
        with client(server, key) as gone:
            session = gone.create_session(MESH, options=OPTIONS)
            with session.watch() as watcher:
                watcher.next_frame(30)
            keys_file.write_text("# no keys\n")
            server.process.send_signal(signal.SIGHUP)
            server.wait_for_log("event=api_keys_reloaded keys=0")
            for _ in range(2):
                watcher = session.watch()
                with pytest.raises(filigree.PermissionDenied, match="revoked"):
                    watcher.next_frame(30)
                watcher.free()
    finally:
        server.stop()
        shutil.rmtree(tmp, ignore_errors=True)
