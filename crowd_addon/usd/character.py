"""One layer per character type: a ``SkelRoot`` with its ``Skeleton`` and skinned proxy
``Mesh``, ready to be referenced by instanceable agents.

::

    def SkelRoot "<skeleton>"                      (defaultPrim)
        def Skeleton "Skeleton"                    joints, jointNames, bindTransforms,
                                                   restTransforms
        def Mesh "<mesh>"  (SkelBindingAPI)        the body (a mesh variant): points,
                                                   triangles, normals, extent,
                                                   primvars:skel:jointIndices/jointWeights
                                                   (vertex, elementSize = the mesh's
                                                   influence width: 4, or 8),
                                                   primvars:skel:geomBindTransform = identity,
                                                   skel:skeleton -> Skeleton,
                                                   primvars:st (faceVarying) when the
                                                   mesh has texture coordinates,
                                                   material:binding (one look) or a
                                                   GeomSubset per look
        def Mesh "<prop>"  (SkelBindingAPI)        per prop the body carries: its points
                                                   bound rigidly to its joint (constant
                                                   jointIndices [bone], jointWeights [1])
        def Scope "Looks"                          a Material per look: UsdPreviewSurface
                                                   with the base colour, or an
                                                   UsdUVTexture of the image read at st;
                                                   a palette material's colour is read
                                                   from the primvar crowdPalette<column>,
                                                   a grey or white look's from
                                                   crowdTint_<look> (each agent's,
                                                   docs/variety.md), its own colour the
                                                   fallback

``bindTransforms`` are the joints' model-space (skeleton-space) bind matrices, the
inverse of core's ``Skeleton.inverse_bind``, so UsdSkel's skinning transform
``skel_i @ inverse(bind_i)`` is core's ``model_i @ inverse_bind_i`` (paper Eq. 1).
``restTransforms`` are the local bind pose. The mesh is in skeleton space at bind.
"""

from __future__ import annotations

import hashlib

import numpy as np
from pxr import Gf, Sdf, Tf, Vt

from ..core.base import pose as sqt
from . import convert
from ..core.meshes.bodies import merge_meshes
from ..core.meshes.mesh import Look, tint_weight
from .layers import apply_api, attribute, connect, define, new_layer, relationship
from .naming import joint_paths, unique_identifiers

__all__ = ["character_layer", "joint_tokens", "palette_primvar", "tint_primvar", "tinted_looks", "SKELETON_PRIM"]

SKELETON_PRIM = "Skeleton"
_T = Sdf.ValueTypeNames


def joint_tokens(skeleton) -> Vt.TokenArray:
    """The joint path tokens of ``skeleton`` (core Skeleton), shared by its character
    and every animation of it."""
    return Vt.TokenArray(joint_paths(skeleton.bone_names, skeleton.parents))


def character_layer(skeleton, mesh, fmt: str, fps: float, root_name: str, textures=None,
                    proxy=None, palette_materials=(), props=(), variant=0):
    """The character layer of ``skeleton`` (core Skeleton) drawn with ``mesh`` (core
    ProxyMesh), its SkelRoot named ``root_name``; returns ``(layer, joints)`` with the
    joint path tokens (shared by every animation of this skeleton). ``textures`` maps
    a look's texture to the asset path the layer names it by (default: as it is).
    ``proxy``: a lighter mesh (an LOD) written beside it with ``purpose = "proxy"``,
    the full mesh then having ``purpose = "render"``: viewers such as usdview draw the
    proxy, renders the full mesh. ``palette_materials``: the material (look) names
    the agents' palette columns colour, in column order. ``props``: the
    :class:`~crowd_addon.core.meshes.bodies.Prop` s the body carries, each a mesh of its own
    bound rigidly to its joint; ``variant``: the mesh variant ``mesh`` is (recorded in
    the root's ``customData``). Palette and tinted looks' materials read each agent's
    primvars (:func:`palette_primvar`, :func:`tint_primvar`), with the look's own
    colour as the fallback."""
    layer = new_layer(fmt, fps, 0, 0, default_prim=root_name,
                      comment=f"crowd character {skeleton.name!r}")
    joints = joint_tokens(skeleton)
    with Sdf.ChangeBlock():
        root = define(layer, root_name, "SkelRoot")
        info = {"skeleton": skeleton.name, "mesh": mesh.name}
        if variant or props:
            info.update(variant=int(variant), props=Vt.StringArray([p.name for p in props]))
        root.customData = {"crowd": info}
        skel = define(root, SKELETON_PRIM, "Skeleton")
        attribute(skel, "joints", _T.TokenArray, joints, uniform=True)
        attribute(skel, "jointNames", _T.TokenArray, Vt.TokenArray(skeleton.bone_names),
                  uniform=True)
        attribute(skel, "bindTransforms", _T.Matrix4dArray,
                  convert.matrices(np.linalg.inv(skeleton.inverse_bind)), uniform=True)
        attribute(skel, "restTransforms", _T.Matrix4dArray,
                  convert.matrices(sqt.pose_to_matrices(skeleton.bind_pose)), uniform=True)
        whole = merge_meshes(mesh.name, [mesh, *(p.mesh for p in props)])
        materials = _materials(root, whole, textures or {}, tuple(palette_materials))
        look_of = {k.name: i for i, k in enumerate(whole.looks)}
        # (mesh, purpose, rigid bone, the look of a part without looks: as merged)
        meshes = [(mesh, "render" if proxy is not None else None, None, mesh.name)]
        if proxy is not None:
            meshes.append((proxy, "proxy", None, mesh.name))
        meshes += [(p.mesh, None, p.bone, p.mesh.name) for p in props]
        names = unique_identifiers([m[0].name for m in meshes] + [SKELETON_PRIM, "Looks"])
        for (m, purpose, bone, bare), name in zip(meshes, names):
            prim = _mesh(root, m, name, root.path.AppendChild(SKELETON_PRIM), bone)
            if purpose:
                attribute(prim, "purpose", _T.Token, purpose, uniform=True)
            if materials:
                which = np.array([look_of[k.name] for k in m.looks or (Look(bare),)],
                                 np.int64)
                local = np.zeros(m.triangle_count, np.int64) if m.material is None \
                    else m.material.astype(np.int64)
                _bind_looks(prim, which[local], materials)
    return layer, joints


def _mesh(root, mesh, name, skeleton_path, bone=None):
    """A skinned Mesh prim of ``mesh``; with ``bone``, bound rigidly to that joint (a
    prop: constant joint influence)."""
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
    if bone is not None:
        attribute(prim, "primvars:skel:jointIndices", _T.IntArray, convert.ints([bone]),
                  interpolation="constant", elementSize=1)
        attribute(prim, "primvars:skel:jointWeights", _T.FloatArray, convert.floats([1.0]),
                  interpolation="constant", elementSize=1)
    else:
        width = int(mesh.bone_indices.shape[1])      # 4, or 8 past four influences
        attribute(prim, "primvars:skel:jointIndices", _T.IntArray,
                  convert.ints(mesh.bone_indices), interpolation="vertex", elementSize=width)
        attribute(prim, "primvars:skel:jointWeights", _T.FloatArray,
                  convert.floats(mesh.bone_weights), interpolation="vertex", elementSize=width)
    attribute(prim, "primvars:skel:geomBindTransform", _T.Matrix4d, Gf.Matrix4d(1.0))
    relationship(prim, "skel:skeleton", skeleton_path)
    if mesh.uvs is not None:
        attribute(prim, "primvars:st", _T.TexCoord2fArray,
                  Vt.Vec2fArray.FromNumpy(mesh.uvs.reshape(-1, 2)), interpolation="faceVarying")
    return prim


def _materials(root, mesh, textures, palette_materials=()) -> list:
    """A Material per look of ``mesh`` under ``Looks``: ``[(name, material spec)]``."""
    if not mesh.looks:
        return []
    scope = define(root, "Looks", "Scope")
    names = unique_identifiers([k.name for k in mesh.looks])
    return [(name, _material(scope, name, look, mesh.uvs is not None,
                             textures.get(look.texture, look.texture),
                             palette_materials.index(look.name)
                             if look.name in palette_materials else None,
                             _is_tinted(look, palette_materials)))
            for name, look in zip(names, mesh.looks)]


def palette_primvar(column: int) -> str:
    """The primvar an agent's palette colour ``column`` is written as."""
    return f"crowdPalette{int(column)}"


def tint_primvar(look_name: str) -> str:
    """The primvar an agent's tinted colour of look ``look_name`` is written as:
    ``crowdTint_<name>`` (a name that is no identifier made one, with a digest of
    it so that two such names cannot meet)."""
    valid = Tf.MakeValidIdentifier(look_name)
    if valid != look_name:
        valid += "_" + hashlib.sha1(look_name.encode()).hexdigest()[:6]
    return f"crowdTint_{valid}"


def tinted_looks(looks, palette_materials=()) -> list:
    """Of ``looks``, those that agents' colours tint in the export
    (:func:`_is_tinted`): ``[(primvar, (r, g, b))]``, one per name."""
    return list({tint_primvar(look.name): tuple(look.color[:3]) for look in looks
                 if _is_tinted(look, palette_materials)}.items())


def _is_tinted(look, palette_materials) -> bool:
    """Whether agents' colours tint ``look`` in the export, as the preview's shader
    does: a tint weight (:func:`~crowd_addon.core.meshes.mesh.tint_weight`) above 0, in no
    palette and without a texture."""
    return (look.name not in palette_materials and not look.texture
            and tint_weight(look.color[:3]) > 0)


def _bind_looks(prim, which, named_materials):
    """Bind the materials to the mesh, ``which`` (T,) the index of each triangle's
    among ``named_materials``: the one material when all use one, else a GeomSubset of
    its triangles per material."""
    names, materials = zip(*named_materials)
    used = np.unique(which)
    if used.size == 1:
        _bind(prim, materials[int(used[0])])
        return
    attribute(prim, "subsetFamily:materialBind:familyType", _T.Token, "nonOverlapping",
              uniform=True)
    for k, (name, material) in enumerate(zip(names, materials)):
        faces = np.flatnonzero(which == k)
        if not faces.size:
            continue
        subset = define(prim, name, "GeomSubset")
        attribute(subset, "elementType", _T.Token, "face", uniform=True)
        attribute(subset, "familyName", _T.Token, "materialBind", uniform=True)
        attribute(subset, "indices", _T.IntArray, convert.ints(faces))
        _bind(subset, material)


def _material(scope, name, look, has_uvs, texture, column=None, tint=False):
    """``Material "<name>"``: a UsdPreviewSurface of the look's base colour and
    opacity; its texture, when it has one and the mesh has texture coordinates, feeds
    the diffuse colour instead; with a palette ``column``, the agent's primvar
    :func:`palette_primvar` does, and for a look agents' colours ``tint``
    (:func:`_is_tinted`), the agent's primvar :func:`tint_primvar` (the look's colour
    the fallback of both)."""
    material = define(scope, name, "Material")
    shader = define(material, "PreviewSurface", "Shader")
    attribute(shader, "info:id", _T.Token, "UsdPreviewSurface", uniform=True)
    color = attribute(shader, "inputs:diffuseColor", _T.Color3f, Gf.Vec3f(*look.color[:3]))
    attribute(shader, "inputs:opacity", _T.Float, float(look.color[3]))
    attribute(shader, "inputs:roughness", _T.Float, 0.6)
    surface = attribute(shader, "outputs:surface", _T.Token)
    connect(attribute(material, "outputs:surface", _T.Token), surface)
    if column is not None or tint:
        reader = define(material, "Palette" if column is not None else "Tint", "Shader")
        attribute(reader, "info:id", _T.Token, "UsdPrimvarReader_float3", uniform=True)
        attribute(reader, "inputs:varname", _T.String, palette_primvar(column)
                  if column is not None else tint_primvar(look.name))
        attribute(reader, "inputs:fallback", _T.Float3, Gf.Vec3f(*look.color[:3]))
        connect(color, attribute(reader, "outputs:result", _T.Float3))
    elif look.texture and has_uvs:
        reader = define(material, "st", "Shader")
        attribute(reader, "info:id", _T.Token, "UsdPrimvarReader_float2", uniform=True)
        attribute(reader, "inputs:varname", _T.String, "st")
        st = attribute(reader, "outputs:result", _T.Float2)
        image = define(material, "BaseColor", "Shader")
        attribute(image, "info:id", _T.Token, "UsdUVTexture", uniform=True)
        attribute(image, "inputs:file", _T.Asset, Sdf.AssetPath(texture))
        attribute(image, "inputs:fallback", _T.Float4, Gf.Vec4f(*look.color))
        connect(attribute(image, "inputs:st", _T.Float2), st)
        connect(color, attribute(image, "outputs:rgb", _T.Float3))
    return material


def _bind(prim, material):
    apply_api(prim, "MaterialBindingAPI")
    relationship(prim, "material:binding", material.path)
