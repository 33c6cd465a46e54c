"""One layer per character type: a ``SkelRoot`` with its ``Skeleton`` and skinned proxy
``Mesh``, ready to be referenced by instanceable agents.

::

    def SkelRoot "<skeleton>"                      (defaultPrim)
        def Skeleton "Skeleton"                    joints, jointNames, bindTransforms,
                                                   restTransforms
        def Mesh "<mesh>"  (SkelBindingAPI)        points, triangles, normals, extent,
                                                   primvars:skel:jointIndices/jointWeights
                                                   (vertex, elementSize = the mesh's
                                                   influence width: 4, or 8),
                                                   primvars:skel:geomBindTransform = identity,
                                                   skel:skeleton -> Skeleton

``bindTransforms`` are the joints' model-space (skeleton-space) bind matrices, the
inverse of core's ``Skeleton.inverse_bind``, so UsdSkel's skinning transform
``skel_i @ inverse(bind_i)`` is core's ``model_i @ inverse_bind_i`` (paper Eq. 1).
``restTransforms`` are the local bind pose. The mesh is in skeleton space at bind.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Vt

from ..core import pose as sqt
from . import convert
from .layers import apply_api, attribute, define, new_layer, relationship
from .naming import joint_paths, unique_identifiers

__all__ = ["character_layer", "SKELETON_PRIM"]

SKELETON_PRIM = "Skeleton"
_T = Sdf.ValueTypeNames


def character_layer(skeleton, mesh, fmt: str, fps: float, root_name: str):
    """The character layer of ``skeleton`` (core Skeleton) drawn with ``mesh`` (core
    ProxyMesh), its SkelRoot named ``root_name``; returns ``(layer, joints)`` with the
    joint path tokens (shared by every animation of this skeleton)."""
    layer = new_layer(fmt, fps, 0, 0, default_prim=root_name,
                      comment=f"crowd character {skeleton.name!r}")
    joints = Vt.TokenArray(joint_paths(skeleton.bone_names, skeleton.parents))
    with Sdf.ChangeBlock():
        root = define(layer, root_name, "SkelRoot")
        root.customData = {"crowd": {"skeleton": skeleton.name, "mesh": mesh.name}}
        skel = define(root, SKELETON_PRIM, "Skeleton")
        attribute(skel, "joints", _T.TokenArray, joints, uniform=True)
        attribute(skel, "jointNames", _T.TokenArray, Vt.TokenArray(skeleton.bone_names),
                  uniform=True)
        attribute(skel, "bindTransforms", _T.Matrix4dArray,
                  convert.matrices(np.linalg.inv(skeleton.inverse_bind)), uniform=True)
        attribute(skel, "restTransforms", _T.Matrix4dArray,
                  convert.matrices(sqt.pose_to_matrices(skeleton.bind_pose)), uniform=True)
        _mesh(root, mesh, root.path.AppendChild(SKELETON_PRIM))
    return layer, joints


def _mesh(root, mesh, skeleton_path):
    (name,) = unique_identifiers([mesh.name])
    if name == SKELETON_PRIM:
        name = f"{name}_mesh"
    prim = define(root, name, "Mesh")
    apply_api(prim, "SkelBindingAPI")
    attribute(prim, "points", _T.Point3fArray, convert.vec3f(mesh.positions))
    attribute(prim, "normals", _T.Normal3fArray, convert.vec3f(mesh.normals),
              interpolation="vertex")
    attribute(prim, "extent", _T.Float3Array, convert.vec3f(mesh.extent))
    attribute(prim, "faceVertexCounts", _T.IntArray,
              convert.ints(np.full(mesh.triangle_count, 3)))
    attribute(prim, "faceVertexIndices", _T.IntArray, convert.ints(mesh.triangles))
    attribute(prim, "subdivisionScheme", _T.Token, "none", uniform=True)
    width = int(mesh.bone_indices.shape[1])          # 4, or 8 past four influences
    attribute(prim, "primvars:skel:jointIndices", _T.IntArray,
              convert.ints(mesh.bone_indices), interpolation="vertex", elementSize=width)
    attribute(prim, "primvars:skel:jointWeights", _T.FloatArray,
              convert.floats(mesh.bone_weights), interpolation="vertex", elementSize=width)
    attribute(prim, "primvars:skel:geomBindTransform", _T.Matrix4d, Gf.Matrix4d(1.0))
    relationship(prim, "skel:skeleton", skeleton_path)
