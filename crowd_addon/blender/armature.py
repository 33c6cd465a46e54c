"""Armature objects -> core :class:`Skeleton`; skinned mesh objects -> core :class:`ProxyMesh`.

This module reads the Blender data (bones, rest matrices, vertices, vertex groups)
into arrays; the math on them is :mod:`crowd_addon.core.bake.armature_math`. Every bone
of the armature becomes a skeleton bone, ordered parents first
(:meth:`Skeleton.from_parent_names`); ``skeleton.bone_names`` is the name -> index
mapping. The local SQT of bone ``i`` is its transform relative
to its parent bone in the pose::

    local_i = inv(parent.bone.matrix_local) @ bone.matrix_local @ pose_bone.matrix_basis

(roots: ``bone.matrix_local @ matrix_basis``), so that core's model matrices equal
``pose.bones[name].matrix`` (armature space). The bind pose is the rest pose and
``inverse_bind = inv(bone.matrix_local)``, so skinning matrices are
``pose.bones[name].matrix @ inv(bone.matrix_local)``, as in the Armature modifier.
"""

from __future__ import annotations

import numpy as np

from ..core.base import quaternion as quat
from ..core.bake.armature_math import (check_hierarchy, relative_to_parent, rest_skeleton,
                                       vertex_influences)
from ..core.base.errors import CrowdError
from ..core.meshes.mesh import ProxyMesh
from ..core.base.skeleton import Skeleton
from .looks import mesh_looks

__all__ = ["skeleton_from_armature", "check_skeleton", "skeleton_and_rest", "matrices",
           "object_to_armature", "proxy_mesh_from_object", "prop_from_object"]


def _checked(obj, kind: str, noun: str):
    """``obj`` if it is a live Blender object of type ``kind``, else a CrowdError."""
    try:
        found = getattr(obj, "type", None)
    except ReferenceError:                      # the object was deleted from Blender
        raise CrowdError(f"the {noun} no longer exists (it was deleted)") from None
    if found != kind:
        article = "an" if noun[0] in "aeiou" else "a"
        raise CrowdError(f"object {getattr(obj, 'name', obj)!r} is not {article} {noun}")
    return obj


def _armature(obj):
    return _checked(obj, "ARMATURE", "armature")


def matrices(collection, prop: str) -> np.ndarray:
    """``(len(collection), 4, 4)`` float64 row-major matrices of a matrix property read
    with one ``foreach_get`` (Blender stores them column-major)."""
    buf = np.empty(len(collection) * 16, np.float32)
    collection.foreach_get(prop, buf)
    return buf.reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float64)


def _bones(armature_obj):
    """Bone names, parent names and ``matrix_local`` (B, 4, 4) in Blender's order."""
    bones = _armature(armature_obj).data.bones
    if len(bones) == 0:
        raise CrowdError(f"armature {armature_obj.name!r} has no bones")
    names = bones.keys()
    parents = [None if p is None else p.name for p in (b.parent for b in bones)]
    return names, parents, matrices(bones, "matrix_local")


def skeleton_from_armature(armature_obj, name: str | None = None) -> Skeleton:
    """The armature's bones as a core :class:`Skeleton` named after the object.

    Bind pose: the rest pose relative to the parent bone; ``inverse_bind``:
    ``inv(bone.matrix_local)`` in float64.
    """
    return rest_skeleton(name or armature_obj.name, *_bones(armature_obj))[0]


def check_skeleton(armature_obj, skeleton: Skeleton) -> None:
    """Raise unless ``skeleton`` has exactly the armature's bones and hierarchy."""
    names, parent_names, _ = _bones(armature_obj)
    check_hierarchy(skeleton, armature_obj.name, names, parent_names)


def skeleton_and_rest(armature_obj, skeleton: Skeleton | None = None):
    """What a bake needs of the armature's bones, read once.

    Returns ``(skeleton, order, rest, rest_rot)``: ``skeleton`` as
    :func:`skeleton_from_armature` makes it (or the one given, checked with
    :func:`check_skeleton`), ``order`` (B,) int64 the Blender index of each skeleton
    bone, ``rest`` (B, 4, 4) float64 the rest matrices relative to the parent bone in
    skeleton order and ``rest_rot`` their rotations ``(B, 4)`` float64.
    """
    names, parent_names, ml = _bones(armature_obj)
    index = {n: i for i, n in enumerate(names)}
    if skeleton is None:
        skeleton, rel, rot = rest_skeleton(armature_obj.name, names, parent_names, ml)
        order = np.array([index[n] for n in skeleton.bone_names], np.int64)
        return skeleton, order, rel[order], rot[order]
    check_hierarchy(skeleton, armature_obj.name, names, parent_names)
    order = np.array([index[n] for n in skeleton.bone_names], np.int64)
    rest = relative_to_parent(ml[order], skeleton.parents.astype(np.int64))
    return skeleton, order, rest, quat.from_matrix(rest[:, :3, :3])


def object_to_armature(obj, armature_obj) -> np.ndarray:
    """(4, 4) float64 ``inv(armature.matrix_world) @ obj.matrix_world``: the object's
    local coordinates to armature space (the Armature modifier's ``premat``)."""
    a = np.array(armature_obj.matrix_world, np.float64)
    return np.linalg.inv(a) @ np.array(obj.matrix_world, np.float64)


def _armature_modifier(mesh_obj, armature_obj):
    what = f"mesh {mesh_obj.name!r}"
    for i, mod in enumerate(mesh_obj.modifiers):
        if mod.type == "ARMATURE" and mod.object == armature_obj:
            break
    else:
        raise CrowdError(f"{what} has no Armature modifier deforming {armature_obj.name!r}")
    before = [m.name for m in mesh_obj.modifiers[:i] if m.show_viewport]
    if before:
        raise CrowdError(f"{what}: modifiers {before} run before Armature modifier "
                         f"{mod.name!r}; the proxy is the base mesh, so apply or remove them")
    unsupported = [("use_vertex_groups", False, "uses no vertex groups"),
                   ("use_bone_envelopes", True, "uses bone envelopes"),
                   ("use_deform_preserve_volume", True, "preserves volume (dual quaternions)"),
                   ("use_multi_modifier", True, "is a multi-modifier")]
    for attr, value, text in unsupported:
        if getattr(mod, attr) == value:
            raise CrowdError(f"{what}: Armature modifier {mod.name!r} {text}; crowd skinning "
                             "is linear blend skinning by vertex groups")
    if mod.vertex_group:
        raise CrowdError(f"{what}: Armature modifier {mod.name!r} is masked by vertex group "
                         f"{mod.vertex_group!r}, which crowd skinning does not support")
    return mod


def proxy_mesh_from_object(mesh_obj, armature_obj, skeleton: Skeleton | None = None,
                           name: str | None = None) -> ProxyMesh:
    """A skinned mesh object as a core :class:`ProxyMesh` for ``skeleton``.

    Positions are the base mesh (no shape keys, no modifiers after the Armature
    modifier) in armature space; triangles are the mesh's loop triangles; influences
    come from vertex groups named after deform bones (others are ignored, as the
    Armature modifier does). Up to eight a vertex are kept exactly; a vertex with more
    keeps its eight strongest (it then differs slightly from Blender, which blends
    them all) and the mesh's ``notes`` say how many vertices that was. The active UV
    map and the material slots come along (:func:`.looks.mesh_looks`).
    """
    _checked(mesh_obj, "MESH", "mesh")
    _armature(armature_obj)
    skeleton = skeleton or skeleton_from_armature(armature_obj)
    _armature_modifier(mesh_obj, armature_obj)
    if mesh_obj.mode == "EDIT":
        mesh_obj.update_from_editmode()
    me = mesh_obj.data
    v = len(me.vertices)
    if v == 0:
        raise CrowdError(f"mesh {mesh_obj.name!r} has no vertices")
    co = np.empty(v * 3, np.float32)
    me.vertices.foreach_get("co", co)
    p = object_to_armature(mesh_obj, armature_obj)
    pos = co.reshape(v, 3).astype(np.float64) @ p[:3, :3].T + p[:3, 3]
    me.calc_loop_triangles()
    tris = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    deform = {b.name for b in armature_obj.data.bones if b.use_deform}
    bone_of_group = np.array([skeleton.bone_names.index(g.name) if g.name in deform else -1
                              for g in mesh_obj.vertex_groups] + [-1], np.int64)
    # vertex group weights have no bulk accessor: one pass over the vertices
    counts = np.zeros(v, np.int64)
    groups, weights = [], []
    for vert in me.vertices:
        gs = vert.groups
        counts[vert.index] = len(gs)
        for g in gs:
            groups.append(g.group)
            weights.append(g.weight)
    idx, wt = vertex_influences(counts, np.array(groups, np.int64),
                                np.array(weights, np.float64), bone_of_group)
    loops = np.empty(tris.size, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    return ProxyMesh.from_influences(name or mesh_obj.name, skeleton.name, pos,
                                     tris.reshape(-1, 3), idx, wt,
                                     bone_count=skeleton.bone_count,
                                     **mesh_looks(mesh_obj, me, loops.reshape(-1, 3)))


def prop_from_object(obj, armature_obj, skeleton: Skeleton, bone: str = ""):
    """A mesh object as a core :class:`~crowd_addon.core.meshes.bodies.Prop` moving rigidly with
    bone ``bone`` of ``armature_obj`` (empty: the bone the object is parented to).

    The prop keeps where it sits on the bone. Parented to that bone, an object is at
    ``armature @ pose_bone.matrix @ T(0, length, 0) @ matrix_parent_inverse @
    matrix_basis`` (Blender hangs bone children on the bone's tail), so at the rest
    pose its vertices are ``bone.matrix_local @ T(0, length, 0) @
    matrix_parent_inverse @ matrix_basis @ co`` in armature space, whatever the pose
    now. Otherwise its vertices (the base mesh where the object is now) are taken into
    the bone's space at its current pose and out again at the bone's rest:
    ``bone.matrix_local @ inv(pose_bone.matrix) @ inv(armature) @ obj.matrix_world``.
    Skinned with weight 1 to the bone (``M_pose @ inv(M_rest)``), that is exactly where
    Blender puts an object parented to the bone, at every pose. Materials and the
    active UV map come along (:func:`.looks.mesh_looks`)."""
    from ..core.meshes.bodies import Prop, rigid_mesh
    _checked(obj, "MESH", "mesh")
    _armature(armature_obj)
    if not bone:
        if obj.parent != armature_obj or obj.parent_type != "BONE" or not obj.parent_bone:
            raise CrowdError(f"object {obj.name!r}: choose its bone (or parent it to a bone "
                             f"of {armature_obj.name!r})")
        bone = obj.parent_bone
    if bone not in skeleton.bone_names:
        raise CrowdError(f"object {obj.name!r}: armature {armature_obj.name!r} has no bone "
                         f"{bone!r}")
    if obj.mode == "EDIT":
        obj.update_from_editmode()
    me = obj.data
    v = len(me.vertices)
    me.calc_loop_triangles()
    if v == 0 or not len(me.loop_triangles):
        raise CrowdError(f"object {obj.name!r} has no faces")
    co = np.empty(v * 3, np.float32)
    me.vertices.foreach_get("co", co)
    b = armature_obj.data.bones[bone]
    rest = np.array(b.matrix_local, np.float64)
    if obj.parent == armature_obj and obj.parent_type == "BONE" and obj.parent_bone == bone:
        tail = np.eye(4)
        tail[1, 3] = b.length
        m = rest @ tail @ np.array(obj.matrix_parent_inverse, np.float64) @ \
            np.array(obj.matrix_basis, np.float64)
    else:
        pose = np.array(armature_obj.pose.bones[bone].matrix, np.float64)
        m = rest @ np.linalg.inv(pose) @ object_to_armature(obj, armature_obj)
    pos = co.reshape(v, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    tris = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    loops = np.empty(tris.size, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    b = skeleton.bone_names.index(bone)
    return Prop(obj.name, skeleton.name, b,
                rigid_mesh(obj.name, skeleton.name, b, pos, tris.reshape(-1, 3),
                           skeleton.bone_count,
                           **mesh_looks(obj, me, loops.reshape(-1, 3))))
