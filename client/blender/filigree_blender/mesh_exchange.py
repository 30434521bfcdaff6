"""Meshes between Blender and Filigree: an object's mesh as OBJ bytes to
upload, and a session's arrays as new mesh objects."""

from __future__ import annotations

import io

import bpy
import numpy as np


def vertex_positions(mesh: "bpy.types.Mesh") -> np.ndarray:
    """The mesh's vertex coordinates, (k, 3) float32, object space."""
    co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def triangles(mesh: "bpy.types.Mesh") -> np.ndarray:
    """The mesh's faces as triangles (f, 3) of vertex indices."""
    mesh.calc_loop_triangles()
    tris = np.empty(3 * len(mesh.loop_triangles), dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def obj_bytes(mesh: "bpy.types.Mesh") -> bytes:
    """The mesh as OBJ (vertices in Blender's order, faces triangulated): the
    session's uploaded_ids then refer to Blender's vertex indices."""
    out = io.BytesIO()
    np.savetxt(out, vertex_positions(mesh).astype(np.float64), fmt="v %.9g %.9g %.9g")
    np.savetxt(out, triangles(mesh) + 1, fmt="f %d %d %d")
    return out.getvalue()


def new_object(name: str, positions: np.ndarray, faces: np.ndarray, like: "bpy.types.Object | None",
               collection: "bpy.types.Collection") -> "bpy.types.Object":
    """A mesh object from arrays, placed as `like` (same world matrix) when given."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(positions.astype(np.float64).tolist(), [], faces.astype(np.int64).tolist())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    if like is not None:
        obj.matrix_world = like.matrix_world.copy()
    collection.objects.link(obj)
    return obj


def set_positions(obj: "bpy.types.Object", positions: np.ndarray) -> None:
    """All vertex coordinates at once (foreach_set), then a redraw."""
    obj.data.vertices.foreach_set("co", np.ascontiguousarray(positions, dtype=np.float32).reshape(-1))
    obj.data.update()


def offset_positions(obj: "bpy.types.Object", indices: np.ndarray, offsets: np.ndarray) -> None:
    """Moves vertices `indices` of `obj` by `offsets` (k × 3) in what the
    artist sees: the edit-mode mesh in edit mode; else the mesh and every
    shape key alike, so the evaluated shape moves by the offsets whatever
    the keys' values."""
    if obj.mode == "EDIT":
        import bmesh
        from mathutils import Vector

        edited = bmesh.from_edit_mesh(obj.data)
        edited.verts.ensure_lookup_table()
        for i, offset in zip(indices.tolist(), offsets.tolist()):
            edited.verts[i].co += Vector(offset)
        bmesh.update_edit_mesh(obj.data)
        return
    blocks = [obj.data] + (list(obj.data.shape_keys.key_blocks) if obj.data.shape_keys else [])
    for block in blocks:
        points = block.vertices if block is obj.data else block.data
        co = np.empty(3 * len(points), dtype=np.float32)
        points.foreach_get("co", co)
        co = co.reshape(-1, 3)
        co[indices] += offsets
        points.foreach_set("co", co.reshape(-1))
    obj.data.update()


def posed_positions(obj: "bpy.types.Object", depsgraph) -> np.ndarray:
    """What the artist sees of `obj`: in edit mode the edited mesh; else the
    evaluated one (shape keys, armature, modifiers)."""
    if obj.mode == "EDIT":
        obj.update_from_editmode()
        return vertex_positions(obj.data)
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        return vertex_positions(mesh)
    finally:
        evaluated.to_mesh_clear()


def armature_of(obj: "bpy.types.Object"):
    """The armature object of `obj`'s first Armature modifier, or None."""
    for m in obj.modifiers:
        if m.type == "ARMATURE" and m.object is not None:
            return m.object
    return None


def carry_skin(source: "bpy.types.Object", base: "bpy.types.Object", source_vertex_of_base: np.ndarray) -> bool:
    """Gives `base` the armature skin of `source`: the vertex groups (base
    vertex j takes the weights of source vertex source_vertex_of_base[j]) and
    an Armature modifier on the same armature, so posing the armature poses
    the base. The source's own Armature modifiers are turned off in the
    viewport: its vertices now come posed from the session's frames.
    Returns whether there was a skin to carry."""
    armatures = [m for m in source.modifiers if m.type == "ARMATURE" and m.object is not None]
    if not armatures:
        return False
    names = {g.index: g.name for g in source.vertex_groups}
    groups = {name: base.vertex_groups.new(name=name) for name in names.values()}
    vertices = source.data.vertices
    for j, b in enumerate(source_vertex_of_base.tolist()):
        for element in vertices[b].groups:
            if element.group in names and element.weight > 0.0:
                groups[names[element.group]].add([j], element.weight, "REPLACE")
    for m in armatures:
        carried = base.modifiers.new(name=m.name, type="ARMATURE")
        carried.object = m.object
        carried.use_vertex_groups = m.use_vertex_groups
        carried.use_bone_envelopes = m.use_bone_envelopes
        carried.use_deform_preserve_volume = m.use_deform_preserve_volume
        m.show_viewport = False
    return True
