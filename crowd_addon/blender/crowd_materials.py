"""The materials *Render Crowd*'s pose meshes wear: copies of the characters' materials
that colour each agent as the GPU preview does.

The preview colours a vertex by its material's base colour, tinted by the agent's
colour where that colour is grey (white shirts take the team colour, skin keeps its
own), or replaced by the agent's palette colour where a palette names the material
(``gpu_shaders/crowd_vertex.glsl``). Blender's renders know nothing of agents, so
each material a pose mesh uses is copied once, as ``CrowdMaterial.<name>`` (with the
palette column: ``CrowdMaterial.<name>.<column>``), and the copy's Principled BSDF
*Base Color* goes through the same rule, read from the points object's attributes
through *Attribute* nodes of type *Instancer*:

* ``tinted = mix(base, base * crowd_color, clamp(1 - 4 * saturation(base)))``,
  saturation as HSV's (``(max - min) / max``), as in the shader;
* with a palette column ``c``: ``mix(tinted, crowd_palette<c>.rgb,
  crowd_palette<c>.alpha)``: alpha is 1 where the agent has a colour for it.

EEVEE and Cycles read the copies; Workbench shows a material's viewport colour and
cannot vary it per instance, so it draws the bodies untinted. A material whose
surface is not a Principled BSDF is copied as it is (the preview shows its viewport
colour; no rule is added). A copy follows its source: :func:`refresh_all`, once a
frame, remakes each copy whose source's nodes, their values or its viewport colour
changed, and re-points the pose meshes at the new copy.
"""

from __future__ import annotations

import hashlib

import bpy

from ..core.base.errors import CrowdError
from .looks import principled

__all__ = ["PREFIX", "crowd_material", "refresh_all", "remove_all"]

#: name prefix of the copies
PREFIX = "CrowdMaterial."
#: custom properties of a copy: the digest of the source it was made from, the
#: source's name and the palette column (-1: none)
_SOURCE, _NAME, _COLUMN = "crowd_source", "crowd_source_name", "crowd_palette_column"


def crowd_material(name: str, column=None):
    """The crowd copy of material ``name`` for palette column ``column`` (None: the
    material is in no palette), made or remade as needed; None when there is no
    material of that name."""
    source = bpy.data.materials.get(name)
    if source is None or name.startswith(PREFIX):
        return source
    key = PREFIX + name + ("" if column is None else f".{int(column)}")
    digest = _digest(source)
    old = bpy.data.materials.get(key)
    if old is not None and _SOURCE not in old:
        raise CrowdError(f"material {key!r} is not Render Crowd's; rename it to use "
                         "Render Crowd")
    if old is not None and old.get(_SOURCE) == digest:
        return old
    copy = source.copy()
    copy.use_fake_user = False
    if copy.node_tree is None:              # Blender before 5.0: no nodes yet
        copy.use_nodes = True
        bsdf = principled(copy)
        if bsdf is not None:                # what a node-less material renders
            bsdf.inputs["Base Color"].default_value = tuple(source.diffuse_color)
    bsdf = principled(copy)
    if bsdf is not None:
        _colour_rule(copy.node_tree, bsdf.inputs["Base Color"], column)
    copy[_SOURCE], copy[_NAME] = digest, name
    copy[_COLUMN] = -1 if column is None else int(column)
    if old is not None:
        old.user_remap(copy)
        bpy.data.materials.remove(old)
    copy.name = key
    return copy


def refresh_all() -> None:
    """Remake the copies whose source changed (:func:`crowd_material`)."""
    for copy in [m for m in bpy.data.materials if m.name.startswith(PREFIX)]:
        name, column = copy.get(_NAME), copy.get(_COLUMN, -1)
        if name is not None:
            crowd_material(name, None if column < 0 else column)


def remove_all() -> list:
    """The crowd copies (not a material of the user's that bears the prefix), to
    remove with the rest of the render data."""
    return [m for m in bpy.data.materials if m.name.startswith(PREFIX) and _SOURCE in m]


def _colour_rule(tree, socket, column) -> None:
    """Route what feeds ``socket`` (a colour input) through the preview's rule."""
    nodes, links = tree.nodes, tree.links
    if socket.links:
        base = socket.links[0].from_socket
    else:
        rgb = nodes.new("ShaderNodeRGB")
        rgb.outputs[0].default_value = tuple(socket.default_value)
        base = rgb.outputs[0]
    hsv = nodes.new("ShaderNodeSeparateColor")
    hsv.mode = "HSV"
    links.new(base, hsv.inputs[0])
    grey = nodes.new("ShaderNodeMath")                     # clamp(1 - 4 * saturation)
    grey.operation, grey.use_clamp = "MULTIPLY_ADD", True
    links.new(hsv.outputs[1], grey.inputs[0])
    grey.inputs[1].default_value, grey.inputs[2].default_value = -4.0, 1.0
    tint = _instancer(nodes, "crowd_color")
    tinted = _mix(nodes, links, "MULTIPLY", grey.outputs[0], base, tint.outputs["Color"])
    out = tinted
    if column is not None:
        palette = _instancer(nodes, f"crowd_palette{int(column)}")
        out = _mix(nodes, links, "MIX", palette.outputs["Alpha"], tinted,
                   palette.outputs["Color"])
    links.new(out, socket)


def _instancer(nodes, attribute: str):
    node = nodes.new("ShaderNodeAttribute")
    node.attribute_type, node.attribute_name = "INSTANCER", attribute
    return node


def _mix(nodes, links, blend: str, factor, a, b):
    """A colour Mix node ``blend``-ing ``a`` with ``b`` by ``factor``; its result."""
    mix = nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type = "RGBA", blend
    sockets = {s.identifier: s for s in mix.inputs}
    links.new(factor, sockets["Factor_Float"])
    links.new(a, sockets["A_Color"])
    links.new(b, sockets["B_Color"])
    return next(s for s in mix.outputs if s.identifier == "Result_Color")


def _digest(material) -> str:
    """A digest of what the copy takes from ``material``: its viewport colour, its
    nodes' kinds, input values and images, and its links."""
    parts = [tuple(material.diffuse_color)]
    tree = material.node_tree
    for node in tree.nodes if tree is not None else ():
        image = getattr(node, "image", None)
        parts.append((node.name, node.bl_idname, image.name if image is not None else "",
                      tuple(_value(s) for s in node.inputs)))
    for link in tree.links if tree is not None else ():
        parts.append((link.from_node.name, link.from_socket.identifier,
                      link.to_node.name, link.to_socket.identifier))
    return hashlib.sha1(repr(parts).encode()).hexdigest()


def _value(socket):
    value = getattr(socket, "default_value", None)
    try:
        return tuple(value)
    except TypeError:
        return value
