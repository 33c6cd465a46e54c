"""*Generate Seats* (crowd_addon/blender/seats_operator.py): the Seats and Stands
meshes it makes hold what the core seat generator gives, and making them again
replaces the meshes of the same objects.

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


def _check(expected, seats, stands):
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
    assert [m.name for m in me.materials] == ["concrete", "home", "away"]
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
    bpy.data.objects.remove(seats)
    empty = bpy.data.objects.new("Seats", None)
    scene.collection.objects.link(empty)
    with pytest.raises(RuntimeError, match=r"'Seats' is not a mesh \(it is empty\)"):
        bpy.ops.crowd.generate_seats(seats=300)
    assert "Stands" not in bpy.data.objects
