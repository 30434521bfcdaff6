"""The Python package against a live server: sessions, poses, streams,
handles, errors, and frames equal to the C++ client's decoding."""

from __future__ import annotations

import math
import os
import struct
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

import filigree

TIMEOUT = 30.0


def test_the_library_is_the_c_api():
    assert filigree.library_version().count(".") == 2
    assert Path(filigree.library_path()).name.startswith("libfiligree.so")


def test_a_session_has_its_meshes_as_numpy_arrays(session):
    n, m = session.vertex_count, session.base_vertex_count
    assert 0 < m < n
    assert session.rest_positions.shape == (n, 3) and session.rest_positions.dtype == np.float32
    assert session.base_positions.shape == (m, 3)
    assert session.rest_faces.shape[1] == 3 and session.rest_faces.max() < n
    assert session.base_faces.shape[1] == 3 and session.base_faces.max() < m
    # Base vertex j is session vertex base_original_ids[j]: the same point.
    np.testing.assert_array_equal(session.base_positions, session.rest_positions[session.base_original_ids])
    assert sorted(session.uploaded_ids.tolist()) == list(range(n))
    assert session.editor_token and session.viewer_token and session.editor_token != session.viewer_token
    assert session.joints == [] and session.clips == []
    with pytest.raises(ValueError):
        session.rest_positions[0, 0] = 1.0  # the session's copy is read-only


def test_driving_a_translation_moves_every_vertex_by_it(session, diagonal):
    offset = np.array([0.1, -0.05, 0.2], dtype=np.float32) * diagonal
    with session.drive("pytest") as driver:
        rest = driver.wait_for_pose(driver.send(session.base_positions), TIMEOUT)
        assert rest.pose_id == 1
        assert np.abs(rest.positions - session.rest_positions).max() <= rest.max_error + 1e-5 * diagonal
        # The truth of a rigid motion: every detailed vertex moves by the same offset.
        moved = driver.wait_for_pose(driver.send(session.base_positions + offset), TIMEOUT)
        assert moved.version > rest.version
        worst = np.abs(moved.positions - (session.rest_positions + offset)).max()
        assert worst <= moved.max_error + 1e-4 * diagonal, worst
        assert moved.changes == [filigree.Change("pytest", 2, session.base_vertex_count)]


def test_partial_poses_move_only_what_they_name_and_watchers_see_them(session, diagonal):
    with session.watch() as watcher, session.drive("alice") as driver:
        first = watcher.next_frame(TIMEOUT)  # the current frame, at once
        assert first.version == 0
        lift = np.zeros((10, 3), dtype=np.float32)
        lift[:, 1] = 0.05 * diagonal
        pid = driver.send_partial(np.arange(10), session.base_positions[:10] + lift)
        frame = driver.wait_for_pose(pid, TIMEOUT)
        # Base vertex j is detailed vertex base_original_ids[j]: lifted.
        ids = session.base_original_ids[:10]
        np.testing.assert_allclose(frame.positions[ids], session.base_positions[:10] + lift,
                                   atol=frame.max_error + 1e-4 * diagonal)
        far = session.base_original_ids[-1]
        assert abs(frame.positions[far, 1] - session.rest_positions[far, 1]) < 0.05 * diagonal
        # The watcher gets the same frame, with who changed what.
        seen = watcher.next_frame(TIMEOUT)
        while seen.version < frame.version:
            seen = watcher.next_frame(TIMEOUT)
        assert seen.version == frame.version
        assert np.abs(seen.positions - frame.positions).max() <= 2 * frame.max_error + 1e-7 * diagonal
        assert filigree.Change("alice", pid, 10) in seen.changes
        assert watcher.poll() is None  # nothing newer: poll never waits
        assert not watcher.wait_frame(timeout=0.0)


def test_handles_pull_a_vertex_and_can_be_removed(session, diagonal):
    far = int(np.argmax(session.rest_positions[:, 0]))
    target = session.rest_positions[far] + np.array([0.1 * diagonal, 0, 0], dtype=np.float32)
    with session.watch() as watcher:
        start = watcher.next_frame(TIMEOUT)
        assert session.set_handles([far], [target], client_name="bob") == 1
        frame = watcher.next_frame(TIMEOUT)
        assert frame.version > start.version
        assert frame.positions[far, 0] - session.rest_positions[far, 0] > 0.05 * diagonal
        assert any(c.client_name == "bob" for c in frame.changes)
        assert session.set_handles([], np.zeros((0, 3)), client_name="bob") == 0
    with pytest.raises(filigree.InvalidArgument, match="out of range"):
        session.set_handles([session.vertex_count], [target])
    session.set_threshold(0.5)
    with pytest.raises(filigree.InvalidArgument):
        session.set_threshold(-1.0)


def test_errors_carry_the_grpc_status(client, session, server):
    with pytest.raises(filigree.NotFound) as e:
        client.join("no-such-session", "token")
    assert e.value.status == filigree.Status.NOT_FOUND and e.value.code == 5
    # A wrong token is told what an unknown id is told: nothing about the session.
    with pytest.raises(filigree.NotFound) as wrong:
        client.join(session.id, "not-a-token")
    assert "no session" in str(wrong.value)
    with pytest.raises(filigree.InvalidArgument, match="mesh|face|vertex|parse|OBJ|obj"):
        client.create_session(b"v 0 0 0\nf 1 2 3\n", format="obj")
    # A viewer joins and watches but may not drive or edit.
    with client.join(session.id, session.viewer_token) as viewer:
        assert viewer.editor_token == "" and viewer.vertex_count == session.vertex_count
        with pytest.raises(filigree.PermissionDenied):
            viewer.set_threshold(0.5)
        # Refused at send: the joined session knows its token is a viewer's.
        driver = viewer.drive("viewer")
        with pytest.raises(filigree.PermissionDenied, match="viewer token"):
            driver.send(viewer.base_positions)
        driver.free()
    # Wrong pose sizes and NaN are refused before they are sent; the stream goes on.
    with session.drive("pytest") as driver:
        with pytest.raises(filigree.InvalidArgument, match="expected"):
            driver.send(session.base_positions[:-1])
        bad = session.base_positions.copy()
        bad[3, 1] = np.nan
        with pytest.raises(filigree.InvalidArgument, match="not finite"):
            driver.send(bad)
    # A server that is not there.
    with filigree.Client("127.0.0.1:1") as nowhere:
        with pytest.raises(filigree.Unavailable):
            nowhere.join(session.id, session.editor_token)
    assert server.process.poll() is None  # the server is unharmed


def read_ply_positions(path: Path) -> np.ndarray:
    """The vertices `filigree watch -o` writes: binary little-endian doubles."""
    data = path.read_bytes()
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:header_end].decode()
    assert "format binary_little_endian" in header
    assert "property double x\nproperty double y\nproperty double z\n" in header
    count = int(header.split("element vertex ")[1].split()[0])
    return np.frombuffer(data, dtype="<f8", count=3 * count, offset=header_end).reshape(count, 3)


def test_frames_decode_as_the_cpp_client_decodes_them(server, session, diagonal):
    bend = session.base_positions.copy()
    axis = int(np.argmax(np.ptp(bend, axis=0)))
    mid = float(np.median(bend[:, axis]))
    upper = bend[:, axis] > mid
    bend[upper, (axis + 1) % 3] += 0.3 * (bend[upper, axis] - mid)
    with session.drive("pytest") as driver:
        frame = driver.wait_for_pose(driver.send(bend), TIMEOUT)
    assert np.abs(frame.positions - session.rest_positions).max() > 0.01 * diagonal
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "frame.ply"
        frames = "1" if frame.keyframe else "2"  # a new watcher gets the keyframe first
        run = subprocess.run([os.environ["FILIGREE_CLI"], "watch", "--server", server.address, "--session", session.id,
                              "--frames", frames, "-o", str(out)],
                             env={**os.environ, "FILIGREE_TOKEN": session.viewer_token},  # never an argument
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 0, run.stdout + run.stderr
        assert f"version {frame.version}" in run.stdout + run.stderr
        reference = read_ply_positions(out)
    worst = np.abs(reference - frame.positions).max()
    print(f"python vs C++ client: {worst:.3g} (max_error {frame.max_error:.3g})")
    assert worst <= 2 * frame.max_error + 1e-7 * diagonal


def test_skeletal_poses_and_clips_of_a_rigged_upload(client, diagonal):
    with tempfile.TemporaryDirectory() as tmp:
        rigged = Path(tmp) / "bunny_rigged.glb"
        run = subprocess.run([os.environ["FILIGREE_CLI"], "rig", str(Path(__file__).parent.parent / "data" / "bunny_small.obj"),
                              "-o", str(rigged), "--joints", "3"], capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stdout + run.stderr
        with client.create_session(rigged, options=filigree.SessionOptions(base_vertices=150)) as s:
            assert len(s.joints) >= 3 and s.joints[0].parent == -1
            assert {c.name for c in s.clips} >= {"bend"}
            with s.drive("pytest") as driver:
                rest = np.stack([j.rest for j in s.joints])
                at_rest = driver.wait_for_pose(driver.send_joints(rest), TIMEOUT)
                assert np.abs(at_rest.positions - s.rest_positions).max() <= at_rest.max_error + 1e-4 * diagonal
                with pytest.raises(filigree.InvalidArgument):
                    driver.send_joints(rest[:, :9])
            with s.play_clip("bend") as playing:
                frames = list(playing)  # ends after the clip's last sample
            assert len(frames) >= 2
            assert max(np.abs(f.positions - s.rest_positions).max() for f in frames) > 0.01 * diagonal
            duration = next(c.duration for c in s.clips if c.name == "bend")
            assert frames[-1].clip_seconds == pytest.approx(duration, rel=1e-12)  # the last frame shows the end
            with pytest.raises(filigree.NotFound):
                s.play_clip("no-such-clip").next_frame(TIMEOUT)
            check_clip_from_a_start_time_at_most_max_rate(s, duration)


def check_clip_from_a_start_time_at_most_max_rate(s, duration):
    """Each frame of a clip says which clip time it shows, and start_seconds
    and max_rate reach the server: it takes sample k (pose_id) no sooner than
    1/max_rate s after sample k - 1, so at speed 1 its clip time is at least
    start_seconds + (k - 1)/max_rate; the last is at the duration."""
    assert duration > 1.0
    start, rate = duration - 1.0, 5.0  # the clip's last second
    spacing = 1.0 / rate  # clip seconds from one sample to the next, at least (speed 1)
    with s.play_clip("bend", start_seconds=start, max_rate=rate) as playing:
        frames = list(playing)  # the newest when several wait: a subset, the last one included
    shown, samples, last_version = 0.0, 0, None
    for f in frames:
        # (A keyframe the stream had not sent may come before a frame with an older version.)
        if last_version is not None and f.keyframe and f.version < last_version:
            continue
        last_version = f.version
        if f.pose_id == 0:  # the session's frame from before the first sample
            assert f.clip_seconds == 0.0, f
            continue
        assert f.pose_id >= samples
        assert f.clip_seconds >= shown, (f.pose_id, f.clip_seconds, shown)  # never back in a clip that does not loop
        assert f.clip_seconds >= start + (f.pose_id - 1) * spacing - 1e-9, (f.pose_id, f.clip_seconds)
        assert f.clip_seconds <= duration, (f.pose_id, f.clip_seconds)
        samples, shown = f.pose_id, f.clip_seconds
    assert shown == pytest.approx(duration, rel=1e-12)  # the last frame shows the clip's end
    # Samples 1..K-1 lie before the duration (the first at or past it is the
    # last, K), each at least `spacing` after the one before:
    # (K - 2) * spacing < duration - start.
    assert 2 <= samples <= math.floor((duration - start) / spacing) + 2, samples


def test_play_clip_refuses_bad_numbers_at_the_call(session):
    # ValueError before anything reaches the library (which would raise
    # filigree.InvalidArgument, no ValueError; and this session has no
    # skeleton, which the server would tell only on the stream).
    cases = [
        ({"speed": -1.0}, "speed must be finite and >= 0"),
        ({"speed": float("nan")}, "speed must be finite and >= 0"),
        ({"speed": float("inf")}, "speed must be finite and >= 0"),
        ({"max_rate": -5.0}, "max_rate must be finite and >= 0"),
        ({"max_rate": float("nan")}, "max_rate must be finite and >= 0"),
        ({"max_rate": float("inf")}, "max_rate must be finite and >= 0"),
        ({"start_seconds": float("nan")}, "start_seconds must be finite"),
        ({"start_seconds": float("-inf")}, "start_seconds must be finite"),
    ]
    for arguments, names in cases:
        with pytest.raises(ValueError, match=names):
            session.play_clip("bend", **arguments)
    # The token was play_clip's fourth parameter before start_seconds: by
    # position it is refused, and the error does not repeat it.
    with pytest.raises(TypeError, match="start_seconds must be a number") as refused:
        session.play_clip("bend", 1.0, False, session.editor_token)
    assert session.editor_token not in str(refused.value)
    # Zeros are valid (speed 0 means 1): the stream then ends because this
    # session has no skeleton, as the server says.
    with pytest.raises(filigree.FailedPrecondition):
        session.play_clip("bend", speed=0.0, start_seconds=0.0, max_rate=0.0).next_frame(TIMEOUT)


def test_a_half_closed_drive_still_gets_the_frame_of_its_last_pose(session, diagonal):
    driver = session.drive("closer")
    for k in range(1, 6):
        last = driver.send(session.base_positions + np.float32(0.01 * k * diagonal))
    driver.close()  # no more poses: the server ends the stream once a frame includes the last one
    frame = driver.poll()
    assert frame is not None and frame.pose_id == last, frame
    offset = np.float32(0.05 * diagonal)
    assert np.abs(frame.positions - (session.rest_positions + offset)).max() <= frame.max_error + 1e-4 * diagonal
    driver.free()


def test_a_bad_pose_raises_at_send_and_the_driver_goes_on(session):
    # An engine that gets one NaN from physics keeps its link: the pose is
    # refused at send (naming the base vertex), the next one is answered.
    with session.drive("nan-once") as driver:
        bad = np.array(session.base_positions, dtype=np.float32, copy=True)
        bad[5, 2] = np.nan
        with pytest.raises(filigree.InvalidArgument, match="base vertex 5's z is not finite"):
            driver.send(bad)
        good = np.array(session.base_positions, dtype=np.float32, copy=True)
        good[5, 2] += 0.01
        frame = driver.wait_for_pose(driver.send(good), TIMEOUT)
        assert frame.pose_id >= driver.last_pose_id
