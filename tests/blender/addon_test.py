"""Runs inside Blender (tests/blender/run.sh): the add-on installed and
enabled as a user does, then `upload` (edit the base, check the detailed
object against the server) or `join` (a second process sees that edit)."""

import json
import sys
from pathlib import Path

import bpy
import numpy as np

mode, address, work, zip_path, mesh_path = sys.argv[sys.argv.index("--") + 1:]
work = Path(work)
TIMEOUT = 30.0


def check(condition, message):
    if not condition:
        raise AssertionError(message)


def read_obj(path):
    vertices, faces = [], []
    for line in Path(path).read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.array(vertices, dtype=np.float32), np.array(faces)


bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
bpy.ops.preferences.addon_enable(module="filigree_blender")
from filigree_blender import client_package, live_link, mesh_exchange  # noqa: E402

filigree = client_package.load()
check("vendor" in Path(filigree.__file__).parts, f"the bundled package is used, not {filigree.__file__}")
wm = bpy.context.window_manager
for obj in list(bpy.data.objects):  # the factory scene's cube, camera, light
    bpy.data.objects.remove(obj)


def expect_reported(operator, text):
    """An operator that fails reports an error (in a script, Blender raises it
    as RuntimeError with the report's text): the report says `text`."""
    try:
        result = operator()
    except RuntimeError as e:
        check(text in str(e) and "Traceback" not in str(e), f"reported: {e}")
        print(f"reported as expected: {e}")
        return
    raise AssertionError(f"no error reported ({result})")


def follow(link, pose_id):
    """Applies the link's frames until the one that includes its pose `pose_id`."""
    including = link.driver.wait_for_pose(pose_id, TIMEOUT).version
    while link.version < including:
        check(link.apply_frame(wait=TIMEOUT) is not None, "a frame came")


def frame_reaching(watcher, version):
    frame = watcher.next_frame(TIMEOUT)
    while frame.version < version:
        frame = watcher.next_frame(TIMEOUT)
    return frame


if mode == "upload":
    positions, faces = read_obj(mesh_path)
    diagonal = float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
    bunny = mesh_exchange.new_object("Bunny", positions, faces, None, bpy.context.scene.collection)
    bpy.context.view_layer.objects.active = bunny
    bunny.select_set(True)

    # A server that is not there: reported and cancelled, no traceback, no link.
    wm.filigree_server = "127.0.0.1:1"
    expect_reported(bpy.ops.filigree.upload, "Filigree: UNAVAILABLE")
    check(not live_link.LINKS, "no link after a failed upload")

    wm.filigree_server, wm.filigree_name, wm.filigree_base_vertices = address, "alice", 150
    check(bpy.ops.filigree.upload() == {"FINISHED"}, "upload")
    link = live_link.LINKS["Bunny"]
    base = bpy.data.objects[link.base_name]
    check(len(base.data.vertices) == link.session.base_vertex_count == 150, "the base object is the base mesh")
    bunny.filigree_threshold = 0.5  # the property sets the session's threshold
    check("Bunny" not in live_link.ERRORS, live_link.ERRORS.get("Bunny", ""))

    # Someone else's edit before alice's first: her link sees it (carol, a
    # Python client, pins a vertex with a handle, then lets it go).
    carol = filigree.Client(address).join(link.session.id, link.session.editor_token)
    far = int(np.argmax(carol.rest_positions[:, 0]))
    carol.set_handles([far], [carol.rest_positions[far]], client_name="carol")
    while "carol" not in link.participants:
        check(link.apply_frame(wait=TIMEOUT) is not None, "a frame with carol's change")
    carol.set_handles([], np.zeros((0, 3)), client_name="carol")

    # The artist lifts ten base vertices (object mode, as a sculpt or script would).
    depsgraph = bpy.context.evaluated_depsgraph_get()
    check(link.send_pose(depsgraph, 0.0) == 1, "the rest pose goes first")
    lifted = mesh_exchange.vertex_positions(base.data).copy()
    lifted[:10, 2] += 0.05 * diagonal
    mesh_exchange.set_positions(base, lifted)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    pose_id = link.send_pose(depsgraph, 0.0)
    check(pose_id == 2, f"the edit is sent as pose 2, not {pose_id}")
    check(link.send_pose(depsgraph, 0.0) is None, "an unchanged base is not sent again")
    follow(link, pose_id)

    # Edit mode: what the artist moves there goes out before leaving edit mode.
    import bmesh

    bpy.context.view_layer.objects.active = base
    bpy.ops.object.mode_set(mode="EDIT")
    edited = bmesh.from_edit_mesh(base.data)
    edited.verts.ensure_lookup_table()
    edited.verts[20].co.z += 0.05 * diagonal
    bmesh.update_edit_mesh(base.data)
    pose_id = link.send_pose(bpy.context.evaluated_depsgraph_get(), 0.0)
    check(pose_id is not None, "an edit-mode move is sent")
    follow(link, pose_id)
    check(abs(link.last_sent[20, 2] - (lifted[20, 2] + 0.05 * diagonal)) < 1e-5 * diagonal, "the edit-mode position")
    bpy.ops.object.mode_set(mode="OBJECT")
    lifted = mesh_exchange.vertex_positions(base.data).copy()
    bpy.context.view_layer.objects.active = bunny

    # The timer's step does the same on its own: the next edit goes out, its frame comes in.
    lifted[10:20, 2] += 0.05 * diagonal
    mesh_exchange.set_positions(base, lifted)
    link.last_send_time = 0.0  # as if the throttle's interval had passed
    before = link.version
    check(live_link.tick() is not None, "the timer keeps running while a link is live")
    check(link.last_sent is not None and np.array_equal(link.last_sent, lifted), "the timer sent the edit")
    including = link.driver.wait_for_pose(link.driver.last_pose_id, TIMEOUT).version
    while link.version < including:
        check(link.watcher.wait_frame(TIMEOUT), "a frame for the timer's pose")
        live_link.tick()
    check(link.version > before, "the timer applied the new frame")

    # A shape key of the base: what it shows (the evaluated mesh) goes out.
    base.shape_key_add(name="Basis")
    bulge = base.shape_key_add(name="Bulge", from_mix=False)
    bulge.data[30].co.z += 0.05 * diagonal
    bulge.value = 1.0
    pose_id = link.send_pose(bpy.context.evaluated_depsgraph_get(), 0.0)
    check(pose_id is not None and abs(link.last_sent[30, 2] - (lifted[30, 2] + 0.05 * diagonal)) < 1e-5 * diagonal,
          "the shape key's pose is sent")
    follow(link, pose_id)

    # The detailed object is the server's frame, vertex for vertex (an
    # independent watcher decodes it; session vertex i is Blender vertex uploaded_ids[i]).
    session = link.session
    viewer = filigree.Client(address).join(session.id, session.viewer_token)
    with viewer.watch() as watcher:
        served = frame_reaching(watcher, link.version)
    check(served.version == link.version, f"the watcher got frame {link.version}")
    shown = mesh_exchange.vertex_positions(bunny.data)
    expected = positions.copy()
    expected[session.uploaded_ids] = served.positions
    worst = float(np.abs(shown - expected).max())
    check(worst <= 2 * served.max_error + 1e-6 * diagonal, f"detailed object off the frame by {worst}")
    moved = session.uploaded_ids[session.base_original_ids[[*range(21), 30]]]
    rise = float((shown[moved, 2] - positions[moved, 2]).min())
    check(rise > 0.03 * diagonal, f"the lifted vertices rose by {rise}")
    check("alice" in link.participants, f"participants: {list(link.participants)}")

    print(f"upload: session {session.id}, frame {link.version}, detailed object vs frame {worst:.3g}, "
          f"lifted by >= {rise:.3g}")
    (work / "state.json").write_text(json.dumps({
        "session": session.id, "viewer_token": session.viewer_token, "version": link.version,
        "max_error": float(served.max_error), "diagonal": diagonal}))
    np.save(work / "frame.npy", served.positions)
    bpy.ops.filigree.leave()
    check(not live_link.LINKS, "left")

elif mode == "armature":
    # A skinned bunny: two bones along its longest axis, each half weighted to one.
    positions, faces = read_obj(mesh_path)
    diagonal = float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
    axis = int(np.argmax(np.ptp(positions, axis=0)))
    low, high = float(positions[:, axis].min()), float(positions[:, axis].max())
    mid = 0.5 * (low + high)
    rig = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    bpy.context.scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    center = positions.mean(axis=0)
    point = lambda t: tuple(float(v) for v in np.where(np.arange(3) == axis, t, center))  # noqa: E731
    root = rig.data.edit_bones.new("Root")
    root.head, root.tail = point(low), point(mid)
    tip = rig.data.edit_bones.new("Tip")
    tip.head, tip.tail, tip.parent = point(mid), point(high), root
    bpy.ops.object.mode_set(mode="OBJECT")
    bunny = mesh_exchange.new_object("Bunny", positions, faces, None, bpy.context.scene.collection)
    upper = positions[:, axis] >= mid
    bunny.vertex_groups.new(name="Root").add(np.flatnonzero(~upper).tolist(), 1.0, "REPLACE")
    bunny.vertex_groups.new(name="Tip").add(np.flatnonzero(upper).tolist(), 1.0, "REPLACE")
    bunny.modifiers.new(name="Armature", type="ARMATURE").object = rig
    bpy.context.view_layer.objects.active = bunny
    wm.filigree_server, wm.filigree_name, wm.filigree_base_vertices = address, "rigger", 150
    check(bpy.ops.filigree.upload() == {"FINISHED"}, "upload of a skinned mesh")
    link = live_link.LINKS["Bunny"]
    base = bpy.data.objects[link.base_name]
    check({g.name for g in base.vertex_groups} == {"Root", "Tip"}, "the base carries the skin's groups")
    check(any(m.type == "ARMATURE" and m.object == rig for m in base.modifiers), "and the armature")
    check(not bunny.modifiers["Armature"].show_viewport, "the detailed object is posed by frames, not twice")
    joints = link.session.joints
    check([j.name for j in joints] == ["Root", "Tip"] and [j.parent for j in joints] == [-1, 0],
          f"the upload carried the skeleton: {joints}")

    # Posing the armature poses the base, which goes to the server as a pose.
    bone = rig.pose.bones["Tip"]
    bone.rotation_mode = "XYZ"
    bone.rotation_euler = (0.7, 0.0, 0.0)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    pose_id = link.send_pose(depsgraph, 0.0)
    check(pose_id == 1 and link.last_joints is not None, "the armature's pose was sent as joints")
    follow(link, pose_id)
    # The server skinned the base as Blender does: the detailed mesh passes
    # through the base object Blender's armature posed.
    posed_base = mesh_exchange.posed_positions(base, depsgraph)
    at_base = mesh_exchange.vertex_positions(bunny.data)[link.scatter[link.session.base_original_ids]]
    off = float(np.abs(at_base - posed_base).max())
    check(off < 1e-3 * diagonal, f"the server's skinning differs from Blender's by {off}")
    moved = np.linalg.norm(mesh_exchange.vertex_positions(bunny.data) - positions, axis=1)
    lowest = positions[:, axis] < low + 0.2 * (high - low)
    check(moved[upper].max() > 0.1 * diagonal, f"the tip half swung: {moved[upper].max()}")
    check(moved[lowest].max() < 0.02 * diagonal, f"the root end stayed: {moved[lowest].max()}")
    print(f"armature: tip moved up to {moved[upper].max():.3g}, root end {moved[lowest].max():.3g} "
          f"(diagonal {diagonal:.3g}); base vs Blender's skinning {off:.3g}")
    bpy.ops.filigree.leave()

elif mode == "join":
    state = json.loads((work / "state.json").read_text())
    wm.filigree_server, wm.filigree_name = address, "bob"
    wm.filigree_session_id, wm.filigree_role = state["session"], live_link.VIEWER
    wm.filigree_token = "not-a-token"
    expect_reported(bpy.ops.filigree.join, "Filigree: NOT_FOUND")
    check(not live_link.LINKS, "no link after a refused join")
    wm.filigree_token = state["viewer_token"]
    check(bpy.ops.filigree.join() == {"FINISHED"}, "join")
    (name, link), = live_link.LINKS.items()
    check(link.base_name is None, "a viewer gets no base object to edit")
    # A new watcher may get the current frame's keyframe first (chunked frames).
    while link.version < state["version"]:
        frame = link.apply_frame(wait=TIMEOUT)
        check(frame is not None, "a frame came")
    check(link.version == state["version"], f"the current frame is alice's edit, not {link.version}")
    shown = mesh_exchange.vertex_positions(bpy.data.objects[name].data)
    worst = float(np.abs(shown - np.load(work / "frame.npy")).max())
    check(worst <= 2 * state["max_error"] + 1e-6 * state["diagonal"], f"joined object off alice's frame by {worst}")
    check("alice" in link.participants, f"participants: {list(link.participants)}")
    print(f"join: frame {link.version} as alice left it (off by {worst:.3g}); participants {sorted(link.participants)}")
    bpy.ops.filigree.leave()
