"""How long a driven session stalls while two other sessions load from the store.

Two sessions of a large mesh (default: ../shared/data/dragon.ply, 435k
vertices) are created and left idle until the server evicts them
(--idle-timeout 1); a small session is then driven closed-loop while both
large ones are joined at once, which loads them (record, hierarchy, model).
Prints how long the joins took and the driver's longest interval between
frames while they ran.

Usage (from the repository, after a build):
  FILIGREE_LIBRARY=build/client/lib/libfiligree.so.0.1.0 PYTHONPATH=client/python \\
    /usr/bin/python3 bench/session_load_stall.py build/server/filigree-server [mesh]
"""
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

import filigree
from closed_loop_driver import ClosedLoopDriver

REPO = Path(__file__).resolve().parent.parent
binary = sys.argv[1]
mesh = sys.argv[2] if len(sys.argv) > 2 else str(REPO.parent / "shared" / "data" / "dragon.ply")
data = tempfile.mkdtemp(prefix="filigree_load_stall_")
server = subprocess.Popen([binary, "--listen", "127.0.0.1:0", "--data-dir", data, "--idle-timeout", "1", "--log-level", "info"],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
address = server.stdout.readline().split()[-1]
evicted = set()
evictions = threading.Condition()


def read_log() -> None:
    for line in server.stderr:
        if m := re.search(r"event=session_evicted session=(\w+)", line):
            with evictions:
                evicted.add(m.group(1))
                evictions.notify_all()


threading.Thread(target=read_log, daemon=True).start()
try:
    with filigree.Client(address) as client:
        large = []
        for _ in range(2):
            s = client.create_session(mesh)
            large.append((s.id, s.editor_token))
            s.free()
        small = client.create_session(REPO / "tests" / "data" / "bunny_small.obj", options=filigree.SessionOptions(base_vertices=150))
        with evictions:
            evictions.wait_for(lambda: all(i in evicted for i, _ in large), timeout=120)
        driver = ClosedLoopDriver(small)
        driver.start()
        time.sleep(2.0)  # the driver's steady state before the loads
        joined = {}

        def join(session_id: str, token: str) -> None:
            with filigree.Client(address) as other:
                start = time.monotonic()
                other.join(session_id, token).free()
                joined[session_id] = time.monotonic() - start

        loads_start = time.monotonic()
        joins = [threading.Thread(target=join, args=s) for s in large]
        for j in joins:
            j.start()
        for j in joins:
            j.join()
        loads_end = time.monotonic()
        time.sleep(1.0)
        driver.stop()
        intervals = driver.intervals_before(float("inf"))
        during = driver.intervals_during(loads_start, loads_end)
        print(f"joins (each loads a session): {', '.join(f'{t:.2f}' for t in joined.values())} s")
        print(f"driver: interval p50 {1000 * np.median(intervals):.2f} ms; while the loads ran ({loads_end - loads_start:.2f} s): "
              f"{len(during)} frames, longest interval {1000 * max(during, default=float('nan')):.1f} ms")
finally:
    server.terminate()
    server.wait(timeout=60)
    shutil.rmtree(data, ignore_errors=True)
