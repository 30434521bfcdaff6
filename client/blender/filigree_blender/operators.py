"""Upload, Join, Leave and Copy token. Failures are reported in Blender's
report area (self.report), never as tracebacks."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import EnumProperty

from . import client_package, live_link, mesh_exchange, skinned_glb


def _filigree(context):
    preferences = context.preferences.addons[__package__].preferences
    return client_package.load(bpy.path.abspath(preferences.library_path) if preferences.library_path else "")


def _start(link: live_link.LiveLink) -> None:
    link.open()
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
                                  wm.filigree_name, None))
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
        link.close()
        del live_link.LINKS[link.detailed_name]
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


_CLASSES = (FILIGREE_OT_upload, FILIGREE_OT_join, FILIGREE_OT_leave, FILIGREE_OT_copy_token)


def register() -> None:
    for c in _CLASSES:
        bpy.utils.register_class(c)


def unregister() -> None:
    for c in reversed(_CLASSES):
        bpy.utils.unregister_class(c)
