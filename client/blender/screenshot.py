"""Makes docs/blender_addon.png: Blender with its UI (under Xvfb, see
client/blender/screenshot.sh), the add-on's panel on a live session where
"alice" (this Blender) lifted part of the base and "bob" (a Python client)
pulled a vertex with a handle; both are listed as here. For the docs; not a test."""

import sys
from pathlib import Path

import bpy
import numpy as np

address, zip_path, mesh_path, out = sys.argv[sys.argv.index("--") + 1:]

bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
bpy.ops.preferences.addon_enable(module="filigree_blender")
from filigree_blender import client_package, live_link, mesh_exchange  # noqa: E402

# Only the Filigree tab in the sidebar, so that it is the one shown.
def panel_classes(cls=bpy.types.Panel):
    for sub in cls.__subclasses__():
        yield sub
        yield from panel_classes(sub)


for panel in list(panel_classes()):
    if (getattr(panel, "bl_space_type", "") == "VIEW_3D" and getattr(panel, "bl_region_type", "") == "UI"
            and getattr(panel, "bl_category", "") != "Filigree"):
        try:
            bpy.utils.unregister_class(panel)
        except RuntimeError:
            pass


PRESENT = []


def setup():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    vertices, faces = [], []
    for line in Path(mesh_path).read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(x) - 1 for x in line.split()[1:4]])
    bunny = mesh_exchange.new_object("Bunny", np.array(vertices), np.array(faces), None, bpy.context.scene.collection)
    bunny.rotation_euler = (1.5708, 0, 0)
    bpy.context.view_layer.objects.active = bunny
    bunny.select_set(True)
    wm = bpy.context.window_manager
    wm.filigree_server, wm.filigree_name, wm.filigree_base_vertices = address, "alice", 150
    bpy.ops.filigree.upload()
    link = live_link.LINKS["Bunny"]
    base = bpy.data.objects[link.base_name]
    lifted = mesh_exchange.vertex_positions(base.data).copy()
    top = lifted[:, 1] > np.percentile(lifted[:, 1], 80)
    lifted[top, 2] += 2.0
    mesh_exchange.set_positions(base, lifted)
    # bob, from Python, pulls the vertex furthest along x with a handle.
    filigree = client_package.load()
    bob = filigree.Client(address).join(link.session.id, link.session.editor_token)
    far = int(np.argmax(bob.rest_positions[:, 0]))
    bob.set_handles([far], [bob.rest_positions[far] + np.array([2.0, 0, 0], dtype=np.float32)], client_name="bob")
    PRESENT.append(bob.presence("bob"))  # bob is listed as here while it is open
    for area in bpy.context.screen.areas:
        if area.type == "VIEW_3D":
            area.spaces[0].show_region_ui = True
            area.spaces[0].shading.type = "SOLID"
            with bpy.context.temp_override(area=area, region=area.regions[-1]):
                bpy.ops.view3d.view_selected()
    bpy.app.timers.register(open_tab, first_interval=3.0)
    return None


def open_tab():
    """Clicks the sidebar's Filigree tab (--enable-event-simulate): the
    built-in Item tab, made in C, cannot be hidden from Python."""
    window = bpy.context.window_manager.windows[0]
    for area in window.screen.areas:
        if area.type != "VIEW_3D":
            continue
        sidebar = next(r for r in area.regions if r.type == "UI")
        # The tabs run down the sidebar's right edge; Filigree is the second.
        x, y = sidebar.x + sidebar.width - 8, sidebar.y + sidebar.height - 95
        window.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
        window.event_simulate(type="LEFTMOUSE", value="PRESS", x=x, y=y)
        window.event_simulate(type="LEFTMOUSE", value="RELEASE", x=x, y=y)
    bpy.app.timers.register(shoot, first_interval=2.0)
    return None


def shoot():
    window = bpy.context.window_manager.windows[0]
    for area in window.screen.areas:
        area.tag_redraw()
    with bpy.context.temp_override(window=window):
        bpy.ops.screen.screenshot(filepath=out)
    print(f"screenshot: {out}; links {list(live_link.LINKS)}; frames "
          f"{[link.frames for link in live_link.LINKS.values()]}")
    bpy.ops.wm.quit_blender()
    return None


bpy.app.timers.register(setup, first_interval=1.0)
