"""Render Crowd's points object, the Geometry Nodes group on it and the collection of
pose objects it instances (:mod:`.render_crowd`): made once, found again by their mark.

All of Render Crowd's data is the extension's own (:mod:`.owned`): the points object,
its mesh, the collection and the node group carry the mark :data:`RENDER`, a pose mesh
its ``crowd_made_from`` digest (a pose object is one whose mesh is a pose mesh:
:mod:`.render_crowd`) and a material copy its ``crowd_source``
(:mod:`.crowd_materials`). Only those are reused, changed or removed: a datablock of
the user's named ``Crowd Render``, ``Crowd Poses`` or ``Crowd Render Instances`` is
left as it is (the new one is named by Blender, ``Crowd Render.001``); one of the
user's bearing a pose object's, pose mesh's or material copy's name
(``CrowdPose.000042``) stops Render Crowd with an error naming it rather than being
taken over (the pose objects' names give the instances' order). A points object saved
by an older version (unmarked) is recognised (:func:`points_object`), marked and used;
the older node group and collection it used are left unused.
"""

from __future__ import annotations

import bpy

from .owned import made, mark

__all__ = ["RENDER", "POINTS", "POSES", "NODE_GROUP", "own", "node_group",
           "poses_collection", "points_object", "points_for"]

#: the mark (:mod:`.owned`) of Render Crowd's points object, its mesh, the pose
#: collection and the node group
RENDER = "render crowd"
POINTS = "Crowd Render"
POSES = "Crowd Poses"
NODE_GROUP = "Crowd Render Instances"


def node_group():
    """The Geometry Nodes group: Instance on Points picking ``crowd_pose`` from the
    pose collection, turned by ``crowd_heading`` and scaled by ``crowd_scale`` (a
    group made by an older version, unmarked, is left to the points object it
    served: that object gets this one)."""
    group = own(bpy.data.node_groups)
    if group is not None:
        return group
    group = mark(bpy.data.node_groups.new(NODE_GROUP, "GeometryNodeTree"), RENDER)
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    inp, out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    coll = nodes.new("GeometryNodeCollectionInfo")
    coll.inputs["Collection"].default_value = poses_collection()
    coll.inputs["Separate Children"].default_value = True
    coll.inputs["Reset Children"].default_value = True
    coll.transform_space = "ORIGINAL"
    pose = nodes.new("GeometryNodeInputNamedAttribute")
    pose.data_type = "INT"
    pose.inputs["Name"].default_value = "crowd_pose"
    heading = nodes.new("GeometryNodeInputNamedAttribute")
    heading.data_type = "FLOAT"
    heading.inputs["Name"].default_value = "crowd_heading"
    drawn = nodes.new("GeometryNodeInputNamedAttribute")
    drawn.data_type = "BOOLEAN"
    drawn.inputs["Name"].default_value = "crowd_drawn"
    scale = nodes.new("GeometryNodeInputNamedAttribute")
    scale.name = "crowd_scale"
    scale.data_type = "FLOAT"
    scale.inputs["Name"].default_value = "crowd_scale"
    euler = nodes.new("ShaderNodeCombineXYZ")
    inst = nodes.new("GeometryNodeInstanceOnPoints")
    inst.inputs["Pick Instance"].default_value = True
    links.new(inp.outputs[0], inst.inputs["Points"])
    links.new(drawn.outputs["Attribute"], inst.inputs["Selection"])
    links.new(coll.outputs[0], inst.inputs["Instance"])
    links.new(pose.outputs["Attribute"], inst.inputs["Instance Index"])
    links.new(heading.outputs["Attribute"], euler.inputs["Z"])
    links.new(euler.outputs[0], inst.inputs["Rotation"])
    links.new(scale.outputs["Attribute"], inst.inputs["Scale"])
    links.new(inst.outputs[0], out.inputs[0])
    return group


def own(data):
    """The datablock of ``data`` (a ``bpy.data`` collection) marked :data:`RENDER`, or None."""
    return next((block for block in data if made(block, RENDER)), None)


def poses_collection():
    """The collection of the pose objects (not linked to a scene: only instanced)."""
    coll = own(bpy.data.collections)
    return coll if coll is not None else mark(bpy.data.collections.new(POSES), RENDER)


def points_object():
    """Render Crowd's points object (marked, or made by an older version: named
    :data:`POINTS`, a mesh with the ``crowd_pose`` attribute and the Geometry Nodes
    modifier ``Crowd Instances``), or None."""
    obj = own(bpy.data.objects)
    if obj is not None:
        return obj
    obj = bpy.data.objects.get(POINTS)
    mod = obj.modifiers.get("Crowd Instances") if obj is not None else None
    older = (mod is not None and mod.type == "NODES" and obj.type == "MESH"
             and "crowd_pose" in obj.data.attributes)
    return obj if older else None


def points_for(scene, count: int):
    """The points object with ``count`` vertices and its modifier, linked to ``scene``."""
    obj = points_object()
    if obj is None:
        obj = bpy.data.objects.new(POINTS, bpy.data.meshes.new(POINTS))
    mark(obj, RENDER)
    mark(obj.data, RENDER)
    if obj.name not in scene.collection.objects:
        scene.collection.objects.link(obj)
    mesh = obj.data
    if len(mesh.vertices) != count:
        mesh.clear_geometry()
        mesh.vertices.add(count)
    for name, kind, domain in (("crowd_pose", "INT", "POINT"),
                               ("crowd_drawn", "BOOLEAN", "POINT"),
                               ("crowd_agent", "INT", "POINT"),
                               ("crowd_prop", "INT", "POINT"),
                               ("crowd_heading", "FLOAT", "POINT"),
                               ("crowd_scale", "FLOAT", "POINT"),
                               ("crowd_color", "FLOAT_COLOR", "POINT"),
                               *((f"crowd_palette{c}", "FLOAT_COLOR", "POINT")
                                 for c in range(4))):
        if mesh.attributes.get(name) is None:
            mesh.attributes.new(name, kind, domain)
    mod = obj.modifiers.get("Crowd Instances")
    if mod is None:
        mod = obj.modifiers.new("Crowd Instances", "NODES")
    if not made(mod.node_group, RENDER):
        mod.node_group = node_group()
    return obj
