"""Runs in Blender with its window (under Xvfb, tests/blender/run.sh, with
--enable-event-simulate): Ctrl+Z and Ctrl+Shift+Z pressed over the 3D View
reach the add-on's keymap before Blender's own undo, so they undo and redo
alice's gesture in the session; with another object active the same key is
Blender's undo (the session's history gets no undo). Steps run from a timer,
as events are only handled between them; the outcome goes to RESULT ("ok",
or the failure), which run.sh reads."""

import sys
import time
import traceback
from pathlib import Path

import bmesh
import bpy
import numpy as np

address, zip_path, mesh_path, result_path = sys.argv[sys.argv.index("--") + 1:]
TIMEOUT = 30.0

bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
bpy.ops.preferences.addon_enable(module="filigree_blender")
from filigree_blender import client_package, live_link, mesh_exchange  # noqa: E402

filigree = client_package.load()


def check(condition, message):
    if not condition:
        raise AssertionError(message)


def view3d():
    """The window, the 3D View's area and its main region."""
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    return window, area, next(r for r in area.regions if r.type == "WINDOW")


def press(key, **modifiers):
    """A key pressed and released with the mouse over the 3D View's middle."""
    window, _, region = view3d()
    x, y = region.x + region.width // 2, region.y + region.height // 2
    window.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
    window.event_simulate(type=key, value="PRESS", x=x, y=y, **modifiers)
    window.event_simulate(type=key, value="RELEASE", x=x, y=y, **modifiers)


def script():
    """The steps; each yield lets Blender handle events for that many seconds."""
    window, area, region = view3d()
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    vertices, faces = [], []
    for line in Path(mesh_path).read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    positions = np.array(vertices, dtype=np.float32)
    bunny = mesh_exchange.new_object("Bunny", positions, np.array(faces), None, bpy.context.scene.collection)
    wm = bpy.context.window_manager
    wm.filigree_server, wm.filigree_name, wm.filigree_base_vertices = address, "alice", 150
    with bpy.context.temp_override(window=window, area=area, region=region, active_object=bunny, object=bunny):
        check(bpy.ops.filigree.upload() == {"FINISHED"}, "upload")
    link = live_link.LINKS["Bunny"]
    base = bpy.data.objects[link.base_name]
    observer = filigree.Client(address).join(link.session.id, link.session.viewer_token)

    def latest():
        entries = [e for e in observer.history().entries if e.author == "alice"]
        return entries[-1] if entries else None

    # alice's gesture: base vertices 0..9 moved by an operator, as the artist would.
    bpy.context.view_layer.objects.active = base
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj == base)
    moved = mesh_exchange.vertex_positions(base.data).copy()
    lift = 0.05 * float(np.ptp(positions, axis=0).max())
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.object.mode_set(mode="EDIT")
        edited = bmesh.from_edit_mesh(base.data)
        for v in edited.verts:
            v.select = v.index < 10
        edited.select_flush_mode()
        bmesh.update_edit_mesh(base.data)
        check(bpy.ops.transform.translate("EXEC_DEFAULT", True, value=(0.0, 0.0, lift)) == {"FINISHED"}, "translate")
    moved[:10, 2] += lift
    deadline = time.monotonic() + TIMEOUT
    while latest() is None:  # the timer sends it
        check(time.monotonic() < deadline, "alice's gesture reached the session")
        yield 0.1
    gesture = latest()
    check(gesture.kind == "pose" and sorted(gesture.base_vertices) == list(range(10)), f"the gesture: {gesture}")

    def wait_for(kind, what):
        deadline = time.monotonic() + TIMEOUT
        while latest().kind != kind:
            check(time.monotonic() < deadline, f"{what}: alice's latest entry is {latest()}")
            yield 0.1

    def base_now():
        return mesh_exchange.posed_positions(base, bpy.context.evaluated_depsgraph_get())

    # Ctrl+Z over the 3D View, the base active in edit mode: the session's undo.
    press("Z", ctrl=True)
    yield from wait_for("undo", "Ctrl+Z")
    check(latest().target == gesture.seq, "Ctrl+Z undid alice's gesture in the session")
    deadline = time.monotonic() + TIMEOUT
    while np.abs(base_now()[:10, 2] - (moved[:10, 2] - lift)).max() > 1e-3 * lift:
        check(time.monotonic() < deadline, "the base followed the undo")
        yield 0.1
    # Ctrl+Shift+Z: the session's redo.
    press("Z", ctrl=True, shift=True)
    yield from wait_for("redo", "Ctrl+Shift+Z")
    deadline = time.monotonic() + TIMEOUT
    while np.abs(base_now()[:10, 2] - moved[:10, 2]).max() > 1e-3 * lift:
        check(time.monotonic() < deadline, "the base followed the redo")
        yield 0.1

    # Another object active: Ctrl+Z is Blender's, the session's history gets no undo.
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.object.mode_set(mode="OBJECT")
    other = mesh_exchange.new_object("Other", positions[:3], np.array([[0, 1, 2]]), None, bpy.context.scene.collection)
    bpy.context.view_layer.objects.active = other
    count = len(observer.history().entries)
    undone = []
    bpy.app.handlers.undo_post.append(lambda *_: undone.append(True))
    press("Z", ctrl=True)
    deadline = time.monotonic() + TIMEOUT
    while not undone:
        check(time.monotonic() < deadline, "Ctrl+Z with another object active ran Blender's undo")
        yield 0.1
    yield 1.0
    entries = observer.history().entries
    check(all(e.kind != "undo" for e in entries[count:]), f"no undo in the session: {entries[count:]}")
    print(f"keys: Ctrl+Z undid entry {gesture.seq} in the session, Ctrl+Shift+Z redid it, the base followed both; "
          f"with another object active Ctrl+Z was Blender's undo ({len(entries) - count} new entries)")


steps = script()


def run():
    try:
        return next(steps)
    except StopIteration:
        Path(result_path).write_text("ok\n")
    except Exception:  # noqa: BLE001  (written for run.sh, which fails on it)
        Path(result_path).write_text(traceback.format_exc())
        print(traceback.format_exc())
    bpy.ops.wm.quit_blender()
    return None


bpy.app.timers.register(run, first_interval=1.0)
