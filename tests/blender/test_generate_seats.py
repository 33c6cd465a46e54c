"""*Generate Seats* (crowd_addon/blender/seats_operator.py): the Seats and Stands
meshes it makes hold what the core seat generator gives, making them again in a scene
replaces the meshes of the objects it made there, and nothing of the user's that
bears their names is changed.

Oracles: :func:`crowd_addon.core.authoring.seats.generate_seats` for the same spec, and Blender's
own data read back (vertex positions, point attributes, vertex groups, polygons)."""

import os
import sys
from dataclasses import replace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.core.authoring.seat_spec import SeatSpec, Tier, Tunnel  # noqa: E402
from crowd_addon.core.authoring.seats import generate_seats  # noqa: E402
from crowd_addon.blender.seats_operator import STAND_COLOURS  # noqa: E402

extension = cs.extension_fixture()

#: the operator's defaults as a spec (its floats as Blender stores them: float32)
_F = lambda x: float(np.float32(x))  # noqa: E731
DEFAULT = SeatSpec(
    tiers=(Tier(rows=32, tread=_F(0.8), riser=_F(0.4), setback=0.0, lift=_F(1.2)),
           Tier(rows=36, tread=_F(0.8), riser=_F(0.45), setback=_F(-3.2), lift=_F(4.0))),
    plan="rect", pitch=(105.0, 68.0), margin=(6.5, 6.0), corner_radius=14.0,
    seat_pitch=0.5, seat_width=_F(0.45), aisle_every=24, aisle_width=_F(1.2),
    tunnels=(Tunnel(90.0, width=6.0, rows=8),), away_end="east")


@pytest.fixture
def scene():
    return cs.reset()


def _points(obj):
    me = obj.data
    n = len(me.vertices)
    co = np.empty(3 * n, np.float32)
    me.vertices.foreach_get("co", co)
    out = {"position": co.reshape(n, 3)}
    for a in me.attributes:
        if a.domain == "POINT" and a.data_type in ("INT", "FLOAT") and not a.name.startswith("."):
            values = np.empty(n, np.int32 if a.data_type == "INT" else np.float32)
            a.data.foreach_get("value", values)
            out[a.name] = values
    return out


def _check(expected, seats, stands, home_material="home"):
    got = _points(seats)
    assert len(got["position"]) == len(expected)
    np.testing.assert_allclose(got["position"], expected.position, atol=1e-4)
    np.testing.assert_allclose(got["heading"], expected.heading, atol=1e-5)
    for name in ("section", "tier", "row", "seat", "team"):
        np.testing.assert_array_equal(got[name], getattr(expected, name), err_msg=name)
    kinds = {a.name: (a.data_type, a.domain) for a in seats.data.attributes}
    assert kinds["heading"] == ("FLOAT", "POINT") and kinds["team"] == ("INT", "POINT")
    groups = {g.index: g.name for g in seats.vertex_groups}
    away = np.array([[groups[g.group] for g in v.groups] == ["away"]
                     for v in seats.data.vertices])
    home = np.array([[groups[g.group] for g in v.groups] == ["home"]
                     for v in seats.data.vertices])
    np.testing.assert_array_equal(away, expected.team == 1)
    np.testing.assert_array_equal(home, expected.team == 0)
    mesh = expected.stands
    me = stands.data
    assert len(me.vertices) == len(mesh.vertices) and len(me.polygons) == len(mesh.sizes)
    sizes = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_total", sizes)
    np.testing.assert_array_equal(sizes, mesh.sizes)
    corners = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", corners)
    np.testing.assert_array_equal(corners, mesh.corners)
    material = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("material_index", material)
    np.testing.assert_array_equal(material, mesh.kind)
    assert [m.name for m in me.materials] == ["concrete", home_material, "away"]
    assert not me.validate()                        # nothing to fix


def test_generate_seats_makes_the_core_generators_seats_and_stands(scene):
    assert bpy.ops.crowd.generate_seats(seats=2000) == {"FINISHED"}
    expected = generate_seats(replace(DEFAULT, seats=2000))
    assert len(expected) == 2000
    _check(expected, bpy.data.objects["Seats"], bpy.data.objects["Stands"])


def test_generating_again_replaces_the_meshes_of_the_same_objects(scene):
    bpy.ops.crowd.generate_seats(seats=500)
    seats, stands = bpy.data.objects["Seats"], bpy.data.objects["Stands"]
    seats.location = (1.0, 2.0, 0.0)
    src = scene.crowd.agent_sources.add()
    src.object = seats
    meshes = len(bpy.data.meshes)
    result = bpy.ops.crowd.generate_seats(plan="OVAL", margin_end=20.0, margin_side=14.0,
                                          corner_radius=40.0, tiers=1, rows=(6, 1, 1),
                                          tunnels="0, 180", tunnel_rows=2, tunnel_width=4.0,
                                          away_end="WEST", aisle_every=16)
    assert result == {"FINISHED"}
    assert bpy.data.objects["Seats"] == seats and bpy.data.objects["Stands"] == stands
    assert tuple(seats.location) == (1.0, 2.0, 0.0) and src.object == seats
    assert len(bpy.data.meshes) == meshes                    # the old meshes are gone
    expected = generate_seats(SeatSpec(
        tiers=(Tier(rows=6, tread=_F(0.8), riser=_F(0.4), lift=_F(1.2)),), plan="oval",
        margin=(20.0, 14.0), corner_radius=40.0, seat_width=_F(0.45), aisle_every=16,
        aisle_width=_F(1.2), tunnels=(Tunnel(0.0, 4.0, 2), Tunnel(180.0, 4.0, 2)),
        away_end="west"))
    _check(expected, seats, stands)


def test_bad_input_is_reported_and_changes_nothing(scene):
    bpy.ops.crowd.generate_seats(seats=300, make_stands=False)
    seats = bpy.data.objects["Seats"]
    mesh = seats.data
    assert "Stands" not in bpy.data.objects
    for props, words in (({"tunnels": "north"}, "tunnels"),
                         ({"seat_width": 0.6}, "seat_width"),
                         ({"plan": "OVAL"}, "margin")):
        with pytest.raises(RuntimeError, match=words):
            bpy.ops.crowd.generate_seats(**props)
        assert bpy.data.objects["Seats"].data == mesh and len(mesh.vertices) == 300


def test_the_users_objects_and_materials_of_the_same_names_are_left_alone(scene):
    """Generate Seats makes its own objects and materials beside the user's "Seats",
    "Stands" and "home" (before, it gave the user's objects its meshes, deleting the
    Stands' own, rebuilt the Seats' vertex groups and recoloured the material), and
    making them again replaces its own, not the user's."""
    cube = bpy.data.objects.new("Stands", _box("MyStandsMesh"))
    mine = bpy.data.objects.new("Seats", _box("MySeatsMesh"))
    for obj in (cube, mine):
        scene.collection.objects.link(obj)
    mine.vertex_groups.new(name="home").add([0, 1], 0.5, "REPLACE")
    red = bpy.data.materials.new("home")
    red.diffuse_color = (1.0, 0.0, 0.0, 1.0)

    def intact():
        assert bpy.data.objects["Stands"] == cube and cube.data.name == "MyStandsMesh"
        assert bpy.data.objects["Seats"] == mine and mine.data.name == "MySeatsMesh"
        assert len(cube.data.vertices) == len(mine.data.vertices) == 8
        assert [g.name for g in mine.vertex_groups] == ["home"]
        assert [[(g.group, g.weight) for g in v.groups] for v in mine.data.vertices] == \
            [[(0, 0.5)]] * 2 + [[]] * 6
        assert tuple(red.diffuse_color) == (1.0, 0.0, 0.0, 1.0)

    assert bpy.ops.crowd.generate_seats(seats=300) == {"FINISHED"}
    intact()
    seats, stands = bpy.data.objects["Seats.001"], bpy.data.objects["Stands.001"]
    assert [m.name for m in stands.data.materials] == ["concrete", "home.001", "away"]
    np.testing.assert_allclose(stands.data.materials[1].diffuse_color, STAND_COLOURS["home"],
                               atol=1e-6)
    _check(generate_seats(replace(DEFAULT, seats=300)), seats, stands, "home.001")
    meshes, materials = len(bpy.data.meshes), len(bpy.data.materials)
    assert bpy.ops.crowd.generate_seats(seats=200) == {"FINISHED"}      # again: its own
    intact()
    assert bpy.data.objects["Seats.001"] == seats and bpy.data.objects["Stands.001"] == stands
    assert "Seats.002" not in bpy.data.objects and "Stands.002" not in bpy.data.objects
    assert (len(bpy.data.meshes), len(bpy.data.materials)) == (meshes, materials)
    _check(generate_seats(replace(DEFAULT, seats=200)), seats, stands, "home.001")


def test_each_scene_gets_seats_of_its_own(scene):
    """Generate Seats in a second scene makes that scene's objects and leaves the first
    scene's as they were (before, it gave the first scene's objects the new meshes and
    made nothing in the second); generating again in either replaces its own."""
    assert bpy.ops.crowd.generate_seats(seats=300) == {"FINISHED"}
    seats_a, stands_a = bpy.data.objects["Seats"], bpy.data.objects["Stands"]
    mesh_a = seats_a.data
    other = bpy.data.scenes.new("Other")
    bpy.context.window.scene = other
    assert bpy.ops.crowd.generate_seats(seats=500, make_stands=False) == {"FINISHED"}
    (seats_b,) = other.objects
    assert seats_b.name == "Seats.001" and len(seats_b.data.vertices) == 500
    assert seats_a.data == mesh_a and len(mesh_a.vertices) == 300
    assert set(scene.objects) == {seats_a, stands_a}
    assert bpy.ops.crowd.generate_seats(seats=400) == {"FINISHED"}     # again, in Other
    assert set(other.objects) - {seats_b} == {bpy.data.objects["Stands.001"]}
    assert seats_b.name == "Seats.001" and len(seats_b.data.vertices) == 400
    assert seats_a.data == mesh_a and len(mesh_a.vertices) == 300
    bpy.context.window.scene = scene
    assert bpy.ops.crowd.generate_seats(seats=200) == {"FINISHED"}     # and in the first
    assert set(scene.objects) == {seats_a, stands_a} and len(seats_a.data.vertices) == 200
    assert len(seats_b.data.vertices) == 400


def _box(name):
    """A mesh of the eight corners of a unit cube and its six faces."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)], [],
                   [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
                    (1, 5, 7, 3)])
    return me
