"""The sidebar panel (View3D > Sidebar > Filigree)."""

from __future__ import annotations

import bpy

from . import live_link


class FILIGREE_PT_session(bpy.types.Panel):
    bl_label = "Filigree"
    bl_idname = "FILIGREE_PT_session"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Filigree"

    def draw(self, context):
        layout = self.layout
        wm = context.window_manager
        obj = context.active_object
        link = live_link.link_of(obj)
        column = layout.column(align=True)
        column.prop(wm, "filigree_server")
        column.prop(wm, "filigree_name")
        error = live_link.ERRORS.get(obj.name) if obj else None
        if error:
            box = layout.box()
            box.alert = True
            box.label(text=error, icon="ERROR")
        if link is None:
            box = layout.box()
            box.label(text="New session from the active mesh", icon="EXPORT")
            box.prop(wm, "filigree_base_vertices")
            box.operator("filigree.upload", icon="EXPORT")
            box = layout.box()
            box.label(text="Someone's session", icon="COMMUNITY")
            box.prop(wm, "filigree_session_id")
            box.prop(wm, "filigree_token")
            box.prop(wm, "filigree_role")
            box.operator("filigree.join", icon="IMPORT")
            return
        box = layout.box()
        box.label(text=f"Session {link.session.id}", icon="LINKED")
        box.label(text=f"{link.role.title()} · frame {link.version} · {link.frames} received")
        box.label(text=f"{link.session.vertex_count} vertices, base {link.session.base_vertex_count}")
        if link.base_name:
            box.label(text=f"Edit {link.base_name}", icon="EDITMODE_HLT")
        detailed = bpy.data.objects.get(link.detailed_name)
        if detailed is not None and link.role == live_link.EDITOR:
            box.prop(detailed, "filigree_threshold")
        box.prop(wm, "filigree_rate")
        row = box.row(align=True)
        row.operator("filigree.copy_token", text="Viewer token", icon="COPYDOWN").which = "VIEWER"
        row.operator("filigree.copy_token", text="Editor token", icon="COPYDOWN").which = "EDITOR"
        box.operator("filigree.leave", icon="UNLINKED")
        people = layout.box()
        people.label(text="Participants", icon="COMMUNITY")
        if not link.participants:
            people.label(text="No changes yet")
        for p in sorted(link.participants.values(), key=lambda p: -p.seen_version):
            you = " (you)" if p.name == link.client_name else ""
            people.label(text=f"{p.name}{you} · pose {p.pose_id} · {p.vertex_count} v · frame {p.seen_version}")


def register() -> None:
    bpy.utils.register_class(FILIGREE_PT_session)


def unregister() -> None:
    bpy.utils.unregister_class(FILIGREE_PT_session)
