"""Levels of detail from Python and the CLI: a watcher with a vertex budget
gets the level's mesh and frames of its vertices where the full frame puts
them; set_detail moves it to another level; `filigree watch --max-vertices`
writes the posed level mesh."""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

import filigree

TIMEOUT = 30.0

# Budgets and the level each gets on bunny_small with a base of 150 of its
# 1839 vertices: a power of two at most the budget, the base below its size,
# the full mesh at or above it.
CASES = [(1, 150), (200, 150), (300, 256), (1000, 512), (1838, 1024), (1839, 1839), (100000, 1839)]


def bent(session) -> np.ndarray:
    pose = session.base_positions.copy()
    axis = int(np.argmax(np.ptp(pose, axis=0)))
    mid = float(np.median(pose[:, axis]))
    upper = pose[:, axis] > mid
    pose[upper, (axis + 1) % 3] += 0.3 * (pose[upper, axis] - mid)
    return pose


class Latest:
    """A watcher's latest frame, read on when it is not yet what is wanted."""

    def __init__(self, watcher) -> None:
        self.watcher = watcher
        self.frame = None

    def at_least(self, version: int, vertex_count: int = 0) -> filigree.Frame:
        """Its frames until one of at least `version` at a level of
        `vertex_count` vertices (0: any)."""
        while (self.frame is None or self.frame.version < version
               or (vertex_count and self.frame.level.vertex_count != vertex_count)):
            self.frame = self.watcher.next_frame(TIMEOUT)
        return self.frame


def at_one_version(level: Latest, full: Latest, version: int, vertex_count: int = 0):
    """Frames of both at one version, at least `version`: a new level makes
    the session compute a frame for it, so a later frame may follow the one
    a pose asked for."""
    a = level.at_least(version, vertex_count)
    b = full.at_least(a.version)
    while a.version != b.version:
        if a.version < b.version:
            a = level.at_least(b.version, vertex_count)
        else:
            b = full.at_least(a.version)
    return a, b


def assert_at_full_positions(level_frame: filigree.Frame, full: filigree.Frame, session, diagonal) -> None:
    assert level_frame.version == full.version
    level = level_frame.level
    assert level_frame.positions.shape == (level.vertex_count, 3)
    assert full.positions.shape == (session.vertex_count, 3)
    tolerance = level_frame.max_error + full.max_error + 1e-7 * diagonal
    assert np.abs(full.positions[level.original_ids] - session.rest_positions[level.original_ids]).max() > 100 * tolerance, \
        "the pose moved nothing: the comparison proves nothing"
    worst = np.abs(level_frame.positions - full.positions[level.original_ids]).max()
    assert worst <= tolerance, worst


def test_a_watchers_budget_gets_its_level_at_the_full_frames_positions(session, diagonal):
    assert (session.vertex_count, session.base_vertex_count) == (1839, 150)
    watchers = [session.watch(max_vertices=budget) for budget, _ in CASES]
    try:
        with session.watch() as full_watcher, session.drive("pytest") as driver:
            full = Latest(full_watcher)
            posed = driver.wait_for_pose(driver.send(bent(session)), TIMEOUT).version
            for (budget, expected), watcher in zip(CASES, watchers):
                frame, full_frame = at_one_version(Latest(watcher), full, posed)
                level = frame.level
                assert level.vertex_count == expected, budget
                assert watcher.level is level
                assert level.full_detail == (expected == session.vertex_count)
                assert level.original_ids.shape == (expected,) and level.original_ids.dtype == np.uint32
                assert np.all(np.diff(level.original_ids.astype(np.int64)) > 0), "ids ascend"
                assert level.faces.ndim == 2 and level.faces.shape[1] == 3 and level.faces.max() < expected
                np.testing.assert_array_equal(level.rest_positions, session.rest_positions[level.original_ids])
                if level.full_detail:
                    np.testing.assert_array_equal(level.faces, session.rest_faces)
                assert_at_full_positions(frame, full_frame, session, diagonal)
    finally:
        for watcher in watchers:
            watcher.free()


def test_set_detail_moves_a_live_watcher_to_another_level(session, diagonal):
    with session.watch(max_vertices=300) as watcher, session.watch() as full_watcher, \
            session.drive("pytest") as driver:
        level, full = Latest(watcher), Latest(full_watcher)
        assert level.at_least(0).level.vertex_count == 256
        assert watcher.set_detail(1000) == 512
        level.at_least(0, 512)  # with no pose sent
        posed = driver.wait_for_pose(driver.send(bent(session)), TIMEOUT).version
        assert_at_full_positions(*at_one_version(level, full, posed, 512), session, diagonal)
        assert watcher.set_detail(1) == session.base_vertex_count
        posed = driver.wait_for_pose(driver.send(session.base_positions * 1.1), TIMEOUT).version
        assert_at_full_positions(*at_one_version(level, full, posed, session.base_vertex_count), session, diagonal)
        with pytest.raises(ValueError):
            watcher.set_detail(0)
        with pytest.raises(filigree.FailedPrecondition):
            full_watcher.set_detail(512)
    with pytest.raises(ValueError):
        session.watch(max_vertices=-1)


def read_ply(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of the binary PLY `filigree watch -o` writes."""
    data = path.read_bytes()
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:header_end].decode()
    assert "property double x\nproperty double y\nproperty double z\n" in header
    assert "property list uchar uint vertex_indices" in header
    vertices = int(header.split("element vertex ")[1].split()[0])
    faces = int(header.split("element face ")[1].split()[0])
    positions = np.frombuffer(data, dtype="<f8", count=3 * vertices, offset=header_end).reshape(vertices, 3)
    record = np.dtype([("n", "u1"), ("v", "<u4", (3,))])
    face_records = np.frombuffer(data, dtype=record, count=faces, offset=header_end + 24 * vertices)
    assert np.all(face_records["n"] == 3)
    return positions, face_records["v"]


def test_the_cli_writes_the_posed_level_mesh(server, session, diagonal):
    with tempfile.TemporaryDirectory() as tmp, session.watch(max_vertices=600) as watcher, \
            session.watch() as full_watcher, session.drive("pytest") as driver:
        level, full = Latest(watcher), Latest(full_watcher)
        posed = driver.wait_for_pose(driver.send(bent(session)), TIMEOUT).version
        frame, _ = at_one_version(level, full, posed, 512)
        out = Path(tmp) / "level.ply"
        frames = "1" if frame.keyframe else "2"  # a new stream gets the level's keyframe first
        run = subprocess.run([os.environ["FILIGREE_CLI"], "watch", "--server", server.address, "--session", session.id,
                              "--max-vertices", "600", "--frames", frames, "-o", str(out)],
                             env={**os.environ, "FILIGREE_TOKEN": session.viewer_token},  # never an argument
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 0, run.stdout + run.stderr
        lines = run.stdout.splitlines()
        assert lines[0].startswith("level 512 vertices  "), lines
        assert all(" level 512 " in line for line in lines[1:]), lines
        written = int(lines[-1].split()[1])  # the version of the frame written
        positions, faces = read_ply(out)
        frame, full_frame = at_one_version(level, full, written, 512)
        assert frame.version == written
    assert positions.shape == (512, 3)
    np.testing.assert_array_equal(faces, frame.level.faces)
    assert np.abs(positions - frame.level.rest_positions).max() > 0.01 * diagonal, "the pose moved nothing"
    worst = np.abs(positions - frame.positions).max()
    assert worst <= 2 * frame.max_error + 1e-7 * diagonal, worst
    # And where the full frame puts those vertices.
    worst = np.abs(positions - full_frame.positions[frame.level.original_ids]).max()
    assert worst <= frame.max_error + full_frame.max_error + 1e-7 * diagonal, worst
