"""Runs inside Blender (tests/blender/run.sh): the add-on installed and
enabled as a user does, then `upload` (edit the base, check the detailed
object against the server), `join` (a second process sees that edit),
`armature` (a skinned upload posed by its bones), `undo` (gestures,
the session's undo and redo from Blender, presence) or `export` (the undo
session's history, exported by the CLI, imported as an animation)."""

import json
import sys
import time
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
    check(link.send_pose(depsgraph, 0.0) is None, "nothing goes out before the base changes")
    lifted = mesh_exchange.vertex_positions(base.data).copy()
    lifted[:10, 2] += 0.05 * diagonal
    mesh_exchange.set_positions(base, lifted)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    pose_id = link.send_pose(depsgraph, 0.0)
    check(pose_id == 1, f"the edit is sent as pose 1, not {pose_id}")
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
    # Its bones are Blender's data: the session's undo is not the one for it.
    bpy.context.view_layer.objects.active = base
    expect_reported(bpy.ops.filigree.undo, "an armature poses this session")
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

elif mode == "undo":
    positions, faces = read_obj(mesh_path)
    diagonal = float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
    bunny = mesh_exchange.new_object("Bunny", positions, faces, None, bpy.context.scene.collection)
    bpy.context.view_layer.objects.active = bunny
    wm.filigree_server, wm.filigree_name, wm.filigree_base_vertices = address, "alice", 150
    check(bpy.ops.filigree.upload() == {"FINISHED"}, "upload")
    link = live_link.LINKS["Bunny"]
    base = bpy.data.objects[link.base_name]
    session = link.session

    # Ctrl+Z / Ctrl+Shift+Z in the 3D View are the add-on's undo and redo.
    keymap = wm.keyconfigs.addon.keymaps["3D View"]
    bound = {(k.idname, k.type, k.value, k.ctrl, k.shift, k.alt) for k in keymap.keymap_items}
    check({("filigree.undo", "Z", "PRESS", True, False, False), ("filigree.redo", "Z", "PRESS", True, True, False)}
          <= bound, f"the 3D View's keymap binds {bound}")

    # carol: another editor (a Python client) who reads the history and a watcher's frames.
    carol = filigree.Client(address).join(session.id, session.editor_token)
    watcher = carol.watch()

    def alice_entries():
        return [e for e in carol.history().entries if e.author == "alice"]

    def step():
        """The timer's step, as if the throttle's interval had passed."""
        link.last_send_time = 0.0
        check(live_link.tick() is not None, "the timer runs")

    def settle():
        """Frames until the link has the one that includes its last pose, or its base followed an undo."""
        if link.resync_after is not None:
            while link.resync_after is not None:
                check(link.apply_frame(wait=TIMEOUT) is not None, "a frame with the undo")
        elif link.driver.last_pose_id:
            follow(link, link.driver.last_pose_id)
        return mesh_exchange.posed_positions(base, bpy.context.evaluated_depsgraph_get()).copy()

    import bmesh

    def select(indices):
        edited = bmesh.from_edit_mesh(base.data)
        for v in edited.verts:
            v.select = False
        edited.verts.ensure_lookup_table()
        for i in indices:
            edited.verts[i].select = True
        edited.select_flush_mode()
        bmesh.update_edit_mesh(base.data)

    def translate(dz, registered):
        """A move of the selection; `registered` as an operator the artist ran
        (it registers, and Blender pushes an undo step), else a drag's middle."""
        check(bpy.ops.transform.translate("EXEC_DEFAULT", registered, value=(0.0, 0.0, dz)) == {"FINISHED"},
              "translate")

    rise = 0.04 * diagonal
    first, second = list(range(0, 8)), list(range(4, 12))  # overlapping on 4..7
    bpy.context.view_layer.objects.active = base
    bpy.ops.object.mode_set(mode="EDIT")
    rest = settle()

    # Gesture 1: a drag the timer sees at three moments 0.6 s apart (the
    # server would make three entries of them without the gesture id), ended
    # by the operator finishing (it registers: Blender's undo step).
    select(first)
    for _ in range(2):
        translate(rise, registered=False)
        step()
        time.sleep(0.6)
    translate(rise, registered=True)
    step()  # the finished operator: its last step goes with gesture 1, which ends
    after_first = settle()
    check(np.allclose(after_first[first, 2], rest[first, 2] + 3 * rise, atol=1e-5 * diagonal), "the drag rose 3 steps")
    reference_first = frame_reaching(watcher, link.version)

    # Gesture 2 right after (well within 0.5 s of gesture 1's last pose:
    # without gesture ids the server would join the two).
    select(second)
    translate(rise, registered=True)
    step()
    after_second = settle()
    entries = alice_entries()
    check(len(entries) == 2, f"two gestures are two entries, not {len(entries)}: "
          f"{[(e.seq, list(e.base_vertices), e.gesture_id) for e in entries]}")
    check(sorted(entries[0].base_vertices) == first and sorted(entries[1].base_vertices) == second,
          f"the entries' vertices: {[sorted(e.base_vertices) for e in entries]}")
    check(0 != entries[0].gesture_id != entries[1].gesture_id != 0, "each gesture has its own id")

    # Ctrl+Z with the base active in edit mode: the session's undo of alice's latest gesture.
    check(bpy.ops.filigree.undo.poll(), "the add-on's undo is the one for the live base")
    check(bpy.ops.filigree.undo() == {"FINISHED"}, "undo")
    shown = settle()
    entries = alice_entries()
    check(entries[1].undone and not entries[0].undone, "the session's history has gesture 2 undone")
    check(entries[-1].kind == "undo" and entries[-1].target == entries[1].seq,
          f"the newest entry is alice's undo of gesture 2: {entries[-1]}")
    error = float(reference_first.max_error)
    off = back = float(np.abs(shown - after_first).max())
    check(off <= 2 * error + 1e-6 * diagonal, f"the base is back where gesture 1 left it (off by {off})")
    served = frame_reaching(watcher, link.version)
    detailed = mesh_exchange.vertex_positions(bunny.data)[link.scatter]
    rms_back = float(np.sqrt(np.mean(np.sum((served.positions - reference_first.positions) ** 2, axis=1))))
    rms_shown = float(np.sqrt(np.mean(np.sum((detailed - served.positions) ** 2, axis=1))))
    check(rms_back <= error, f"the session's frame is gesture 1's again (RMS {rms_back}, max_error {error})")
    check(rms_shown <= error, f"the detailed object shows it (RMS {rms_shown})")
    # The base following the undo is no change of alice's: nothing goes out.
    step()
    check(len(alice_entries()) == 3, "the followed base was not sent back")

    # Ctrl+Shift+Z: gesture 2 again.
    check(bpy.ops.filigree.redo() == {"FINISHED"}, "redo")
    shown = settle()
    off = float(np.abs(shown - after_second).max())
    check(off <= 2 * error + 1e-6 * diagonal, f"redo: the base is where gesture 2 left it (off by {off})")
    check(alice_entries()[-1].kind == "redo", "the history has the redo")

    # carol changes one of gesture 2's vertices; alice's undo then keeps
    # carol's work there, restores the rest, and says whose work stayed.
    kept = second[-1]
    carol_driver = carol.drive("carol")
    carol_target = after_second[kept] + np.array([0.0, 0.0, rise], dtype=np.float32)
    carol_driver.wait_for_pose(carol_driver.send_partial([kept], carol_target[None]), TIMEOUT)
    check(bpy.ops.filigree.undo() == {"FINISHED"}, "undo over carol's change")
    shown = settle()
    check("carol" in link.note, f"the undo names carol: {link.note}")
    partial_note = link.note
    expected = after_first.copy()
    expected[kept] = carol_target
    off = float(np.abs(shown - expected).max())
    check(off <= 2 * error + 1e-6 * diagonal, f"carol's vertex kept her work, the rest is back (off by {off})")

    # carol then changes every vertex of alice's gesture 1: alice's undo
    # changes nothing and says so; the panel offers to force it, which does.
    carol_driver.wait_for_pose(carol_driver.send_partial(first, after_first[first] + np.float32(rise)), TIMEOUT)
    check(bpy.ops.filigree.undo() == {"FINISHED"} and link.refused == "undo" and link.resync_after is None,
          f"an undo of vertices all changed since is refused: {link.note}")
    check(len([e for e in alice_entries() if e.kind == "undo"]) == 2, "and records nothing")
    check(bpy.ops.filigree.undo(force=True) == {"FINISHED"}, "undo anyway")
    shown = settle()
    expected[first] = rest[first]
    off = float(np.abs(shown - expected).max())
    check(off <= 2 * error + 1e-6 * diagonal, f"the forced undo put gesture 1's vertices back at rest (off by {off})")

    # Another object active: Ctrl+Z is Blender's (the add-on's undo does not poll).
    bpy.ops.object.mode_set(mode="OBJECT")
    other = mesh_exchange.new_object("Other", positions[:3], np.array([[0, 1, 2]]), None, bpy.context.scene.collection)
    bpy.context.view_layer.objects.active = other
    check(not bpy.ops.filigree.undo.poll(), "Ctrl+Z with another object active is Blender's undo")
    # Blender's own undo bringing back an older base (as its memfile undo
    # does; no window here to run ed.undo): sent as a change of its own, and said.
    count = len(alice_entries())
    live_link.before_blender_undo()
    mesh_exchange.set_positions(base, rest)
    live_link.after_blender_undo()
    check("Blender's undo" in link.note, f"the panel says what Blender's undo did: {link.note}")
    settle()
    entries = alice_entries()
    check(len(entries) == count + 1 and entries[-1].kind == "pose",
          "Blender's undo went as one new change")

    # Presence: who is here, with their colours, in the panel's list.
    carol_presence = carol.presence("carol")
    deadline = time.monotonic() + TIMEOUT
    while {p.name for p in wm.filigree_people} != {"alice", "carol"}:
        check(time.monotonic() < deadline, f"presence: {[p.name for p in wm.filigree_people]}")
        live_link.tick()
        time.sleep(0.05)
    truth = {p.client_name: p for p in carol_presence.next(TIMEOUT).participants}
    for person in wm.filigree_people:
        colour = "#" + "".join(f"{round(c * 255):02x}" for c in person.colour)
        check(colour == truth[person.name].colour, f"{person.name}'s colour {colour}, not {truth[person.name].colour}")
        check(person.you == (person.name == "alice") and person.editor, f"{person.name}: you/editor")
    # The panel (drawn into a stand-in layout that records what it shows).
    from filigree_blender import panel

    class Layout:
        def __init__(self, shown):
            self.shown, self.enabled, self.alert, self.ui_units_x = shown, True, False, 0

        def box(self, **_):
            return Layout(self.shown)

        row = column = box

        def label(self, text="", icon="NONE"):
            self.shown.append(("label", text))

        def prop(self, data, name, text=None, **_):
            check(hasattr(data, name), f"the panel shows {name} of {data}")
            self.shown.append(("prop", getattr(data, "name", ""), name))

        def operator(self, idname, text="", icon="NONE"):
            self.shown.append(("operator", idname, text))
            return type("Properties", (), {})()

    link.refused = "undo"
    bpy.context.view_layer.objects.active = base
    shown = []
    panel.FILIGREE_PT_session.draw(type("Panel", (), {"layout": Layout(shown)})(), bpy.context)
    labels = [item[1] for item in shown if item[0] == "label"]
    check({"alice (you)", "carol"} <= set(labels) and any(t.startswith("editor · ") for t in labels),
          f"who is here: {labels}")
    check({("prop", "alice", "colour"), ("prop", "carol", "colour")} <= set(shown), "each with a colour swatch")
    check({("operator", "filigree.undo", "Undo"), ("operator", "filigree.redo", "Redo"),
           ("operator", "filigree.undo", "Undo anyway")} <= set(shown), f"undo, redo, undo anyway: {shown}")
    check(any("Blender's undo" in t for t in labels), "the note")
    print(f"undo: 2 gestures (the first over 3 steps 0.6 s apart) are 2 entries; undo: the base back to gesture 1 "
          f"within {back:.3g} (frame's max_error {error:.3g}), the session's frame RMS {rms_back:.3g} from gesture 1's, "
          f"the detailed object RMS {rms_shown:.3g} from it; redo; an undo keeping carol's vertex "
          f"('{partial_note}'); Blender's undo sent as a change; presence {sorted(p.name for p in wm.filigree_people)}")
    carol_presence.free()
    watcher.free()
    carol_driver.free()
    bpy.ops.object.select_all(action="DESELECT")
    bpy.context.view_layer.objects.active = bunny
    bpy.ops.filigree.leave()
    # The session's history goes on to `export` (run.sh exports it with the CLI in between).
    (work / "undo_state.json").write_text(json.dumps({
        "session": session.id, "viewer_token": session.viewer_token, "diagonal": diagonal}))

elif mode == "export":
    # `filigree export-history` wrote the undo session's history as a glTF
    # animation (run.sh); Blender imports it: one frame per history entry,
    # each the state the session exports for that entry.
    state = json.loads((work / "undo_state.json").read_text())
    viewer = filigree.Client(address).join(state["session"], state["viewer_token"])
    entries = viewer.history().entries
    states = list(viewer.export_history())  # the reference: the session's own full-detail states
    check(len(entries) >= 6 and [s.entry for s in states] == [e.seq for e in entries],
          f"a state per entry: {[s.entry for s in states]} for {[e.seq for e in entries]}")
    with viewer.watch() as watcher:  # the frame that includes the newest entry (a keyframe may come first)
        current = frame_reaching(watcher, entries[-1].version + 1)

    def rms(a, b):
        return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))

    # Float32 coordinates round to this; a state at rest has a max_error below it.
    rounding = 4 * float(np.finfo(np.float32).eps) * float(np.abs(viewer.rest_positions).max())
    off = rms(states[-1].positions, current.positions)
    check(off <= states[-1].max_error + current.max_error + rounding,
          f"the last state is the session's current frame (RMS {off}, frame {current.version})")

    # Blender 3.4's importer with its default shading (from the normals)
    # calls numpy's removed np.bool on Debian's numpy: smooth shading instead.
    check(bpy.ops.import_scene.gltf(filepath=str(work / "history.glb"), import_shading="SMOOTH") == {"FINISHED"},
          "import")
    imported, = [o for o in bpy.data.objects if o.type == "MESH"]
    check(len(imported.data.vertices) == viewer.vertex_count, "the importer kept every vertex")
    action = imported.data.shape_keys.animation_data.action
    frames = sorted({point.co[0] for curve in action.fcurves for point in curve.keyframe_points})
    check(len(frames) == len(entries), f"the animation has {len(frames)} frames for {len(entries)} history entries")

    def file_space(p):  # Blender's Z-up back to glTF's Y-up, the session's own axes
        return np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1)

    rest = file_space(mesh_exchange.vertex_positions(imported.data))
    check(float(np.abs(rest - viewer.rest_positions).max()) <= 1e-6 * state["diagonal"],
          "the imported mesh at rest is the session's, vertex for vertex")
    scene = bpy.context.scene
    worst = 0.0
    for k, frame in enumerate(frames):
        scene.frame_set(int(frame), subframe=frame - int(frame))
        shown = file_space(mesh_exchange.posed_positions(imported, bpy.context.evaluated_depsgraph_get()))
        off = rms(shown, states[k].positions)
        bound = max(states[k].max_error, rounding)
        check(off <= bound, f"frame {frame} (entry {states[k].entry}): RMS {off} over the state's max_error "
                            f"{states[k].max_error}")
        worst = max(worst, off / bound)
    moved = [rms(states[k].positions, viewer.rest_positions) for k in range(len(states))]
    check(len({round(m, 6) for m in moved}) > 2, f"the states differ from one another: {moved}")
    print(f"export: {len(entries)} entries, {len(frames)} frames; each frame's evaluated mesh within "
          f"RMS <= {worst:.3g} × its state's max_error")
