"""A mesh object with its armature as a skinned GLB (glTF 2.0 binary), so the
session gets the skeleton and armature poses can go up as joints. Positions
stay in the mesh object's space and in Blender's vertex order (uploaded_ids
then refer to Blender's vertices); joints are the armature's bones, parents
first, their model matrices taken into the mesh object's space."""

from __future__ import annotations

import json
import struct

import numpy as np

from . import mesh_exchange


def bones_in_order(armature) -> list:
    """The armature's bones, every parent before its children."""
    ordered = []

    def visit(bone):
        ordered.append(bone)
        for child in bone.children:
            visit(child)

    for bone in armature.data.bones:
        if bone.parent is None:
            visit(bone)
    return ordered


def column_major(matrix) -> list[float]:
    """A mathutils 4×4 matrix as glTF wants it (columns one after another)."""
    return [float(matrix[r][c]) for c in range(4) for r in range(4)]


def model_matrices(obj, armature, bones, posed: bool) -> np.ndarray:
    """Each bone's rest (posed False) or pose matrix in the mesh object's
    space, (J, 16) column-major float32: what JointPose SPACE_MODEL_MATRIX takes."""
    to_model = obj.matrix_world.inverted() @ armature.matrix_world
    out = np.empty((len(bones), 16), dtype=np.float32)
    for j, bone in enumerate(bones):
        m = armature.pose.bones[bone.name].matrix if posed else bone.matrix_local
        out[j] = column_major(to_model @ m)
    return out


def _weights(obj, bones) -> tuple[np.ndarray, np.ndarray]:
    """Four influences per vertex (the largest, normalised) from the vertex
    groups named after bones; a vertex with none follows the first root."""
    index = {bone.name: j for j, bone in enumerate(bones)}
    group_bone = {g.index: index[g.name] for g in obj.vertex_groups if g.name in index}
    n = len(obj.data.vertices)
    joints = np.zeros((n, 4), dtype=np.uint16)
    weights = np.zeros((n, 4), dtype=np.float32)
    for v in obj.data.vertices:
        influences = sorted(((e.weight, group_bone[e.group]) for e in v.groups if e.group in group_bone and e.weight > 0),
                            reverse=True)[:4]
        total = sum(w for w, _ in influences)
        if total <= 0:
            weights[v.index, 0] = 1.0
            continue
        for k, (w, j) in enumerate(influences):
            joints[v.index, k], weights[v.index, k] = j, w / total
    return joints, weights


def skinned_glb(obj, armature) -> bytes:
    """The GLB of `obj` (at rest) skinned to `armature`'s bones."""
    bones = bones_in_order(armature)
    positions = mesh_exchange.vertex_positions(obj.data)
    indices = mesh_exchange.triangles(obj.data).astype(np.uint32)
    joints, weights = _weights(obj, bones)
    rest = model_matrices(obj, armature, bones, posed=False)
    inverse_bind = np.stack([np.linalg.inv(m.reshape(4, 4).T.astype(np.float64)).T.reshape(16) for m in rest])

    blob = bytearray()
    views, accessors = [], []

    def add(array: np.ndarray, component: int, kind: str, count: int, target=None, bounds=False) -> int:
        while len(blob) % 4:
            blob.append(0)
        data = np.ascontiguousarray(array).tobytes()
        view = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        if target:
            view["target"] = target
        views.append(view)
        blob.extend(data)
        accessor = {"bufferView": len(views) - 1, "componentType": component, "count": count, "type": kind}
        if bounds:
            accessor["min"] = array.min(axis=0).tolist()
            accessor["max"] = array.max(axis=0).tolist()
        accessors.append(accessor)
        return len(accessors) - 1

    n = len(positions)
    attributes = {
        "POSITION": add(positions, 5126, "VEC3", n, 34962, bounds=True),
        "JOINTS_0": add(joints, 5123, "VEC4", n, 34962),
        "WEIGHTS_0": add(weights, 5126, "VEC4", n, 34962),
    }
    faces = add(indices.reshape(-1), 5125, "SCALAR", indices.size, 34963)
    bind = add(inverse_bind.astype(np.float32), 5126, "MAT4", len(bones))

    index = {bone.name: j for j, bone in enumerate(bones)}
    joint_nodes = []
    for j, bone in enumerate(bones):
        local = rest[j].reshape(4, 4).T.astype(np.float64)
        if bone.parent is not None:
            local = np.linalg.inv(rest[index[bone.parent.name]].reshape(4, 4).T.astype(np.float64)) @ local
        node = {"name": bone.name, "matrix": local.T.reshape(16).tolist()}
        children = [1 + index[c.name] for c in bone.children]
        if children:
            node["children"] = children
        joint_nodes.append(node)
    document = {
        "asset": {"version": "2.0", "generator": "Filigree Blender add-on"},
        "scene": 0,
        "scenes": [{"nodes": [0] + [1 + j for j, b in enumerate(bones) if b.parent is None]}],
        "nodes": [{"name": obj.name, "mesh": 0, "skin": 0}] + joint_nodes,
        "meshes": [{"primitives": [{"attributes": attributes, "indices": faces}]}],
        "skins": [{"joints": [1 + j for j in range(len(bones))], "inverseBindMatrices": bind}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob)}],
    }
    text = json.dumps(document, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    while len(blob) % 4:
        blob.append(0)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(text), b"JSON") + text
            + struct.pack("<I4s", len(blob), b"BIN\0") + bytes(blob))
