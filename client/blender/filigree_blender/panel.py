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
        if link.role == live_link.EDITOR and link.base_name:
            history = layout.box()
            history.label(text="Your changes", icon="LOOP_BACK")
            row = history.row(align=True)
            row.enabled = not link.skinned
            row.operator("filigree.undo", text="Undo", icon="LOOP_BACK")
            row.operator("filigree.redo", text="Redo", icon="LOOP_FORWARDS")
            for line in (["Ctrl+Z, Ctrl+Shift+Z", "over the 3D View"] if not link.skinned
                         else ["Posed by an armature:", "Ctrl+Z is Blender's"]):
                history.label(text=line)
            if link.note:
                for line in _wrap(link.note, 30):
                    history.label(text=line)
            if link.refused:
                force = history.operator(f"filigree.{link.refused}", text=f"{link.refused.title()} anyway",
                                         icon="ERROR")
                force.force = True
        here = layout.box()
        here.label(text="In the session", icon="COMMUNITY")
        present = [p for p in wm.filigree_people if p.session == link.session.id]
        if link.presence is None:
            here.label(text="(this filigree package shows no presence)")
        elif not present:
            here.label(text="Waiting for the server…")
        for person in sorted(present, key=lambda p: (not p.you, p.name)):
            row = here.row(align=True)
            swatch = row.row()
            swatch.ui_units_x = 1.2
            swatch.prop(person, "colour", text="")
            row.label(text=person.name + (" (you)" if person.you else ""))
            role = "editor" if person.editor else "viewer"
            row.label(text=f"{role} · {person.touching} v" if person.touching
                      else f"{role} · idle {person.idle_seconds:.0f} s")
        people = layout.box()
        people.label(text="Latest changes", icon="MOD_HUE_SATURATION")
        if not link.participants:
            people.label(text="No changes yet")
        for p in sorted(link.participants.values(), key=lambda p: -p.seen_version):
            you = " (you)" if p.name == link.client_name else ""
            people.label(text=f"{p.name}{you} · pose {p.pose_id} · {p.vertex_count} v · frame {p.seen_version}")


def _wrap(text: str, width: int) -> list[str]:
    """Lines of at most about `width` characters (a label does not wrap)."""
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return lines + ([line] if line else [])


def register() -> None:
    bpy.utils.register_class(FILIGREE_PT_session)


def unregister() -> None:
    bpy.utils.unregister_class(FILIGREE_PT_session)
