"""The add-on's settings: where the server is and who you are (window
manager properties, which are not saved in .blend files, so tokens never
travel with a scene), and the threshold of a linked object."""

from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, StringProperty)

from . import live_link


class FiligreePreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    library_path: StringProperty(
        name="libfiligree.so", subtype="FILE_PATH",
        description="Path of the Filigree C library; empty: the system's (after make install)")

    def draw(self, context):
        self.layout.prop(self, "library_path")


class FiligreePerson(bpy.types.PropertyGroup):
    """Someone in a live session (the session's presence), as the panel
    shows them: `name` is their client name."""

    session: StringProperty()
    colour: FloatVectorProperty(subtype="COLOR_GAMMA", size=3, min=0.0, max=1.0,
                                description="Their colour in every client of the session")
    editor: BoolProperty()
    you: BoolProperty()
    idle_seconds: FloatProperty()
    touching: IntProperty(description="Base vertices of their latest change (while under 10 s old)")


def _threshold_changed(obj, context) -> None:
    link = live_link.link_of(obj)
    if link is None or link.role != live_link.EDITOR:
        return
    try:
        link.session.set_threshold(obj.filigree_threshold)
    except Exception as e:  # noqa: BLE001  (an update callback cannot report: the panel shows it)
        live_link.ERRORS[link.detailed_name] = f"threshold: {e}"


_WM_PROPERTIES = {
    "filigree_server": StringProperty(name="Server", default="127.0.0.1:50051",
                                      description="host:port of filigree-server"),
    "filigree_name": StringProperty(name="Name", default="blender",
                                    description="How other participants see your changes"),
    "filigree_session_id": StringProperty(name="Session", description="The session to join"),
    "filigree_token": StringProperty(name="Token", subtype="PASSWORD",
                                     description="The session's editor or viewer token (never saved in the .blend)"),
    "filigree_role": EnumProperty(name="Join as", items=[
        (live_link.EDITOR, "Editor", "Edit the base mesh (needs the editor token)"),
        (live_link.VIEWER, "Viewer", "Watch only")], default=live_link.EDITOR),
    "filigree_base_vertices": IntProperty(name="Base vertices", default=0, min=0,
                                          description="Size of the base mesh to build (0: the server's default)"),
    "filigree_rate": FloatProperty(name="Updates/s", default=30.0, min=1.0, max=120.0,
                                   description="How often edits are sent and frames applied"),
}


def register() -> None:
    bpy.utils.register_class(FiligreePreferences)
    bpy.utils.register_class(FiligreePerson)
    for name, prop in _WM_PROPERTIES.items():
        setattr(bpy.types.WindowManager, name, prop)
    bpy.types.WindowManager.filigree_people = CollectionProperty(type=FiligreePerson)
    bpy.types.Object.filigree_threshold = FloatProperty(
        name="Threshold", default=0.0, min=0.0, update=_threshold_changed,
        description="Performance threshold T of the session's cut: larger is faster, 0 is direct recovery only")


def unregister() -> None:
    live_link.close_all()
    del bpy.types.Object.filigree_threshold
    del bpy.types.WindowManager.filigree_people
    for name in _WM_PROPERTIES:
        delattr(bpy.types.WindowManager, name)
    bpy.utils.unregister_class(FiligreePerson)
    bpy.utils.unregister_class(FiligreePreferences)
