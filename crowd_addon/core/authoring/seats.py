"""Stadium seats and stands from a cross-section and a plan (numpy only).

:func:`generate_seats` turns a description of a stadium (:class:`SeatSpec`) into
agent points, one per seat, and the stands' geometry:

plan
    The stands' front edge, the *inner loop*, round a pitch centred at the origin with
    its length along X. ``"rect"``: four straight stands joined by quarter-circle
    corners of ``corner_radius``; ``"oval"``: a four-centre oval, end arcs of
    ``corner_radius`` joined by flatter side arcs. Its half extents are half the pitch
    plus ``margin`` (behind each goal line, beside each touchline). Everything behind
    it lies on an *offset loop* ``d`` metres out along the loop's normal (arcs grow,
    straights keep their length). A point is addressed by its loop parameter ``u``
    (segment ``j`` plus the fraction along it; the loop starts at the south end of the
    east stand and runs counter-clockwise) and its offset ``d``; a line of constant
    ``u`` runs straight out from the pitch: aisles and tunnel walls follow such lines.
cross-section
    ``tiers``: each ``rows`` rows, each row a tread ``tread`` deep and ``riser`` higher
    than the row in front. The first tier starts ``setback`` behind the inner loop with
    its first tread ``lift`` above the pitch (the front wall); a later tier starts
    ``setback`` behind the back of the tier below (negative: it hangs over that tier's
    back rows, but never reaches in front of that tier) with its first tread ``lift``
    above the last tread below, its underside ``slab`` under its first tread. A seat is
    where a fan's feet rest, ``seat_setback`` behind its row's front edge; each row has
    a bench ``bench = (front, back, height)`` measured from the row's front edge.
aisles and sections
    Aisles ``aisle_width`` wide run up every tier at each joint of the plan (between a
    stand and a corner) and split each stand or corner into blocks of about
    ``aisle_every`` seats on the tier's front row (0: only the joints). A block of a
    tier with the same block in the rows behind it is a *section*, numbered from 0
    round the bowl, tier after tier. Neighbours in a row are ``seat_pitch`` apart,
    centre to centre in a straight line (a little more along a curved row), as many as
    fit the block at ``seat_width`` each, centred in it; seats across an aisle are at
    least its width plus a seat's width apart along the row.
tunnels
    :class:`Tunnel`: a gap ``width`` wide (on the first tier's front row) through the
    first ``rows`` rows of the first tier, centred where the direction ``angle``
    degrees from the pitch centre (0 = east, counter-clockwise) meets the stands.
teams
    ``away_end``: the stand behind the east or the west goal (the straight of a
    ``"rect"``, the end arc of an ``"oval"``), all its sections in every tier, holds
    the away fans (team 1); the other seats are home (team 0); ``"none"``: all home.
seat count
    ``seats=None`` builds the tiers as given. ``seats=N`` sizes the bowl to hold
    exactly ``N``: starting from one row per tier, rows are added one at a time, to
    the lowest tier that has fewer than its given rows, and once every tier has them,
    to the tier furthest below its share of them, until the bowl holds ``N`` or more;
    the surplus is left empty in the rows added last, the seats kept there spread
    evenly along the row. The stands are built whole.

Each seat has a heading, the rotation about +Z that turns a character facing -Y at
rest towards the pitch centre: ``forward = (sin h, -cos h, 0)``. Units are metres, Z
up, the pitch's surface at z = 0. Everything is vectorised; the same spec always gives
the same seats.

The parts: the spec (:mod:`.seat_spec`), the plan's loop and the cross-section
(:mod:`.seat_plan`), aisles, rows, tunnels and the seat count (:mod:`.seat_rows`) and
the stands' mesh (:mod:`.stands`); this module checks the spec and puts them together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..base.errors import CrowdError
from .seat_plan import BACK_WALL, Loop, place_tiers
from .seat_rows import bowl_rows, seat_line, size_rows, trim, tunnel_spans
from .seat_spec import ENDS, MAX_SEATS, MAX_TIERS, PLANS, SeatSpec, Tier, Tunnel
from .stands import StandsMesh, stands_mesh

__all__ = ["SeatLayout", "generate_seats", "plan_ring"]

_HEADROOM = 2.2                   # an overhanging tier's underside above the last row below


@dataclass(frozen=True)
class SeatLayout:
    """The generated seats (N of them) and stands.

    position : (N, 3) float32. heading : (N,) float32 radians about +Z, facing the
    pitch centre. section, tier, row, seat, team : (N,) int32: the section (block) from
    0 round the bowl tier after tier, the tier from 0, the row within the tier from
    the front, the seat's number in its section's row (counter-clockwise, from 0; a
    seat left empty by a seat count keeps its number's place), 0 home / 1 away.
    rows : rows built per tier. fronts, heights : per tier, the offset of its front
    edge behind the stands' front edge and the height of its first tread. sections :
    sections of the bowl. capacity : the seats the built rows hold. stands :
    :class:`StandsMesh`. spec : the :class:`SeatSpec` (checked).
    """

    position: np.ndarray
    heading: np.ndarray
    section: np.ndarray
    tier: np.ndarray
    row: np.ndarray
    seat: np.ndarray
    team: np.ndarray
    rows: tuple
    fronts: tuple
    heights: tuple
    sections: int
    capacity: int
    stands: StandsMesh
    spec: SeatSpec

    def __len__(self):
        return len(self.heading)


def plan_ring(spec: SeatSpec, offset: float = 0.0):
    """The plan's loop ``offset`` metres behind the stands' front edge, for meshing (the
    apron inside the stands): points (K, 2) counter-clockwise and outward normals."""
    spec = _checked(spec)
    loop = Loop(spec)
    return loop.point(loop.ring(), float(offset))


# --- checking the spec ---------------------------------------------------------------

def _number(value, name, low=None, high=None, low_open=False, integer=False):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise CrowdError(f"seat generator: {name}: expected a number, got {value!r}")
    if not math.isfinite(float(value)):
        raise CrowdError(f"seat generator: {name}: expected a finite number, got {value!r}")
    if integer and int(value) != value:
        raise CrowdError(f"seat generator: {name}: expected a whole number, got {value!r}")
    value = float(value)
    if low is not None and (value <= low if low_open else value < low):
        raise CrowdError(f"seat generator: {name}: must be {'above' if low_open else 'at least'}"
                         f" {low:g}, got {value:g}")
    if high is not None and value > high:
        raise CrowdError(f"seat generator: {name}: must be at most {high:g}, got {value:g}")
    return int(value) if integer else value


def _pair(value, name, low, low_open):
    try:
        a, b = value
    except (TypeError, ValueError):
        raise CrowdError(f"seat generator: {name}: expected two numbers, got {value!r}") from None
    return (_number(a, f"{name}[0]", low, low_open=low_open),
            _number(b, f"{name}[1]", low, low_open=low_open))


def _checked(spec: SeatSpec) -> SeatSpec:
    """``spec`` with plain numbers and tuples, or a CrowdError naming the field at fault."""
    if not isinstance(spec, SeatSpec):
        raise CrowdError(f"seat generator: expected a SeatSpec, got {type(spec).__name__}")
    if spec.plan not in PLANS:
        raise CrowdError(f"seat generator: plan: expected one of {PLANS}, got {spec.plan!r}")
    if spec.away_end not in ENDS:
        raise CrowdError(f"seat generator: away_end: expected one of {ENDS}, got "
                         f"{spec.away_end!r}")
    pitch = _pair(spec.pitch, "pitch", 0.0, True)
    margin = _pair(spec.margin, "margin", 0.0, False)
    radius = _number(spec.corner_radius, "corner_radius", 0.0, low_open=True)
    big_a, big_b = 0.5 * pitch[0] + margin[0], 0.5 * pitch[1] + margin[1]
    if spec.plan == "rect" and radius > min(big_a, big_b):
        raise CrowdError(f"seat generator: corner_radius: at most the stands' half width "
                         f"{min(big_a, big_b):g} m (half the pitch plus the margin), got "
                         f"{radius:g}")
    if spec.plan == "oval" and not radius < big_b < big_a:
        raise CrowdError(f"seat generator: corner_radius: an oval's end radius must be below "
                         f"its half width {big_b:g} m, itself below its half length "
                         f"{big_a:g} m (half the pitch plus the margin), got {radius:g}")
    seat_pitch = _number(spec.seat_pitch, "seat_pitch", 0.0, low_open=True)
    seat_width = _number(spec.seat_width, "seat_width", 0.0, seat_pitch, low_open=True)
    setback = _number(spec.seat_setback, "seat_setback", 0.0)
    try:
        bench = tuple(spec.bench)
    except TypeError:
        bench = ()
    if len(bench) != 3:
        raise CrowdError(f"seat generator: bench: expected (front, back, height), got "
                         f"{spec.bench!r}")
    bench = (_number(bench[0], "bench[0] (front)", 0.0),
             _number(bench[1], "bench[1] (back)", bench[0], low_open=True),
             _number(bench[2], "bench[2] (height)", 0.0, low_open=True))
    aisle_every = _number(spec.aisle_every, "aisle_every", 0, integer=True)
    aisle_width = _number(spec.aisle_width, "aisle_width", 0.0)
    if not isinstance(spec.tiers, (tuple, list)) or not 1 <= len(spec.tiers) <= MAX_TIERS:
        raise CrowdError(f"seat generator: tiers: expected 1 to {MAX_TIERS} Tier, got "
                         f"{spec.tiers!r}")
    tiers = []
    for t, tier in enumerate(spec.tiers):
        name = f"tiers[{t}]"
        if not isinstance(tier, Tier):
            raise CrowdError(f"seat generator: {name}: expected a Tier, got {tier!r}")
        tread = _number(tier.tread, f"{name}.tread", 0.0, low_open=True)
        if setback >= tread or bench[1] > tread or seat_width > tread:
            raise CrowdError(f"seat generator: {name}.tread: {tread:g} m leaves no room for the "
                             f"seat ({seat_width:g} m wide, {setback:g} m behind the row's "
                             f"front) and its bench (to {bench[1]:g} m)")
        tier = Tier(rows=_number(tier.rows, f"{name}.rows", 1, 100000, integer=True),
                    tread=tread, riser=_number(tier.riser, f"{name}.riser", 0.0, 1.0),
                    setback=_number(tier.setback, f"{name}.setback", 0.0 if t == 0 else None),
                    lift=_number(tier.lift, f"{name}.lift", 0.0),
                    slab=_number(tier.slab, f"{name}.slab", 0.0, low_open=True))
        if t and tier.setback < BACK_WALL[1] and tier.lift - tier.slab < _HEADROOM:
            raise CrowdError(f"seat generator: {name}.lift: a tier hanging over the one below "
                             f"needs its underside (lift - slab = {tier.lift - tier.slab:g} m) "
                             f"at least {_HEADROOM:g} m above the last row below")
        tiers.append(tier)
    tunnels = []
    if not isinstance(spec.tunnels, (tuple, list)):
        raise CrowdError(f"seat generator: tunnels: expected a list of Tunnel, got "
                         f"{spec.tunnels!r}")
    for k, tun in enumerate(spec.tunnels):
        name = f"tunnels[{k}]"
        if not isinstance(tun, Tunnel):
            raise CrowdError(f"seat generator: {name}: expected a Tunnel, got {tun!r}")
        tunnels.append(Tunnel(angle=_number(tun.angle, f"{name}.angle"),
                              width=_number(tun.width, f"{name}.width", 0.0, 50.0,
                                            low_open=True),
                              rows=_number(tun.rows, f"{name}.rows", 1, integer=True)))
    seats = spec.seats
    if seats is not None:
        seats = _number(seats, "seats", 1, MAX_SEATS, integer=True)
    out = replace(spec, tiers=tuple(tiers), pitch=pitch, margin=margin, corner_radius=radius,
                  seat_pitch=seat_pitch, seat_width=seat_width, seat_setback=setback,
                  bench=bench, aisle_every=aisle_every, aisle_width=aisle_width,
                  tunnels=tuple(tunnels), seats=seats)
    _check_pitch_fits(out)
    return out


def _check_pitch_fits(spec):
    """The pitch's corners lie inside the inner loop (a convex polygon, densely sampled)."""
    poly = Loop(spec).polygon()
    edge = np.roll(poly, -1, axis=0) - poly
    px, py = 0.5 * spec.pitch[0], 0.5 * spec.pitch[1]
    for corner in ((px, py), (-px, py), (-px, -py), (px, -py)):
        rel = np.asarray(corner) - poly
        if np.any(edge[:, 0] * rel[:, 1] - edge[:, 1] * rel[:, 0] < -1e-9):
            field, fix = (("margin", "widen the margin or the end radius")
                          if spec.plan == "oval" else
                          ("corner_radius", "use a smaller corner radius or a wider margin"))
            raise CrowdError(f"seat generator: {field}: the pitch's corners ({px:g}, {py:g}) "
                             f"stick out of the stands' front edge; {fix}")


# --- the generator -----------------------------------------------------------------

def generate_seats(spec: SeatSpec = SeatSpec()) -> SeatLayout:
    """Seats and stands for ``spec`` (see the module doc); a CrowdError names the field
    at fault."""
    spec = _checked(spec)
    loop = Loop(spec)
    spans = tunnel_spans(spec, loop, place_tiers(spec, [1] * len(spec.tiers)))
    built, order = size_rows(spec, loop, spans)
    tiers = place_tiers(spec, built)
    rows = bowl_rows(spec, loop, tiers)
    block, index, s = seat_line(spec, loop, rows, spans)
    # a seat's number: its place among the seats of its block that exist
    new = np.ones(len(block), bool)
    new[1:] = block[1:] != block[:-1]
    group_start = np.flatnonzero(new)
    number = np.arange(len(block)) - np.repeat(group_start, np.diff(np.append(group_start,
                                                                              len(block))))
    stands = stands_mesh(spec, loop, tiers, rows, spans, block, index, s)
    capacity = len(block)
    row_offsets = np.cumsum([0] + list(built))[:-1]
    keep = trim(spec, rows, block, order, row_offsets)
    block, s, number = block[keep], s[keep], number[keep]
    row = rows.block_row[block]
    seg = rows.block_segment[block]
    lens = rows.lens[row, seg]
    before = (np.cumsum(rows.lens, axis=-1) - rows.lens)[row, seg]
    u = seg + np.clip((s - before) / lens, 0.0, 1.0)
    xy = loop.point(u, rows.front[row] + spec.seat_setback)[0]
    position = np.column_stack([xy, rows.z[row]]).astype(np.float32)
    heading = np.arctan2(-xy[:, 0], xy[:, 1]).astype(np.float32)
    section = rows.block_section[block]
    return SeatLayout(position=position, heading=heading,
                      section=section.astype(np.int32), tier=rows.tier[row].astype(np.int32),
                      row=rows.index[row].astype(np.int32), seat=number.astype(np.int32),
                      team=rows.section_team[section], rows=built,
                      fronts=tuple(float(f) for f in tiers.front),
                      heights=tuple(float(z) for z in tiers.z0), sections=rows.sections,
                      capacity=capacity, stands=stands, spec=spec)
