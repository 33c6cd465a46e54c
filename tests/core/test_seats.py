"""The seat generator (crowd_addon/core/authoring/seats.py): counts, spacing, aisles, tunnels,
headings, the closest seats, attributes, tiers, the stands mesh and bad input.

The checks are geometric and independent of how the generator works inside: rows are
read back by sorting their seats round the pitch centre, and the closest pair of
seats is found by a sweep over the seats sorted along X."""

import math

import numpy as np
import pytest

from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.authoring.seat_spec import AWAY, HOME, SeatSpec, Tier, Tunnel
from crowd_addon.core.authoring.seats import generate_seats, plan_ring
from crowd_addon.core.authoring.stands import AWAY_BENCH, CONCRETE, HOME_BENCH

TWO_TIERS = (Tier(rows=12), Tier(rows=10, riser=0.5, setback=-2.4, lift=4.0))
TUNNELS = (Tunnel(90.0, width=6.0, rows=5), Tunnel(-90.0, width=4.0, rows=3))
SPEC = SeatSpec(tiers=TWO_TIERS, tunnels=TUNNELS)
OVAL = SeatSpec(plan="oval", margin=(20.0, 14.0), corner_radius=40.0, tiers=TWO_TIERS)


@pytest.fixture(scope="module")
def bowl():
    return generate_seats(SPEC)


def _along(layout, mask):
    """Indices of the seats in ``mask`` sorted round the pitch centre (counter-clockwise
    from -X), and their positions."""
    idx = np.flatnonzero(mask)
    pos = layout.position[idx].astype(np.float64)
    order = np.argsort(np.arctan2(pos[:, 1], pos[:, 0]), kind="stable")
    return idx[order], pos[order]


def _closest_pair(pos):
    """The smallest distance between two of the points (N, 3): a sweep over the points
    sorted by x, comparing each with the next ones while they are within the best
    distance found so far along x."""
    pos = pos[np.argsort(pos[:, 0], kind="stable")].astype(np.float64)
    best = np.inf
    for lag in range(1, len(pos)):
        dx = pos[lag:, 0] - pos[:-lag, 0]
        near = dx < best
        if not near.any():
            break
        d = np.linalg.norm(pos[lag:][near] - pos[:-lag][near], axis=1)
        best = min(best, float(d.min()))
    return best


def test_the_count_is_what_the_rows_hold_or_exactly_the_target(bowl):
    assert len(bowl) == bowl.capacity and bowl.rows == (12, 10)
    for n in (1, 7, 300, 2000, 12345):
        layout = generate_seats(SeatSpec(tiers=TWO_TIERS, tunnels=TUNNELS, seats=n))
        assert len(layout) == n and layout.position.shape == (n, 3)
        assert layout.capacity >= n
        for name in ("heading", "section", "tier", "row", "seat", "team"):
            assert getattr(layout, name).shape == (n,), name


def test_a_target_count_fills_the_lower_tier_first_then_grows_both():
    small = generate_seats(SeatSpec(tiers=TWO_TIERS, seats=2000))
    assert small.rows[1] == 1 and 1 < small.rows[0] < 12
    big = generate_seats(SeatSpec(tiers=TWO_TIERS, seats=65000))
    assert len(big) == 65000 and big.rows[0] > 12 and big.rows[1] > 10
    ratio = big.rows[0] / big.rows[1]
    assert abs(ratio - 12 / 10) < 0.1                       # the tiers' proportions
    # the surplus is left empty in the row added last, the rest of it spread evenly
    partial = [(t, r) for t in range(2) for r in range(big.rows[t])
               if 0 < ((big.tier == t) & (big.row == r)).sum()
               < ((big.tier == t) & (big.row == r - 1)).sum() * 0.98]
    assert len(partial) <= 1
    fewer = generate_seats(SeatSpec(tiers=TWO_TIERS, seats=64000))
    assert sum(fewer.rows) <= sum(big.rows)


def test_seats_are_a_seat_pitch_apart_along_each_row(bowl):
    spec = bowl.spec
    clear = max(t.rows for t in TUNNELS)             # the first row behind the tunnels
    for tier, first in ((0, clear), (1, 0)):
        for row in (first, bowl.rows[tier] - 1):
            keys = np.stack([bowl.section, bowl.seat], 1)
            mask = (bowl.tier == tier) & (bowl.row == row)
            idx = np.flatnonzero(mask)
            idx = idx[np.lexsort((keys[idx, 1], keys[idx, 0]))]
            same = np.diff(bowl.section[idx]) == 0
            step = np.linalg.norm(np.diff(bowl.position[idx], axis=0), axis=1)[same]
            gap_in_numbers = np.diff(bowl.seat[idx])[same]
            assert np.all(gap_in_numbers == 1)
            np.testing.assert_allclose(step, spec.seat_pitch, atol=2e-5)   # float32


def test_aisles_separate_the_sections_and_hold_no_seat(bowl):
    spec = bowl.spec
    for tier in (0, 1):
        for row in (0, 5, bowl.rows[tier] - 1):
            idx, pos = _along(bowl, (bowl.tier == tier) & (bowl.row == row))
            gap = np.linalg.norm(np.diff(np.vstack([pos, pos[:1]]), axis=0), axis=1)
            changes = bowl.section[idx] != np.roll(bowl.section[idx], -1)
            # between sections: an aisle plus a seat's width at least; within: a seat pitch
            assert gap[changes].min() >= spec.aisle_width + spec.seat_width - 1e-3
            tunnel_rows = tier == 0 and row < max(t.rows for t in TUNNELS)
            inside = gap[~changes]
            if not tunnel_rows:
                np.testing.assert_allclose(inside, spec.seat_pitch, atol=1e-3)
            # as many aisles as sections in the tier
            assert changes.sum() == len(np.unique(bowl.section[bowl.tier == tier]))


def test_aisles_every_k_seats_and_none_but_the_joints():
    """Sections hold about aisle_every seats on the tier's front row; with 0 the only
    aisles are the joints between the stands and the corners (8 sections a tier)."""
    spec = SeatSpec(tiers=(Tier(rows=3),), aisle_every=20)
    layout = generate_seats(spec)
    front = layout.row == 0
    per_section = np.bincount(layout.section[front])
    assert layout.sections > 8
    assert 0.6 * 20 <= per_section.min() and per_section.max() <= 1.5 * 20
    joints_only = generate_seats(SeatSpec(tiers=(Tier(rows=3),), aisle_every=0))
    assert joints_only.sections == 8
    assert generate_seats(SeatSpec(plan="oval", margin=(20.0, 14.0), corner_radius=40.0,
                                   aisle_every=0)).sections == 4


def test_tunnels_leave_a_gap_through_the_front_rows(bowl):
    spec = bowl.spec
    for tunnel in TUNNELS:
        direction = np.array([math.cos(math.radians(tunnel.angle)),
                              math.sin(math.radians(tunnel.angle))])
        lower = bowl.tier == 0
        pos = bowl.position[:, :2].astype(np.float64)
        ahead = pos @ direction > 0
        sideways = np.abs(pos @ np.array([-direction[1], direction[0]]))
        cut = lower & (bowl.row < tunnel.rows) & ahead
        # on a straight stand the gap's walls are parallel: no seat within half its width
        assert sideways[cut].min() >= 0.5 * tunnel.width + 0.5 * spec.seat_width - 1e-3
        behind = lower & (bowl.row >= tunnel.rows) & ahead
        assert sideways[behind].min() < spec.seat_pitch          # seated again behind it
    with pytest.raises(CrowdError, match=r"tunnels\[1\]: overlaps tunnels\[0\]"):
        generate_seats(SeatSpec(tunnels=(Tunnel(90.0, 6.0), Tunnel(91.0, 6.0))))


def test_headings_face_the_pitch_centre(bowl):
    forward = np.column_stack([np.sin(bowl.heading), -np.cos(bowl.heading)])
    to_centre = -bowl.position[:, :2] / np.linalg.norm(bowl.position[:, :2], axis=1)[:, None]
    assert np.einsum("ij,ij->i", forward, to_centre).min() > 0.99999
    oval = generate_seats(OVAL)
    forward = np.column_stack([np.sin(oval.heading), -np.cos(oval.heading)])
    to_centre = -oval.position[:, :2] / np.linalg.norm(oval.position[:, :2], axis=1)[:, None]
    assert np.einsum("ij,ij->i", forward, to_centre).min() > 0.99999


@pytest.mark.parametrize("spec", [SPEC, OVAL, SeatSpec(seat_pitch=0.55, seat_width=0.55,
                                                       aisle_width=0.05, corner_radius=3.0),
                                  SeatSpec(tiers=TWO_TIERS, tunnels=TUNNELS, seats=65000)],
                         ids=["rect", "oval", "tight", "65k"])
def test_no_two_seats_are_closer_than_a_seat_width(spec):
    """Also with seats as wide as their pitch round corners of 3 m: neighbours on a
    curve are a pitch apart in a straight line (more along the curve); across a
    narrow aisle the curve costs less than its width."""
    layout = generate_seats(spec)
    assert _closest_pair(layout.position) >= spec.seat_width - 1e-4


def test_attributes(bowl):
    assert bowl.position.dtype == bowl.heading.dtype == np.float32
    for name in ("section", "tier", "row", "seat", "team"):
        assert getattr(bowl, name).dtype == np.int32, name
    assert set(np.unique(bowl.tier)) == {0, 1}
    for t in (0, 1):
        rows = bowl.row[bowl.tier == t]
        assert rows.min() == 0 and rows.max() == bowl.rows[t] - 1
    assert bowl.section.min() == 0 and bowl.section.max() == bowl.sections - 1
    assert np.unique(bowl.section).size == bowl.sections
    # a section lies in one tier; within a section's row the seats are numbered 0..n-1
    tiers_of = np.zeros(bowl.sections, np.int64)
    tiers_of[bowl.section] = bowl.tier
    np.testing.assert_array_equal(tiers_of[bowl.section], bowl.tier)
    key = (bowl.section.astype(np.int64) * 1000 + bowl.row) * 10000 + bowl.seat
    assert np.unique(key).size == len(bowl)
    counts = np.bincount(bowl.section * 1000 + bowl.row)
    top = np.zeros_like(counts)
    np.maximum.at(top, bowl.section * 1000 + bowl.row, bowl.seat + 1)
    np.testing.assert_array_equal(top[counts > 0], counts[counts > 0])
    # the away fans: every seat of the stand behind the east goal, and nothing else
    a = 0.5 * bowl.spec.pitch[0] + bowl.spec.margin[0] - bowl.spec.corner_radius
    b = 0.5 * bowl.spec.pitch[1] + bowl.spec.margin[1] - bowl.spec.corner_radius
    east = (bowl.position[:, 0] > a) & (np.abs(bowl.position[:, 1]) <= b + 1e-3)
    np.testing.assert_array_equal(bowl.team == AWAY, east)
    assert set(np.unique(bowl.team)) == {HOME, AWAY}
    west = generate_seats(SeatSpec(tiers=(Tier(rows=2),), away_end="west"))
    assert np.all(west.position[west.team == AWAY, 0] < -a)
    assert np.all(generate_seats(SeatSpec(tiers=(Tier(rows=2),), away_end="none")).team == HOME)


def test_rows_step_up_and_the_upper_tier_sits_above_and_over_the_lower(bowl):
    spec = bowl.spec
    lower, upper = spec.tiers
    z = bowl.position[:, 2]
    for t, tier in enumerate(spec.tiers):
        m = bowl.tier == t
        np.testing.assert_allclose(z[m], bowl.heights[t] + bowl.row[m] * tier.riser, atol=1e-4)
    assert bowl.heights[0] == pytest.approx(lower.lift)
    last_lower = lower.lift + (bowl.rows[0] - 1) * lower.riser
    assert bowl.heights[1] == pytest.approx(last_lower + upper.lift)
    back = bowl.fronts[0] + bowl.rows[0] * lower.tread
    assert bowl.fronts[1] == pytest.approx(back + upper.setback)
    # distance behind the stands' front edge (on the straight north stand: y - B)
    north = (np.abs(bowl.position[:, 0]) < 20) & (bowl.position[:, 1] > 0)
    edge = 0.5 * spec.pitch[1] + spec.margin[1]
    behind = bowl.position[north, 1] - edge
    expect = (np.asarray(bowl.fronts)[bowl.tier[north]] + spec.seat_setback
              + bowl.row[north] * np.array([lower.tread, upper.tread])[bowl.tier[north]])
    np.testing.assert_allclose(behind, expect, atol=1e-4)


def test_an_overhang_never_reaches_in_front_of_the_tier_below():
    layout = generate_seats(SeatSpec(tiers=(Tier(rows=2), Tier(rows=2, setback=-20.0,
                                                                lift=4.0))))
    assert layout.fronts[1] == layout.fronts[0]


def test_the_stands_mesh(bowl):
    st = bowl.stands
    assert st.vertices.shape[1] == 3 and len(st.sizes) == len(st.kind)
    assert st.corners.min() >= 0 and st.corners.max() < len(st.vertices)
    assert st.sizes.sum() == len(st.corners) and st.sizes.min() >= 3
    assert set(np.unique(st.kind)) == {CONCRETE, HOME_BENCH, AWAY_BENCH}
    # faces are flat and not degenerate; treads face up (Newell normals)
    normals = np.zeros((len(st.sizes), 3))
    for i, (start, size) in enumerate(zip(st.starts, st.sizes)):
        p = st.vertices[st.corners[start:start + size]]
        q = np.roll(p, -1, axis=0)
        normals[i] = [((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])).sum(),
                      ((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])).sum(),
                      ((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1])).sum()]
    assert np.linalg.norm(normals, axis=1).min() > 1e-6
    # every seat stands on an upward face at its height: a tread level with it nearby
    concrete = st.kind == CONCRETE
    up = concrete & (normals[:, 2] > 0.99 * np.linalg.norm(normals, axis=1))
    heights = np.unique([st.vertices[st.corners[s], 2] for s in st.starts[up]])
    seat_z = np.unique(bowl.position[:, 2]).astype(np.float64)
    assert np.abs(seat_z[:, None] - heights[None, :]).min(1).max() < 1e-5
    # the bench boxes are closed and face outwards: their signed volume is positive
    bench = ~concrete
    centre = np.array([st.vertices[st.corners[s:s + n]].mean(0)
                       for s, n in zip(st.starts[bench], st.sizes[bench])])
    volume = np.einsum("ij,ij->", centre, normals[bench]) / 6
    bf, bb, bh = bowl.spec.bench
    box = (bb - bf) * bh                     # a bench runs from seat edge to seat edge
    # (round a corner a bench, behind the seats, is a little longer than their row)
    n = len(bowl)
    assert n * bowl.spec.seat_width * box < volume < 1.02 * n * bowl.spec.seat_pitch * box


def test_plan_ring_is_the_stands_front_edge():
    ring, normal = plan_ring(SPEC)
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0)
    assert np.abs(ring[:, 0]).max() == pytest.approx(0.5 * 105 + 6.5)
    assert np.abs(ring[:, 1]).max() == pytest.approx(0.5 * 68 + 6.0)
    oval, _ = plan_ring(OVAL)
    assert np.abs(oval[:, 0]).max() == pytest.approx(0.5 * 105 + 20.0, abs=0.05)


def test_the_same_spec_gives_the_same_seats():
    a, b = generate_seats(SPEC), generate_seats(SPEC)
    for name in ("position", "heading", "section", "tier", "row", "seat", "team"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(a.stands.vertices, b.stands.vertices)


@pytest.mark.parametrize("spec, field", [
    (SeatSpec(seats=0), "seats"),
    (SeatSpec(seats=2.5), "seats"),
    (SeatSpec(plan="square"), "plan"),
    (SeatSpec(away_end="north"), "away_end"),
    (SeatSpec(pitch=(105.0,)), "pitch"),
    (SeatSpec(margin=(-1.0, 6.0)), r"margin\[0\]"),
    (SeatSpec(corner_radius=0.0), "corner_radius"),
    (SeatSpec(corner_radius=45.0), "corner_radius"),
    (SeatSpec(corner_radius=1.0, margin=(0.0, 0.0)), "corner_radius"),
    (SeatSpec(plan="oval"), "margin"),
    (SeatSpec(plan="oval", corner_radius=50.0), "corner_radius"),
    (SeatSpec(seat_width=0.6), "seat_width"),
    (SeatSpec(seat_pitch=float("nan")), "seat_pitch"),
    (SeatSpec(aisle_every=-1), "aisle_every"),
    (SeatSpec(aisle_width=-0.5), "aisle_width"),
    (SeatSpec(bench=(0.5, 0.4, 0.45)), r"bench\[1\]"),
    (SeatSpec(tiers=()), "tiers"),
    (SeatSpec(tiers=(Tier(rows=0),)), r"tiers\[0\]\.rows"),
    (SeatSpec(tiers=(Tier(tread=0.2),)), r"tiers\[0\]\.tread"),
    (SeatSpec(tiers=(Tier(riser=-0.1),)), r"tiers\[0\]\.riser"),
    (SeatSpec(tiers=(Tier(setback=-1.0),)), r"tiers\[0\]\.setback"),
    (SeatSpec(tiers=(Tier(), Tier(setback=-3.0, lift=2.0))), r"tiers\[1\]\.lift"),
    (SeatSpec(tiers=(Tier(), "upper")), r"tiers\[1\]"),
    (SeatSpec(tunnels=(Tunnel(90.0, width=0.0),)), r"tunnels\[0\]\.width"),
    (SeatSpec(tunnels=(Tunnel(90.0, rows=0),)), r"tunnels\[0\]\.rows"),
    (SeatSpec(tunnels=(90.0,)), r"tunnels\[0\]"),
])
def test_bad_input_names_the_field(spec, field):
    with pytest.raises(CrowdError, match=rf"seat generator: {field}"):
        generate_seats(spec)
