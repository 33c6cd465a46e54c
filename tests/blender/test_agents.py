"""Agents from scene geometry (crowd_addon.blender.agents).

Oracles: Blender's own object transforms and evaluated geometry (``matrix_world @
vertex.co`` with mathutils, vertex group weights, depsgraph instances, point
attributes) and mathutils rotations for headings. The placement policy on plain
arrays (seeded offsets, streams by weight or name, colours) is tested in
tests/core/test_placement.py.
"""

import math
import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402

from crowd_addon.blender.agents import agents_from_scene, agents_from_source  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.core.authoring.placement import CharacterStreams  # noqa: E402

STREAMS = ["idle", "cheer", "sit"]


extension = cs.extension_fixture()


@pytest.fixture
def scene():
    return cs.reset()


def _source(scene, obj, **props):
    src = scene.crowd.agent_sources.add()
    src.name = "seats"
    src.object = obj
    for k, v in props.items():
        setattr(src, k, v)
    return src


def _agents(scene, src, weights=(1, 1, 1), m=30, seed=4, forward="NEG_Y"):
    cast = (CharacterStreams("fan", tuple(STREAMS), tuple(weights)),)
    return agents_from_source(src, bpy.context.evaluated_depsgraph_get(), characters=cast,
                              max_offset=m, seed=seed, forward_axis=forward)


def _world_vertices(obj):
    return np.array([tuple(obj.matrix_world @ v.co) for v in obj.data.vertices])


def test_one_agent_per_vertex_at_its_world_position(scene):
    seats = cs.make_seats(7, 5)
    seats.location = (3.0, -2.0, 1.5)
    seats.rotation_euler = (0.0, 0.0, 0.7)
    seats.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    a = _agents(scene, _source(scene, seats))
    assert a.count == 35
    np.testing.assert_allclose(a.positions, _world_vertices(seats), atol=1e-5)
    # fixed heading 0 plus the object's own turn about +Z
    np.testing.assert_allclose(a.headings, 0.7, atol=1e-6)


def test_vertex_group_keeps_only_weighted_vertices(scene):
    seats = cs.make_seats(6, 6)
    group = seats.vertex_groups.new(name="front")
    group.add(list(range(0, 36, 3)), 0.8, "REPLACE")
    group.add([1, 2], 0.0, "REPLACE")               # members with weight 0 are not agents
    expected = [i for i in range(36)
                if any(g.group == group.index and g.weight > 0
                       for g in seats.data.vertices[i].groups)]
    a = _agents(scene, _source(scene, seats, mode="VERTEX_GROUP", vertex_group="front"))
    assert a.count == len(expected) == 12
    np.testing.assert_allclose(a.positions, _world_vertices(seats)[expected], atol=1e-6)


def test_headings_from_an_attribute_and_toward_a_target(scene):
    seats = cs.make_seats(5, 4)
    seats.rotation_euler.z = 0.25
    attr = seats.data.attributes.new("heading", "FLOAT", "POINT")
    values = np.linspace(-1.0, 1.0, 20, dtype=np.float32)
    attr.data.foreach_set("value", values)
    bpy.context.view_layer.update()
    a = _agents(scene, _source(scene, seats, heading_mode="ATTRIBUTE"))
    np.testing.assert_allclose(a.headings, values + 0.25, atol=1e-6)

    target = bpy.data.objects.new("Pitch", None)
    scene.collection.objects.link(target)
    target.location = (2.0, 20.0, 0.0)
    bpy.context.view_layer.update()
    for forward, vec in (("NEG_Y", (0, -1, 0)), ("POS_X", (1, 0, 0))):
        a = _agents(scene, _source(scene, seats, heading_mode="TARGET",
                                   heading_target=target), forward=forward)
        for p, h in zip(a.positions, a.headings):
            facing = Matrix.Rotation(float(h), 3, "Z") @ Vector(vec)
            to_target = (target.location - Vector(p)).to_2d().normalized()
            assert (facing.to_2d() - to_target).length < 1e-5


def test_offsets_streams_and_colours_from_attributes(scene):
    seats = cs.make_seats(4, 3)
    me = seats.data
    off = np.arange(12, dtype=np.int32) % 30
    me.attributes.new("offset", "INT", "POINT").data.foreach_set("value", off)
    st = np.arange(12, dtype=np.int32) % 3
    me.attributes.new("stream", "INT", "POINT").data.foreach_set("value", st)
    col = np.random.default_rng(0).uniform(0, 1, (12, 4)).astype(np.float32)
    me.attributes.new("Col", "FLOAT_COLOR", "POINT").data.foreach_set("color", col.ravel())
    bpy.context.view_layer.update()
    src = _source(scene, seats, offset_mode="ATTRIBUTE", stream_mode="ATTRIBUTE",
                  color_mode="ATTRIBUTE")
    a = _agents(scene, src)
    np.testing.assert_array_equal(a.offsets, off)
    np.testing.assert_array_equal(a.streams, st)
    np.testing.assert_allclose(a.colors, col[:, :3], atol=1e-6)
    # an offset outside 0..M-1 names the source, the point and the attribute
    off[5] = 30
    me.attributes["offset"].data.foreach_set("value", off)
    me.update()                      # as an edit in the UI tags it (Blender 4.2 needs it)
    bpy.context.view_layer.update()
    with pytest.raises(CrowdError, match=r"agent source 'seats'.*5.*offset 30.*'offset'"):
        _agents(scene, src)


def test_instances_use_the_depsgraph_instance_transforms(scene):
    grid = cs.make_seats(4, 4, name="Stand")
    grid.rotation_euler.z = 0.5
    grid.location = (1.0, 2.0, 3.0)
    grid.instance_type = "VERTS"
    seat = cs.make_seats(1, 1, name="Seat")
    seat.parent = grid
    bpy.context.view_layer.update()
    a = _agents(scene, _source(scene, grid, mode="INSTANCES"))
    dg = bpy.context.evaluated_depsgraph_get()
    truth = [tuple(i.matrix_world.translation) for i in dg.object_instances
             if i.is_instance and i.parent.original == grid]
    assert a.count == 16 == len(truth)
    np.testing.assert_allclose(np.sort(a.positions, 0), np.sort(np.array(truth), 0),
                               atol=1e-5)
    np.testing.assert_allclose(a.headings, 0.5, atol=1e-6)
    src = _source(scene, grid, mode="INSTANCES", heading_mode="ATTRIBUTE")
    with pytest.raises(CrowdError, match="attributes are read from mesh vertices"):
        _agents(scene, src)


def test_geometry_nodes_point_instances(scene):
    stand = cs.make_seats(5, 4, name="Stand")
    seat = cs.make_seats(1, 1, name="Seat")
    tree = bpy.data.node_groups.new("seats", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    group_in, group_out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    on_points = tree.nodes.new("GeometryNodeInstanceOnPoints")
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = seat
    on_points.inputs["Rotation"].default_value = (0.0, 0.0, -0.3)
    tree.links.new(group_in.outputs[0], on_points.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs["Instances"], group_out.inputs[0])
    stand.modifiers.new("seats", "NODES").node_group = tree
    stand.location.z = 2.0
    bpy.context.view_layer.update()
    a = _agents(scene, _source(scene, stand, mode="INSTANCES"))
    assert a.count == 20
    np.testing.assert_allclose(a.positions, _world_vertices(stand), atol=1e-6)
    np.testing.assert_allclose(a.headings, -0.3, atol=1e-6)


def test_bad_sources_name_the_problem(scene):
    seats = cs.make_seats(2, 2)
    with pytest.raises(CrowdError, match="agent source 'seats': no object chosen"):
        _agents(scene, _source(scene, None))
    with pytest.raises(CrowdError, match="no vertex group 'back'"):
        _agents(scene, _source(scene, seats, mode="VERTEX_GROUP", vertex_group="back"))
    with pytest.raises(CrowdError, match="has no attribute 'heading'"):
        _agents(scene, _source(scene, seats, heading_mode="ATTRIBUTE"))
    seats.data.attributes.new("heading", "INT", "POINT")
    with pytest.raises(CrowdError, match="'heading' of 'Seats' is INT on POINT"):
        _agents(scene, _source(scene, seats, heading_mode="ATTRIBUTE"))
    empty = bpy.data.objects.new("Empty", None)
    scene.collection.objects.link(empty)
    with pytest.raises(CrowdError, match="'Empty' is a EMPTY, not a mesh"):
        _agents(scene, _source(scene, empty))
    with pytest.raises(CrowdError, match="generates no instances"):
        _agents(scene, _source(scene, seats, mode="INSTANCES"))


def test_errors_name_the_object_of_an_unnamed_source(scene):
    # before: "agent source '': ..." said nothing about which source was wrong
    seats = cs.make_seats(2, 2)
    scene.crowd.agent_sources.clear()
    _source(scene, seats)
    _source(scene, seats, name="", mode="VERTEX_GROUP", vertex_group="back")
    rig = cs.make_armature()
    for name in STREAMS:
        cs.add_stream(cs.add_character(scene.crowd, rig) if name == STREAMS[0] else
                      scene.crowd, name, None)
    with pytest.raises(CrowdError, match=r"^agent source 2 \(object 'Seats'\): object 'Seats' "
                                         r"has no vertex group 'back'"):
        agents_from_scene(scene, bpy.context.evaluated_depsgraph_get())
    with pytest.raises(CrowdError, match=r"^agent source 'seats' \(object 'Seats'\): object "
                                         r"'Seats' has no vertex group 'back'"):
        _agents(scene, _source(scene, seats, mode="VERTEX_GROUP", vertex_group="back"))


def test_a_stadium_of_65k_seats(scene):
    """65,536 agents from a grid's vertices, half of them from a vertex group (how long
    it takes is benchmarks' business, not a test's)."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=255, y_subdivisions=255, size=200)
    stand = bpy.context.active_object
    stand.vertex_groups.new(name="lower").add(list(range(0, 65536, 2)), 1.0, "REPLACE")
    target = bpy.data.objects.new("Pitch", None)
    scene.collection.objects.link(target)
    bpy.context.view_layer.update()
    src = _source(scene, stand, heading_mode="TARGET", heading_target=target,
                  offset_mode="NORMAL")
    a = _agents(scene, src)
    assert a.count == 65536
    src.mode, src.vertex_group = "VERTEX_GROUP", "lower"
    b = _agents(scene, src)
    assert b.count == 32768
    assert math.isfinite(float(a.headings.sum()))


def test_agents_from_scene_tells_which_agents_each_source_made(scene):
    """``placed``: per enabled source, its agent id range and the vertex each agent
    stands on (None for instances), what cue selections read."""
    rig = cs.make_armature()
    cs.add_stream(cs.add_character(scene.crowd, rig), "idle", None)
    seats = cs.make_seats(6, 6)
    seats.vertex_groups.new(name="front").add([3, 8, 20, 33], 1.0, "REPLACE")
    grid = cs.make_seats(3, 2, name="Stand")
    grid.instance_type = "VERTS"
    cs.make_seats(1, 1, name="Seat").parent = grid
    bpy.context.view_layer.update()
    _source(scene, seats, name="front", mode="VERTEX_GROUP", vertex_group="front")
    _source(scene, seats, name="off", enabled=False)
    _source(scene, grid, name="stand", mode="INSTANCES")
    _source(scene, seats, name="all")
    agents, placed = agents_from_scene(scene, bpy.context.evaluated_depsgraph_get())
    assert agents.count == 4 + 6 + 36
    assert [(p.index, p.name, p.object_name, p.first, p.count) for p in placed] == [
        (0, "front", "Seats", 0, 4), (2, "stand", "Stand", 4, 6), (3, "all", "Seats", 10, 36)]
    np.testing.assert_array_equal(placed[0].rows, [3, 8, 20, 33])
    assert placed[0].rows.dtype == np.int64 and placed[1].rows is None
    np.testing.assert_array_equal(placed[2].rows, np.arange(36))
    world = _world_vertices(seats)
    np.testing.assert_allclose(agents.positions[placed[0].first:4], world[placed[0].rows],
                               atol=1e-6)
