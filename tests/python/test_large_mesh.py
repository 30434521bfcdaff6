"""A rest mesh too large for one message: on a server with --max-message-mib 1
a 40,962-vertex icosphere's SessionInfo (~1.2 MB of rest mesh) is over half
the limit, so the server answers with a summary (RestMesh.in_parts) and the
library reads the arrays from GetRestMesh in parts. Uploading and joining
must still give the whole mesh, equal to the upload through uploaded_ids."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

import numpy as np
import pytest

import filigree


def icosphere(levels: int) -> tuple[np.ndarray, np.ndarray]:
    """A unit icosphere subdivided `levels` times: 10·4^levels + 2 vertices,
    20·4^levels faces (the C++ tests' test::icosphere builds the same kind)."""
    t = (1 + 5 ** 0.5) / 2
    vertices = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
             [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
             [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    for _ in range(levels):
        midpoints: dict[tuple[int, int], int] = {}

        def middle(a: int, b: int) -> int:
            key = (a, b) if a < b else (b, a)
            if key not in midpoints:
                midpoints[key] = len(vertices)
                vertices.append([(vertices[a][k] + vertices[b][k]) / 2 for k in range(3)])
            return midpoints[key]

        finer = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            finer += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = finer
    p = np.array(vertices, dtype=np.float64)
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p, np.array(faces, dtype=np.uint32)


def off_text(positions: np.ndarray, faces: np.ndarray) -> bytes:
    lines = ["OFF", f"{len(positions)} {len(faces)} 0"]
    lines += [f"{x!r} {y!r} {z!r}" for x, y, z in positions.tolist()]
    lines += [f"3 {a} {b} {c}" for a, b, c in faces.tolist()]
    return ("\n".join(lines) + "\n").encode()


def sorted_triangles(faces: np.ndarray) -> set[tuple[int, ...]]:
    return set(map(tuple, np.sort(faces.astype(np.int64), axis=1).tolist()))


@pytest.fixture(scope="module")
def small_message_server():
    data_dir = tempfile.mkdtemp(prefix="filigree_large_mesh_")
    process = subprocess.Popen([os.environ["FILIGREE_SERVER"], "--listen", "127.0.0.1:0", "--data-dir", data_dir,
                                "--log-level", "warn", "--max-message-mib", "1"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline()
        if not line.startswith("listening on "):
            raise RuntimeError(f"filigree-server did not start: {line!r} {process.stderr.read()}")
        yield line.split()[-1]
    finally:
        process.terminate()
        process.wait(timeout=60)
        shutil.rmtree(data_dir, ignore_errors=True)


def test_a_mesh_too_large_for_one_message_arrives_whole(small_message_server):
    positions, faces = icosphere(6)
    assert len(positions) == 40962 and len(faces) == 81920
    mesh = off_text(positions, faces)
    # The upload itself is ~3.6 MB, over the 1 MiB limit as one message: it goes in chunks.
    assert len(mesh) > 1 << 20
    uploaded = sorted_triangles(faces)
    with filigree.Client(small_message_server) as client:
        with client.create_session(mesh, format="off", client_name="pytest-large") as made:
            with client.join(made.id, made.viewer_token) as joined:
                for session in (made, joined):
                    assert session.vertex_count == len(positions)
                    assert session.rest_positions.shape == (len(positions), 3)
                    assert session.rest_faces.shape == (len(faces), 3)
                    assert session.uploaded_ids.shape == (len(positions),)
                    ids = session.uploaded_ids
                    # Every uploaded vertex once, and each where the upload had it.
                    assert np.array_equal(np.sort(ids), np.arange(len(positions), dtype=np.uint32))
                    np.testing.assert_array_equal(session.rest_positions, positions[ids].astype(np.float32))
                    # The same triangles, in the upload's numbering.
                    assert sorted_triangles(ids[session.rest_faces]) == uploaded
                # The rest mesh is what frames are built on: the first frame is the rest, whole.
                with joined.watch() as watcher:
                    frame = watcher.next_frame(60)
                    assert frame.positions.shape == (len(positions), 3)
                    np.testing.assert_allclose(frame.positions, joined.rest_positions, atol=1e-3)
