"""A >= 2M-vertex session end to end from Python: the Python side of
`filigree_bench_service --huge`.

The same mesh as the C++ side (bench_mesh("huge") in service_harness.cpp: a
bumpy UV ellipsoid of 2,000,002 vertices and 4,000,000 faces) as binary PLY,
uploaded to a filigree-server this script starts on 127.0.0.1 (an ephemeral
port, a fresh data directory, the server's default limits: the ~66 MB rest
mesh is over half its 64 MiB messages and comes in GetRestMesh parts) with
filigree.Client.create_session, which returns with the tokens and the rest
mesh. Then a Drive stream: the first pose, and --poses more closed loop (the
whole-body bend of the C++ bench: runtime/procedural_motion), each timed
from send to its decoded frame. A join afterwards times reading the rest
mesh alone (upload -> tokens is about upload -> session less it). Server
memory: its peak (VmHWM) and now (VmRSS).

Usage (from the repository, after a build):
  FILIGREE_LIBRARY=build/client/lib/libfiligree.so.0.1.0 PYTHONPATH=client/python \\
    /usr/bin/python3 bench/service_large_mesh.py build/server/filigree-server [--poses 40]
"""
import argparse
import shutil
import subprocess
import tempfile
import time

import numpy as np

import filigree


def bumpy_uv_sphere(rings: int, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """bench::bumpy_uv_sphere: the north pole, `rings` rings of `segments`
    vertices, the south pole; faces outward."""
    theta = np.pi * np.arange(1, rings + 1) / (rings + 1)
    phi = 2 * np.pi * np.arange(segments) / segments

    def point(t: np.ndarray, p: np.ndarray) -> np.ndarray:
        r = 1.0 + 0.05 * np.sin(5 * t) * np.cos(4 * p) + 0.01 * np.sin(40 * t) * np.sin(40 * p)
        return np.stack([1.5 * r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t)], axis=-1)

    t, p = np.meshgrid(theta, phi, indexing="ij")
    positions = np.concatenate([point(np.zeros(1), np.zeros(1)), point(t, p).reshape(-1, 3),
                                point(np.full(1, np.pi), np.zeros(1))])
    south = len(positions) - 1
    j = np.arange(segments, dtype=np.int64)

    def at(ring, k):  # ring 1 ... rings
        return 1 + (ring - 1) * segments + k % segments

    north_cap = np.stack([np.zeros(segments, np.int64), at(1, j), at(1, j + 1)], axis=1)
    i = np.arange(1, rings)[:, None]
    a, b, c, d = at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)
    band = np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], axis=2).reshape(-1, 3)
    south_cap = np.stack([np.full(segments, south, np.int64), at(rings, j + 1), at(rings, j)], axis=1)
    return positions, np.concatenate([north_cap, band, south_cap]).astype(np.uint32)


def ply_bytes(positions: np.ndarray, faces: np.ndarray) -> bytes:
    """bench::ply_bytes: binary little-endian PLY, float32 coordinates."""
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(positions)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar uint vertex_indices\nend_header\n").encode()
    rows = np.zeros(len(faces), dtype=np.dtype([("n", "u1"), ("v", "<u4", 3)]))
    rows["n"] = 3
    rows["v"] = faces
    return header + positions.astype("<f4").tobytes() + rows.tobytes()


def bend(base_rest: np.ndarray, phase: float) -> np.ndarray:
    """runtime/procedural_motion's bend (MotionField, Motion::kBend) of the
    base vertices: about the smallest axis, by up to 60 degrees, growing as
    the square of the position along the longest axis past the middle."""
    p = base_rest.astype(np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    extent, center = hi - lo, 0.5 * (lo + hi)
    a = int(np.argmax(extent))
    b = (a + 1) % 3 if extent[(a + 1) % 3] >= extent[(a + 2) % 3] else (a + 2) % 3
    c = 3 - a - b
    s = (p[:, a] - center[a]) / max(0.5 * extent[a], 1e-300)
    angle = phase * (np.pi / 3.0) * np.maximum(s, 0.0) ** 2
    q = p - center
    cos, sin = np.cos(angle), np.sin(angle)
    u, v = (c + 1) % 3, (c + 2) % 3  # a right-handed rotation about axis c turns u towards v
    out = q.copy()
    out[:, u] = cos * q[:, u] - sin * q[:, v]
    out[:, v] = sin * q[:, u] + cos * q[:, v]
    return (out + center).astype(np.float32)


def status_mib(pid: int, field: str) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    return 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("server", help="the filigree-server binary")
    parser.add_argument("--poses", type=int, default=40, help="closed-loop poses after the first (default 40)")
    args = parser.parse_args()

    positions, faces = bumpy_uv_sphere(1000, 2000)
    data = ply_bytes(positions, faces)
    directory = tempfile.mkdtemp(prefix="filigree_large_mesh_")
    server = subprocess.Popen([args.server, "--listen", "127.0.0.1:0", "--data-dir", directory],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = server.stdout.readline()
        if not line.startswith("listening on "):
            raise RuntimeError(f"filigree-server did not start: {line!r}")
        with filigree.Client(line.split()[-1]) as client:
            start = time.monotonic()
            session = client.create_session(data, format="ply", client_name="service_large_mesh.py")
            made = time.monotonic()
            driver = session.drive("service_large_mesh.py")
            base = session.base_positions

            def pose_to_frame(k: int) -> filigree.Frame:
                return driver.wait_for_pose(driver.send(bend(base, 0.5 + 0.5 * np.sin(0.2 * k)), pose_id=k), timeout=600)

            first = pose_to_frame(1)
            if first.positions.shape != (session.vertex_count, 3):
                raise RuntimeError(f"the first frame has {first.positions.shape} positions, not the whole mesh")
            first_frame = time.monotonic()
            latency = []
            for k in range(2, args.poses + 2):
                sent = time.monotonic()
                pose_to_frame(k)
                latency.append(1e3 * (time.monotonic() - sent))
            driver.close()
            driver.free()
            join_start = time.monotonic()
            joined = client.join(session.id, session.viewer_token)
            join_seconds = time.monotonic() - join_start
            joined.free()
            session.free()
        peak, now = status_mib(server.pid, "VmHWM"), status_mib(server.pid, "VmRSS")
    finally:
        server.terminate()
        server.wait(timeout=60)
        shutil.rmtree(directory, ignore_errors=True)

    print(f"# A {len(positions)}-vertex session end to end (Python package), {len(faces)} faces, default server limits\n")
    print(f"Session (tokens and rest mesh) {made - start:.2f} s after the start of the upload; "
          f"rest mesh read again by a join: {join_seconds:.2f} s ({joined.vertex_count} vertices)\n")
    print("| client | vertices | upload MB | upload → session s | session → first frame s | upload → first frame s | "
          "frame p50 ms | frame p99 ms | poses | server peak RSS MiB | server RSS after MiB |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    print(f"| Python | {session.vertex_count} | {len(data) / 1e6:.1f} | {made - start:.2f} | {first_frame - made:.2f} | "
          f"{first_frame - start:.2f} | {np.percentile(latency, 50):.1f} | {np.percentile(latency, 99):.1f} | "
          f"{args.poses} | {peak:.0f} | {now:.0f} |")


if __name__ == "__main__":
    main()
