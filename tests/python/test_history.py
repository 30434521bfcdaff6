"""Working together from Python: undo and redo that keep others' work,
gestures as one entry, checkpoints, presence, the history's export; and the
CLI's history commands (export-history's glTF read back, replay-history),
against a filigree-server started by the fixtures."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

import filigree

TIMEOUT = 30.0


def move(driver, session, vertices, dy, gesture_id):
    """`driver` moves base vertices up by `dy` from rest as one pose of
    gesture `gesture_id`, and waits until a frame includes it (it is merged,
    so in the history)."""
    targets = session.base_positions[vertices].copy()
    targets[:, 1] += dy
    driver.wait_for_pose(driver.send_partial(vertices, targets, gesture_id=gesture_id), TIMEOUT)


def current_pose(session):
    """The merged base pose now: the exported state after the newest entry."""
    newest = session.history(newest=1).entries[-1].seq
    with session.export_history(newest, newest) as states:
        (state,) = list(states)
    return state.base_pose


def heights(session):
    return current_pose(session)[:, 1] - session.base_positions[:, 1]


def expected(session, raised):
    out = np.zeros(session.base_vertex_count, dtype=np.float32)
    for v, h in raised.items():
        out[v] = h
    return out


def test_undo_keeps_others_later_work_and_redo_brings_it_back(session):
    with session.drive("ana") as ana, session.drive("ben") as ben:
        move(ana, session, [1, 2], 0.01, gesture_id=11)
        move(ana, session, [1, 2], 0.03, gesture_id=11)
        move(ben, session, [3], 0.02, gesture_id=21)
        move(ben, session, [2], 0.05, gesture_id=22)
    history = session.history()
    assert [(e.author, e.kind, e.gesture_id) for e in history.entries] == [
        ("ana", "pose", 11), ("ben", "pose", 21), ("ben", "pose", 22)]
    assert history.entries[0].base_vertices.tolist() == [1, 2]
    np.testing.assert_allclose(heights(session), expected(session, {1: 0.03, 2: 0.05, 3: 0.02}), atol=1e-6)

    outcome = session.undo("ana")
    assert outcome.result == "partial" and outcome.changed
    assert outcome.entry == history.entries[0].seq
    assert [(c.author, c.entry, c.base_vertices.tolist()) for c in outcome.conflicts] == [
        ("ben", history.entries[2].seq, [2])]
    assert outcome.message
    np.testing.assert_allclose(heights(session), expected(session, {2: 0.05, 3: 0.02}), atol=1e-6)
    assert session.history().entries[0].undone

    assert session.redo("ana").result == "done"
    np.testing.assert_allclose(heights(session), expected(session, {1: 0.03, 2: 0.05, 3: 0.02}), atol=1e-6)
    nothing = session.redo("ana")
    assert nothing.result == "nothing" and not nothing.changed


def test_a_conflicting_undo_changes_nothing_unless_forced(session):
    with session.drive("ana") as ana, session.drive("ben") as ben:
        move(ana, session, [7], 0.01, gesture_id=1)
        move(ben, session, [7], 0.02, gesture_id=2)
    refused = session.undo("ana")
    assert refused.result == "conflict" and not refused.changed
    assert refused.conflicts[0].author == "ben"
    np.testing.assert_allclose(heights(session), expected(session, {7: 0.02}), atol=1e-6)
    assert session.undo("ana", force=True).result == "done"
    np.testing.assert_allclose(heights(session), expected(session, {}), atol=1e-6)
    with pytest.raises(filigree.PermissionDenied):
        session.undo("ana", token=session.viewer_token)


def test_a_gesture_is_one_entry_and_undoes_as_one(session):
    with session.drive("dragger") as driver:
        with driver.gesture() as first:  # poses well within 0.5 s: without it, one entry with what follows
            assert driver.gesture_id == first != 0
            for k in range(1, 5):
                move(driver, session, [9], 0.01 * k, gesture_id=None)
        assert driver.gesture_id == 0
        with driver.gesture() as second:
            move(driver, session, [10], 0.02, gesture_id=None)
    history = session.history()
    assert [e.gesture_id for e in history.entries] == [first, second]
    assert session.undo("dragger").entry == history.entries[1].seq
    assert session.undo("dragger").entry == history.entries[0].seq
    np.testing.assert_allclose(heights(session), expected(session, {}), atol=1e-6)  # the whole drag

    # Handles: calls of one gesture are one entry.
    rest = session.rest_positions[5]
    for dy in (0.01, 0.02):
        session.set_handles([5], [rest + [0, dy, 0]], client_name="pinner", gesture_id=77)
    handles = [e for e in session.history().entries if e.kind == "handles"]
    assert [(e.author, e.gesture_id) for e in handles] == [("pinner", 77)]


def test_checkpoints_are_made_diffed_restored_and_the_restore_undoes(session):
    with session.drive("ana") as ana, session.drive("ben") as ben:
        move(ana, session, [1], 0.01, gesture_id=1)
        made = session.checkpoint("before the review", client_name="ana")
        move(ben, session, [2, 3], 0.02, gesture_id=2)
    assert made.name == "before the review" and made.after_entry == session.history().entries[0].seq
    diff = session.diff(made)
    assert diff.checkpoint == made.id
    assert diff.base_vertices.tolist() == [2, 3]
    assert diff.max_distance == pytest.approx(0.02, abs=1e-6)
    assert not diff.threshold_differs

    assert session.restore(made.id, client_name="cleo").result == "done"
    np.testing.assert_allclose(heights(session), expected(session, {1: 0.01}), atol=1e-6)
    assert session.diff(made.id).base_vertices.size == 0
    history = session.history()
    assert [(c.id, c.name, c.author) for c in history.checkpoints] == [(made.id, "before the review", "ana")]
    assert (history.entries[-1].kind, history.entries[-1].target, history.entries[-1].author) == (
        "restore", made.id, "cleo")
    assert session.undo("cleo").result == "done"
    np.testing.assert_allclose(heights(session), expected(session, {1: 0.01, 2: 0.02, 3: 0.02}), atol=1e-6)
    with pytest.raises(filigree.NotFound):
        session.restore(made.id + 100)
    with pytest.raises(filigree.InvalidArgument):
        session.checkpoint("")


def next_presence_where(presence, ready):
    """Presences from the stream until one satisfies `ready` (TIMEOUT at most)."""
    while True:
        p = presence.next(TIMEOUT)  # DeadlineExceeded fails the test
        if ready(p):
            return p


def test_presence_shows_who_is_here_their_pointers_and_what_they_touch(session):
    with session.presence("ana") as presence:
        first = next_presence_where(presence, lambda p: "ana" in p)
        assert first.get("ana").colour.startswith("#") and len(first.get("ana").colour) == 7
        session.set_presence([0.5, 0.25, -0.125], vertex=12, client_name="ana")
        pointed = next_presence_where(presence, lambda p: p.get("ana").pointer is not None)
        assert pointed.get("ana").pointer.tolist() == [0.5, 0.25, -0.125]
        assert pointed.get("ana").pointer_vertex == 12
        with session.drive("cleo") as cleo:
            move(cleo, session, [4, 5], 0.01, gesture_id=3)
        touching = next_presence_where(presence, lambda p: "cleo" in p and p.get("cleo").touching.tolist() == [4, 5])
        assert touching.get("cleo").role == "editor"
        session.set_presence(None, client_name="ana")
        next_presence_where(presence, lambda p: p.get("ana").pointer is None)
        presence.close()
        with pytest.raises(filigree.StreamEnded):
            presence.poll()
    with pytest.raises(ValueError):
        session.set_presence([1.0, 2.0])


def watch_current_frame(session, after_version):
    """The first frame a new watcher gets past `after_version`: the current one."""
    with session.watch() as watcher:
        while True:
            frame = watcher.next_frame(TIMEOUT)
            if frame.version > after_version:
                return frame


def test_the_export_gives_the_state_after_each_entry(session, diagonal):
    with session.drive("ana") as ana, session.drive("ben") as ben:
        move(ana, session, [1, 2, 3], 0.05, gesture_id=1)
        move(ben, session, [10], -0.04, gesture_id=2)
    entries = session.history().entries
    current = watch_current_frame(session, entries[-1].version)
    states = list(session.export_history())
    assert [(s.entry, s.author) for s in states] == [(e.seq, e.author) for e in entries]
    assert states[0].base_pose[1, 1] == pytest.approx(session.base_positions[1, 1] + 0.05, abs=1e-6)
    assert states[0].base_pose[10, 1] == pytest.approx(session.base_positions[10, 1], abs=1e-7)
    assert states[1].base_pose[10, 1] == pytest.approx(session.base_positions[10, 1] - 0.04, abs=1e-6)
    assert states[1].positions.shape == (session.vertex_count, 3)
    worst = np.abs(states[-1].positions - current.positions).max()
    assert worst <= states[-1].max_error + current.max_error + 1e-7 * diagonal
    assert np.abs(current.positions - session.rest_positions).max() > 0.01
    with pytest.raises(filigree.InvalidArgument):
        list(session.export_history(5, 2))


# ---------------------------------------------------------------- the CLI


def cli(server, *args, token, extra_env=None):
    """Runs `filigree` with the token in its environment (never an argument)."""
    env = {**os.environ, "FILIGREE_TOKEN": token, **(extra_env or {})}
    run = subprocess.run([os.environ["FILIGREE_CLI"], *args, "--server", server.address], env=env,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    assert token not in run.stdout + run.stderr
    return run.stdout


def read_glb(path):
    """A GLB's JSON and a reader of its accessors (float32/uint32, as numpy)."""
    data = Path(path).read_bytes()
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    json_length, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A
    gltf = json.loads(data[20:20 + json_length])
    bin_at = 20 + json_length
    bin_length, bin_type = struct.unpack_from("<II", data, bin_at)
    assert bin_type == 0x004E4942
    binary = data[bin_at + 8:bin_at + 8 + bin_length]

    def accessor(index):
        a = gltf["accessors"][index]
        view = gltf["bufferViews"][a["bufferView"]]
        columns = {"SCALAR": 1, "VEC3": 3}[a["type"]]
        dtype = {5126: "<f4", 5125: "<u4"}[a["componentType"]]
        assert view.get("byteStride", 4 * columns) == 4 * columns
        offset = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        values = np.frombuffer(binary, dtype=dtype, count=a["count"] * columns, offset=offset)
        return values.reshape(a["count"], columns) if columns > 1 else values

    return gltf, accessor


def test_export_history_writes_a_gltf_animation_with_a_morph_target_per_entry(server, session, diagonal):
    with session.drive("ana") as ana, session.drive("ben") as ben:
        move(ana, session, [1, 2, 3], 0.05, gesture_id=1)
        move(ben, session, [10], -0.04, gesture_id=2)
        move(ana, session, [20, 21], 0.03, gesture_id=3)
    assert session.undo("ben").result == "done"
    entries = session.history().entries
    assert len(entries) == 4
    current = watch_current_frame(session, entries[-1].version)
    exported = list(session.export_history())

    listing = cli(server, "history", session.id, token=session.viewer_token)
    lines = [line.split() for line in listing.splitlines()[1:] if line[:1].isdigit()]
    assert [(int(f[0]), f[1], f[2], int(f[3]), f[4]) for f in lines] == [
        (e.seq, e.author, e.kind, e.base_vertices.size, "yes" if e.undone else "no") for e in entries]

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "anim.glb"
        cli(server, "export-history", session.id, "--fps", "10", "-o", str(out), token=session.viewer_token)
        gltf, accessor = read_glb(out)
    (mesh,) = gltf["meshes"]
    (primitive,) = mesh["primitives"]
    rest = accessor(primitive["attributes"]["POSITION"])
    np.testing.assert_array_equal(rest, session.rest_positions)
    np.testing.assert_array_equal(accessor(primitive["indices"]).reshape(-1, 3), session.rest_faces)
    targets = [accessor(t["POSITION"]) for t in primitive["targets"]]
    assert len(targets) == len(entries), "a morph target per history entry"
    # An animation of as many frames: target k alone at time k / fps.
    (animation,) = gltf["animations"]
    (channel,) = animation["channels"]
    assert channel["target"]["path"] == "weights"
    sampler = animation["samplers"][channel["sampler"]]
    assert sampler["interpolation"] == "STEP"
    np.testing.assert_allclose(accessor(sampler["input"]), np.arange(len(entries)) / 10.0, rtol=1e-6)
    np.testing.assert_array_equal(accessor(sampler["output"]).reshape(len(entries), len(entries)),
                                  np.eye(len(entries)))
    # Each target is its state's deltas; the last one is the session's current frame.
    for target, state in zip(targets, exported):
        assert np.abs(rest + target - state.positions).max() <= 1e-6 * diagonal
    worst = np.abs(rest + targets[-1] - current.positions).max()
    print(f"last morph target vs the current frame: {worst:.3g} (max_error {exported[-1].max_error:.3g} + "
          f"{current.max_error:.3g})")
    assert worst <= exported[-1].max_error + current.max_error + 1e-6 * diagonal
    assert np.abs(targets[-1]).max() > 0.01


def test_undo_checkpoint_and_replay_history_from_the_cli(server, client, session):
    with session.drive("ana") as ana, session.drive("ben") as ben:
        move(ana, session, [1, 2], 0.05, gesture_id=1)
        move(ben, session, [10], -0.04, gesture_id=2)
    editor = session.editor_token
    made = cli(server, "checkpoint", "create", session.id, "two edits", "--client", "ana", token=editor)
    checkpoint = int(made.split("checkpoint: ")[1].split()[0])
    undone = cli(server, "undo", session.id, "--client", "ben", token=editor)
    assert "result: done" in undone
    assert "vertices_differing: 1" in cli(server, "checkpoint", "diff", session.id, str(checkpoint), token=editor)
    assert "result: done" in cli(server, "redo", session.id, "--client", "ben", token=editor)
    source_pose = current_pose(session)

    # The same mesh and base size: the same base, so the poses replay.
    other = client.create_session(Path(__file__).resolve().parent.parent / "data" / "bunny_small.obj",
                                  options=filigree.SessionOptions(base_vertices=150), client_name="pytest")
    try:
        cli(server, "replay-history", session.id, "--into", other.id, token=session.viewer_token,
            extra_env={"FILIGREE_INTO_TOKEN": other.editor_token})
        replayed = other.history().entries
        # Every state whose pose changed, by its author (the checkpoint is no entry).
        assert [e.author for e in replayed] == ["ana", "ben", "ben", "ben"]
        np.testing.assert_allclose(current_pose(other), source_pose, atol=1e-7)
        # Each replayed state is its own entry: the replayer's undo of Ben's last takes back one.
        assert other.undo("ben").result == "done"
    finally:
        other.free()
