"""Seat layout and bowl geometry of the sample stadium (numpy only, no Blender)."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from crowd_addon.core.errors import CrowdError

_PATH = Path(__file__).resolve().parents[2] / "sample_scenes" / "stadium_layout.py"


def _load():
    """The module by path, under the name build_stadium.py imports it by (one copy)."""
    if "stadium_layout" not in sys.modules:
        spec = importlib.util.spec_from_file_location("stadium_layout", _PATH)
        module = importlib.util.module_from_spec(spec)
        sys.modules["stadium_layout"] = module  # dataclasses look their module up
        spec.loader.exec_module(module)
    return sys.modules["stadium_layout"]


layout = _load()

BOWL = layout.Bowl()


def _behind(xy):
    """Distance of points (N, 2) behind the bowl's inner edge (the rounded rectangle)."""
    a, b = BOWL.half_straight
    dx = np.maximum(np.abs(xy[:, 0]) - a, 0.0)
    dy = np.maximum(np.abs(xy[:, 1]) - b, 0.0)
    return np.hypot(dx, dy) - BOWL.corner_radius


@pytest.mark.parametrize("count", [1, 7, 300, 2000, 65000])
def test_exact_count_on_the_treads(count):
    seats = layout.layout_seats(BOWL, count)
    assert seats.position.shape == (count, 3) and seats.position.dtype == np.float32
    assert seats.heading.shape == seats.section.shape == seats.row.shape == (count,)
    assert seats.rows == seats.row.max() + 1
    np.testing.assert_allclose(seats.position[:, 2], BOWL.floor_height(seats.row), atol=1e-5)
    # each seat sits seat_setback behind its row's front edge
    np.testing.assert_allclose(_behind(seats.position[:, :2]),
                               seats.row * BOWL.tread + BOWL.seat_setback, atol=1e-3)


def test_rows_are_as_few_as_the_seat_pitch_allows():
    seats = layout.layout_seats(BOWL, 65000)
    lengths = BOWL.perimeter(BOWL.row_radius(np.arange(seats.rows)))
    capacity = np.floor(lengths / BOWL.seat_pitch)
    assert capacity[:-1].sum() < 65000 <= capacity.sum()
    counts = np.bincount(seats.row)
    assert np.all(lengths / counts >= BOWL.seat_pitch * 0.99)
    # seats in a row are evenly spaced along it (neighbours at equal distance)
    row0 = seats.position[seats.row == 0, :2]
    gaps = np.linalg.norm(np.diff(np.vstack([row0, row0[:1]]), axis=0), axis=1)
    assert gaps.max() - gaps.min() < 0.01


def test_loop_points_are_continuous_and_normals_outward():
    radius = 20.0
    s = np.linspace(0.0, BOWL.perimeter(radius), 20001)
    points, normals = layout.loop_points(BOWL, s, radius)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    np.testing.assert_allclose(steps, s[1] - s[0], rtol=1e-3)
    np.testing.assert_allclose(points[0], points[-1], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    tangent = np.diff(points, axis=0)
    assert np.abs(np.einsum("ij,ij->i", tangent, normals[:-1])).max() < 1e-2 * (s[1] - s[0])
    # counter-clockwise, normal outward: the 2-D cross product (numpy 2 has no 2-D cross)
    z = tangent[:, 0] * normals[:-1, 1] - tangent[:, 1] * normals[:-1, 0]
    assert np.all(z < 0)


def test_headings_face_the_pitch_centre_and_sections_split_the_east_end():
    seats = layout.layout_seats(BOWL, 5000)
    forward = np.column_stack([np.sin(seats.heading), -np.cos(seats.heading)])
    to_centre = -seats.position[:, :2] / np.linalg.norm(seats.position[:, :2], axis=1)[:, None]
    assert np.einsum("ij,ij->i", forward, to_centre).min() > 0.9999
    away = seats.section == layout.AWAY
    assert set(np.unique(seats.section)) == {layout.HOME, layout.AWAY}
    assert np.all(seats.position[away, 0] > BOWL.half_straight[0])
    assert 0.05 < away.mean() < 0.25


def test_sweep_faces_point_up_and_towards_the_pitch():
    ring, normal = layout.bowl_ring(BOWL)
    rows = 3
    verts, quads = layout.sweep(ring, normal, layout.stand_profile(BOWL, rows))
    p = verts[quads]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    centre = p.mean(axis=1)
    tread = np.abs(n[:, 2]) > 0.9 * np.linalg.norm(n, axis=1)
    assert tread.sum() == (rows + 1) * len(ring) and np.all(n[tread, 2] > 0)
    inner = ~tread & (_behind(centre[:, :2]) < rows * BOWL.tread + 0.2)  # not the outer wall
    assert inner.sum() == (rows + 1) * len(ring)
    assert np.all(np.einsum("ij,ij->i", n[inner, :2], centre[inner, :2]) < 0)


@pytest.mark.parametrize("count", [0, -5])
def test_bad_seat_count_is_named(count):
    with pytest.raises(CrowdError, match="seats"):
        layout.layout_seats(BOWL, count)
