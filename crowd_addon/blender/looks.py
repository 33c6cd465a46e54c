"""How a mesh object looks, for the proxy mesh: its active UV map per triangle corner
and its material slots as :class:`~crowd_addon.core.meshes.mesh.Look` s.

A material's look is what its Principled BSDF shows: the *Base Color* input's colour
(and *Alpha*), or the image of an *Image Texture* node plugged into *Base Color* (its
file, made absolute). A material without a Principled BSDF gives its viewport colour
(``diffuse_color``); an empty slot a neutral grey. Materials used by several slots
are one look.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

from ..core.meshes.mesh import Look
from .owned import made, mark

__all__ = ["mesh_looks", "plain_material", "principled"]

#: the look of an empty material slot
EMPTY = (0.8, 0.8, 0.8, 1.0)


def mesh_looks(mesh_obj, me, loops: np.ndarray) -> dict:
    """``uvs``, ``material`` and ``looks`` keyword arguments of
    :class:`~crowd_addon.core.meshes.mesh.ProxyMesh` for ``me`` (the object's mesh data, its
    loop triangles computed) whose loop triangles use ``loops`` ((T, 3) loop indices)."""
    out = {}
    layer = me.uv_layers.active
    if layer is not None and len(me.loops):
        uv = np.empty(len(me.loops) * 2, np.float32)
        layer.uv.foreach_get("vector", uv)
        out["uvs"] = uv.reshape(-1, 2)[loops]
    slots = [s.material for s in mesh_obj.material_slots]
    if not slots:
        return out
    distinct = list(dict.fromkeys(slots))
    looks, names = [], set()
    for m in distinct:
        look = _look(m)
        name, n = look.name, 1
        while name in names:                 # "grey" for two empty slots... one look
            n += 1
            name = f"{look.name}.{n}"
        names.add(name)
        looks.append(Look(name, look.color, look.texture))
    index = np.array([distinct.index(m) for m in slots], np.int64)
    which = np.empty(len(me.loop_triangles), np.int64)
    me.loop_triangles.foreach_get("material_index", which)
    out["material"] = index[np.clip(which, 0, len(slots) - 1)]
    out["looks"] = tuple(looks)
    return out


def _look(material) -> Look:
    if material is None:
        return Look("empty slot", EMPTY)
    bsdf = principled(material)
    if bsdf is None:
        return Look(material.name, tuple(material.diffuse_color))
    base = bsdf.inputs["Base Color"]
    alpha = float(bsdf.inputs["Alpha"].default_value)
    color = tuple(base.default_value)[:3] + (alpha,)
    texture = ""
    for link in base.links:
        node = link.from_node
        if node.type == "TEX_IMAGE" and node.image is not None and node.image.filepath:
            texture = os.path.abspath(bpy.path.abspath(node.image.filepath,
                                                       library=node.image.library))
    return Look(material.name, tuple(min(max(c, 0.0), 1.0) for c in color), texture)


def principled(material):
    """The Principled BSDF feeding the material's output, or None."""
    tree = material.node_tree
    if tree is None:
        return None
    for node in tree.nodes:
        if node.type == "OUTPUT_MATERIAL" and node.is_active_output:
            surface = node.inputs["Surface"]
            for link in surface.links:
                if link.from_node.type == "BSDF_PRINCIPLED":
                    return link.from_node
    return None


def plain_material(name: str, colour):
    """The extension's material ``name`` of one linear RGBA ``colour``, the same in
    every engine and in the crowd's looks: its viewport colour (Workbench) and its
    Principled BSDF's *Base Color* (EEVEE, Cycles, :func:`mesh_looks`). Blender 5
    gives a new material a Principled BSDF of its own grey; setting the viewport
    colour alone would leave that grey. The material this made before (marked:
    :mod:`.owned`) is reused and recoloured; a material of the user's named ``name``
    is left as it is, and a new one is made beside it (``name.001``)."""
    what = f"material {name}"
    mat = next((m for m in bpy.data.materials if made(m, what)), None) or \
        mark(bpy.data.materials.new(name), what)
    mat.diffuse_color = colour
    if mat.node_tree is None:              # Blender before 5.0: nodes on request
        mat.use_nodes = True
    bsdf = principled(mat)
    if bsdf is not None:
        bsdf.inputs["Base Color"].default_value = colour
    return mat
