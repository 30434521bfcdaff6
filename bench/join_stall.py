"""What joining a large session costs the server, and a driven session meanwhile.

A session of a large mesh (default: ../shared/data/dragon.ply, 435k
vertices) is created and kept in memory; a small session is driven
closed-loop while N client processes (default 2) call JoinSession on the
large one as fast as they can for 4 s (each join receives its whole rest
mesh, ~14 MB). Prints the server's CPU time over the joins, how many
joins completed, and the driver's frame intervals before and during them.

Usage (from the repository, after a build):
  FILIGREE_LIBRARY=build/client/lib/libfiligree.so.0.1.0 PYTHONPATH=client/python \\
    /usr/bin/python3 bench/join_stall.py build/server/filigree-server [mesh] [joiners]
"""
import multiprocessing as mp
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import filigree
from closed_loop_driver import ClosedLoopDriver

REPO = Path(__file__).resolve().parent.parent
SECONDS = 4.0


def joiner(address: str, session_id: str, token: str, done) -> None:
    with filigree.Client(address) as client:
        start, joins, worst = time.monotonic(), 0, 0.0
        while time.monotonic() - start < SECONDS:
            t = time.monotonic()
            client.join(session_id, token).free()
            worst = max(worst, time.monotonic() - t)
            joins += 1
        done.put((joins, worst))


def server_cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    binary = sys.argv[1]
    mesh = sys.argv[2] if len(sys.argv) > 2 else str(REPO.parent / "shared" / "data" / "dragon.ply")
    joiners = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    data = tempfile.mkdtemp(prefix="filigree_join_stall_")
    server = subprocess.Popen([binary, "--listen", "127.0.0.1:0", "--data-dir", data],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    address = server.stdout.readline().split()[-1]
    try:
        with filigree.Client(address) as client:
            large = client.create_session(mesh)
            large_id, large_token = large.id, large.editor_token
            large.free()
            small = client.create_session(REPO / "tests" / "data" / "bunny_small.obj",
                                          options=filigree.SessionOptions(base_vertices=150))
            driver = ClosedLoopDriver(small)
            driver.start()
            time.sleep(2.0)  # the driver's steady state first
            # Processes, not threads: a join's client-side decoding must not hold the driver's interpreter.
            spawn = mp.get_context("spawn")  # gRPC does not survive a fork
            done = spawn.Queue()
            procs = [spawn.Process(target=joiner, args=(address, large_id, large_token, done)) for _ in range(joiners)]
            cpu_start, start = server_cpu_seconds(server.pid), time.monotonic()
            for p in procs:
                p.start()
            results = [done.get(timeout=120) for _ in procs]
            for p in procs:
                p.join()
            end, cpu_end = time.monotonic(), server_cpu_seconds(server.pid)
            time.sleep(0.5)
            driver.stop()
            joins = sum(n for n, _ in results)
            before = driver.intervals_before(start)
            during = driver.intervals_during(start, end)
            print(f"{joins} joins by {joiners} clients in {end - start:.2f} s (slowest {max(w for _, w in results):.2f} s); "
                  f"server CPU {cpu_end - cpu_start:.2f} s, {1000 * (cpu_end - cpu_start) / max(joins, 1):.0f} ms a join "
                  f"(the driver's frames included)")
            print(f"driver: before, interval p50 {1000 * np.median(before):.2f} ms, longest {1000 * max(before):.1f} ms; "
                  f"during, {len(during)} frames, p50 {1000 * np.median(during):.2f} ms, p99 {1000 * np.percentile(during, 99):.1f} ms, "
                  f"longest {1000 * max(during):.1f} ms")
    finally:
        server.terminate()
        server.wait(timeout=60)
        shutil.rmtree(data, ignore_errors=True)


if __name__ == "__main__":
    main()
