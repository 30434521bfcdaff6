"""Upload, Join, Leave, Copy token, and Undo and Redo in the session (bound
to Ctrl+Z and Ctrl+Shift+Z in the 3D View while a live object is active).
Failures are reported in Blender's report area (self.report), never as
tracebacks."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import EnumProperty

from . import client_package, live_link, mesh_exchange, skinned_glb


def _filigree(context):
    preferences = context.preferences.addons[__package__].preferences
    return client_package.load(bpy.path.abspath(preferences.library_path) if preferences.library_path else "")


def _start(link: live_link.LiveLink, joined: bool = False) -> None:
    link.open(joined)
    live_link.ERRORS.pop(link.detailed_name, None)
    live_link.LINKS[link.detailed_name] = link
    live_link.start_timer()


class _Reporting:
    """execute() runs run(); what fails is reported, and the operator cancelled."""

    def execute(self, context):
        try:
            return self.run(context)
        except ImportError as e:
            self.report({"ERROR"}, f"Filigree is not installed: {e}")
        except Exception as e:  # noqa: BLE001  (a FiligreeError says what the server refused)
            status = getattr(e, "status", None)
            prefix = f"{status.name}: " if status is not None else ""
            self.report({"ERROR"}, f"Filigree: {prefix}{getattr(e, 'message', None) or e}")
        return {"CANCELLED"}


class FILIGREE_OT_upload(_Reporting, bpy.types.Operator):
    """Upload the active mesh object, make its base mesh, and follow the base's edits live"""

    bl_idname = "filigree.upload"
    bl_label = "Upload"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "MESH" and live_link.link_of(obj) is None

    def run(self, context):
        filigree = _filigree(context)
        wm = context.window_manager
        obj = context.active_object
        if obj.mode == "EDIT":
            obj.update_from_editmode()
        # With an armature, the skin goes up too (a skinned GLB): its poses then travel as joints.
        armature = mesh_exchange.armature_of(obj)
        data, format = ((skinned_glb.skinned_glb(obj, armature), "glb") if armature
                        else (mesh_exchange.obj_bytes(obj.data), "obj"))
        client = filigree.Client(wm.filigree_server)
        session = client.create_session(data, format=format,
                                        options=filigree.SessionOptions(base_vertices=wm.filigree_base_vertices),
                                        client_name=wm.filigree_name)
        base = mesh_exchange.new_object(f"{obj.name}.base", session.base_positions, session.base_faces, obj,
                                        obj.users_collection[0] if obj.users_collection else context.collection)
        base.display_type = "WIRE"
        scatter = np.asarray(session.uploaded_ids, dtype=np.int64)  # session vertex i is Blender vertex scatter[i]
        skinned = mesh_exchange.carry_skin(obj, base, scatter[np.asarray(session.base_original_ids, dtype=np.int64)])
        obj["filigree_session"] = base["filigree_session"] = session.id
        wm.filigree_session_id = session.id
        wm.filigree_token = session.editor_token
        _start(live_link.LiveLink(session, obj.name, base.name, live_link.EDITOR, wm.filigree_name, scatter,
                                  armature_name=armature.name if armature else None,
                                  source_name=obj.name if armature else None))
        self.report({"INFO"}, f"Filigree: session {session.id}: {session.vertex_count} vertices, "
                              f"base {session.base_vertex_count}" + (f"; {len(session.joints)} joints: the armature poses it" if skinned else ""))
        return {"FINISHED"}


class FILIGREE_OT_join(_Reporting, bpy.types.Operator):
    """Join a session someone else made, with its editor or viewer token"""

    bl_idname = "filigree.join"
    bl_label = "Join"

    def run(self, context):
        filigree = _filigree(context)
        wm = context.window_manager
        if not wm.filigree_session_id or not wm.filigree_token:
            self.report({"ERROR"}, "Filigree: give the session id and a token to join")
            return {"CANCELLED"}
        client = filigree.Client(wm.filigree_server)
        session = client.join(wm.filigree_session_id, wm.filigree_token)
        collection = context.collection
        detailed = mesh_exchange.new_object(f"Filigree {session.id[:8]}", session.rest_positions, session.rest_faces,
                                            None, collection)
        base = None
        if wm.filigree_role == live_link.EDITOR:
            base = mesh_exchange.new_object(f"{detailed.name}.base", session.base_positions, session.base_faces,
                                            detailed, collection)
            base.display_type = "WIRE"
            base["filigree_session"] = session.id
        detailed["filigree_session"] = session.id
        for obj in context.selected_objects:
            obj.select_set(False)
        detailed.select_set(True)
        context.view_layer.objects.active = detailed  # the panel shows the session at once
        _start(live_link.LiveLink(session, detailed.name, base.name if base else None, wm.filigree_role,
                                  wm.filigree_name, None), joined=True)
        self.report({"INFO"}, f"Filigree: joined {session.id} as {wm.filigree_role.lower()}")
        return {"FINISHED"}


class FILIGREE_OT_leave(_Reporting, bpy.types.Operator):
    """Stop following the session (it goes on on the server for the others)"""

    bl_idname = "filigree.leave"
    bl_label = "Leave"

    @classmethod
    def poll(cls, context):
        return live_link.link_of(context.active_object) is not None

    def run(self, context):
        link = live_link.link_of(context.active_object)
        try:
            link.end_gesture(context.evaluated_depsgraph_get())  # the last edit goes out first
        finally:
            link.close()
            del live_link.LINKS[link.detailed_name]
            live_link.show_people(context.window_manager)
        return {"FINISHED"}


class FILIGREE_OT_copy_token(_Reporting, bpy.types.Operator):
    """Copy a token of this session to the clipboard, to share it"""

    bl_idname = "filigree.copy_token"
    bl_label = "Copy token"

    which: EnumProperty(items=[("VIEWER", "Viewer", "Lets others watch"), ("EDITOR", "Editor", "Lets others edit")])

    @classmethod
    def poll(cls, context):
        link = live_link.link_of(context.active_object)
        return link is not None and bool(link.session.editor_token)

    def run(self, context):
        link = live_link.link_of(context.active_object)
        context.window_manager.clipboard = (link.session.viewer_token if self.which == "VIEWER"
                                            else link.session.editor_token)
        self.report({"INFO"}, f"Filigree: {self.which.lower()} token copied")
        return {"FINISHED"}


def not_undoable(link) -> str:
    """Why the session's undo is not the one for this link ('' when it is)."""
    if link.role != live_link.EDITOR or not link.base_name:
        return "Filigree: a viewer has no changes to undo in the session; Blender's undo runs"
    if link.skinned:
        return ("Filigree: an armature poses this session: its bones are Blender's, so Blender's undo runs "
                "(the pose it brings back is sent as a new change)")
    return ""


class _SessionUndo(_Reporting):
    """Undo or redo of this client's latest gesture in the session (the
    others' later work on the same base vertices stays, and is named)."""

    bl_options = set()  # not registered: no Blender undo step, and no gesture boundary of its own
    redo = False

    force: bpy.props.BoolProperty(
        name="Force", default=False,
        description="Also restore base vertices someone else changed since (their change is overwritten there)")

    @classmethod
    def poll(cls, context):
        return live_link.link_of(context.active_object) is not None

    def invoke(self, context, event):
        # From Ctrl+Z: where the session's undo is not the one, Blender's runs instead.
        link = live_link.link_of(context.active_object)
        why = not_undoable(link)
        if why:
            link.note = why
            self.report({"INFO"}, why)
            return {"PASS_THROUGH"}
        return self.execute(context)

    def run(self, context):
        link = live_link.link_of(context.active_object)
        why = not_undoable(link)
        if why:
            self.report({"ERROR"}, why)
            return {"CANCELLED"}
        outcome = link.undo(context.evaluated_depsgraph_get(), redo=self.redo, force=self.force)
        # done, nothing: as planned; partial, conflict: others' work stayed, said as a warning.
        self.report({"INFO" if outcome.result in ("done", "nothing") else "WARNING"}, f"Filigree: {link.note}")
        return {"FINISHED"}


class FILIGREE_OT_undo(_SessionUndo, bpy.types.Operator):
    """Undo your latest change to the session (Ctrl+Z in the 3D View while a live object is active)"""

    bl_idname = "filigree.undo"
    bl_label = "Undo in session"


class FILIGREE_OT_redo(_SessionUndo, bpy.types.Operator):
    """Redo your latest change undone in the session (Ctrl+Shift+Z in the 3D View while a live object is active)"""

    bl_idname = "filigree.redo"
    bl_label = "Redo in session"
    redo = True


_CLASSES = (FILIGREE_OT_upload, FILIGREE_OT_join, FILIGREE_OT_leave, FILIGREE_OT_copy_token, FILIGREE_OT_undo,
            FILIGREE_OT_redo)

# Ctrl+Z and Ctrl+Shift+Z in the 3D View's main region: its keymaps are
# looked at before the window's, where Blender's own undo is bound, and an
# operator whose poll fails (no live object active) lets the key through.
KEYS = (("filigree.undo", {"type": "Z", "value": "PRESS", "ctrl": True}),
        ("filigree.redo", {"type": "Z", "value": "PRESS", "ctrl": True, "shift": True}))
_keymap_items = []


def register() -> None:
    for c in _CLASSES:
        bpy.utils.register_class(c)
    keyconfig = bpy.context.window_manager.keyconfigs.addon
    if keyconfig is not None:
        keymap = keyconfig.keymaps.new(name="3D View", space_type="VIEW_3D")
        for idname, key in KEYS:
            _keymap_items.append((keymap, keymap.keymap_items.new(idname, **key)))
    live_link.add_handlers()


def unregister() -> None:
    live_link.remove_handlers()
    for keymap, item in _keymap_items:
        keymap.keymap_items.remove(item)
    _keymap_items.clear()
    for c in reversed(_CLASSES):
        bpy.utils.unregister_class(c)
