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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..base.errors import CrowdError

__all__ = ["Tier", "Tunnel", "SeatSpec", "SeatLayout", "StandsMesh", "generate_seats",
           "plan_ring", "HOME", "AWAY", "PLANS", "ENDS", "CONCRETE", "HOME_BENCH",
           "AWAY_BENCH", "MAX_SEATS"]

HOME, AWAY = 0, 1
PLANS = ("rect", "oval")
ENDS = ("east", "west", "none")
#: face kinds of :class:`StandsMesh`: terraces, a home bench, an away bench
CONCRETE, HOME_BENCH, AWAY_BENCH = 0, 1, 2
MAX_SEATS = 5_000_000
MAX_TIERS = 4
_MAX_ROWS = 2000                  # rows of the whole bowl when sizing it for a seat count
_ARC_STEP = math.radians(5.0)     # the stands mesh's resolution along arcs
_HEADROOM = 2.2                   # an overhanging tier's underside above the last row below
_BACK_WALL = (0.6, 0.4)           # a tier's back wall: above its last riser, thickness
_LINE, _ARC = 0, 1


@dataclass(frozen=True)
class Tier:
    """One tier of the cross-section (metres; see the module doc)."""

    rows: int = 20
    tread: float = 0.8
    riser: float = 0.4
    setback: float = 0.0
    lift: float = 1.2
    slab: float = 0.6


@dataclass(frozen=True)
class Tunnel:
    """A gap through the first tier's front rows: ``angle`` degrees round the pitch
    centre (0 = east, counter-clockwise), ``width`` metres on the front row, ``rows``
    rows deep."""

    angle: float
    width: float = 4.0
    rows: int = 6


@dataclass(frozen=True)
class SeatSpec:
    """What :func:`generate_seats` builds (see the module doc for each field)."""

    tiers: tuple = (Tier(),)
    plan: str = "rect"
    pitch: tuple = (105.0, 68.0)
    margin: tuple = (6.5, 6.0)
    corner_radius: float = 14.0
    seat_pitch: float = 0.5
    seat_width: float = 0.45
    seat_setback: float = 0.25
    bench: tuple = (0.45, 0.8, 0.45)
    aisle_every: int = 24
    aisle_width: float = 1.2
    tunnels: tuple = ()
    away_end: str = "east"
    seats: int | None = None


@dataclass(frozen=True)
class StandsMesh:
    """The stands as one mesh: terraces swept along each tier (tunnels cut into the
    first), and a bench box along each run of seats.

    vertices : (V, 3) float64. corners : (L,) int64, every face's vertex indices one
    face after the other, counter-clockwise seen from outside. sizes : (F,) int64
    corners per face. kind : (F,) int32 :data:`CONCRETE`, :data:`HOME_BENCH` or
    :data:`AWAY_BENCH`.
    """

    vertices: np.ndarray
    corners: np.ndarray
    sizes: np.ndarray
    kind: np.ndarray

    @property
    def starts(self) -> np.ndarray:
        """(F,) index into :attr:`corners` of each face's first corner."""
        return np.cumsum(self.sizes) - self.sizes


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


# --- the plan ------------------------------------------------------------------------

class _Loop:
    """The inner loop as segments (lines and arcs), counter-clockwise from the south end
    of the east stand, and the loops offset from it."""

    def __init__(self, spec: SeatSpec):
        big_a = 0.5 * spec.pitch[0] + spec.margin[0]
        big_b = 0.5 * spec.pitch[1] + spec.margin[1]
        r = spec.corner_radius
        segs = []           # (kind, a, b, c, d): line (p0, tangent, normal, length)
        if spec.plan == "rect":
            a, b = big_a - r, big_b - r
            lines = (((big_a, -b), (0, 1), (1, 0), 2 * b), ((a, big_b), (-1, 0), (0, 1), 2 * a),
                     ((-big_a, b), (0, -1), (-1, 0), 2 * b), ((-a, -big_b), (1, 0), (0, -1), 2 * a))
            centres = ((a, b), (-a, b), (-a, -b), (a, -b))
            for k in range(4):
                segs.append((_LINE,) + lines[k])
                segs.append((_ARC, centres[k], r, 0.5 * math.pi * k, 0.5 * math.pi))
        else:
            r2 = ((big_a - r) ** 2 + big_b ** 2 - r ** 2) / (2 * (big_b - r))
            alpha = math.atan2(r2 - big_b, big_a - r)
            e, c = big_a - r, r2 - big_b
            segs = [(_ARC, (e, 0.0), r, -alpha, 2 * alpha),
                    (_ARC, (0.0, -c), r2, alpha, math.pi - 2 * alpha),
                    (_ARC, (-e, 0.0), r, math.pi - alpha, 2 * alpha),
                    (_ARC, (0.0, c), r2, math.pi + alpha, math.pi - 2 * alpha)]
        n = len(segs)
        self.n = n
        self.kind = np.array([s[0] for s in segs])
        self.p0 = np.zeros((n, 2))
        self.tan = np.zeros((n, 2))
        self.nrm = np.zeros((n, 2))
        self.length0 = np.zeros(n)
        self.r0 = np.zeros(n)
        self.th0 = np.zeros(n)
        self.dth = np.zeros(n)
        for j, s in enumerate(segs):
            if s[0] == _LINE:
                self.p0[j], self.tan[j], self.nrm[j], self.length0[j] = s[1:]
            else:
                self.p0[j], self.r0[j], self.th0[j], self.dth[j] = s[1:]
        self.arc = self.kind == _ARC
        #: the segment of the stand behind each goal (the away end's candidates)
        self.ends = {"east": 0, "west": n // 2}

    def lengths(self, d):
        """(..., n) segment lengths of the loops at offsets ``d`` (...)."""
        d = np.asarray(d, np.float64)[..., None]
        return np.where(self.arc, (self.r0 + d) * self.dth, self.length0 + 0 * d)

    def point(self, u, d):
        """Points (..., 2) and outward normals (..., 2) at loop parameters ``u`` and
        offsets ``d`` (broadcast together)."""
        u, d = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(d, np.float64))
        u = np.mod(u, self.n)
        j = np.minimum(np.floor(u).astype(np.int64), self.n - 1)
        f = u - j
        theta = self.th0[j] + f * self.dth[j]
        arc_n = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        normal = np.where(self.arc[j][..., None], arc_n, self.nrm[j])
        line_p = self.p0[j] + (f * self.length0[j])[..., None] * self.tan[j]
        arc_p = self.p0[j] + self.r0[j][..., None] * arc_n
        base = np.where(self.arc[j][..., None], arc_p, line_p)
        return base + d[..., None] * normal, normal

    def s_of_u(self, u, d):
        """Arc length along the loop at offset ``d`` of parameter ``u`` (in [0, n))."""
        u, d = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(d, np.float64))
        lens = self.lengths(d)
        before = np.cumsum(lens, axis=-1) - lens
        j = np.minimum(np.floor(u).astype(np.int64), self.n - 1)
        take = lambda a: np.take_along_axis(a, j[..., None], -1)[..., 0]   # noqa: E731
        return take(before) + (u - j) * take(lens)

    def u_of_s(self, s, d):
        """The loop parameter of arc length ``s`` (taken modulo the loop's length) at
        offset ``d``."""
        s, d = np.broadcast_arrays(np.asarray(s, np.float64), np.asarray(d, np.float64))
        lens = self.lengths(d)
        ends = np.cumsum(lens, axis=-1)
        s = np.mod(s, ends[..., -1])
        j = np.minimum((s[..., None] >= ends).sum(-1), self.n - 1)
        take = lambda a: np.take_along_axis(a, j[..., None], -1)[..., 0]   # noqa: E731
        seg = take(lens)
        f = np.where(seg > 0, (s - (take(ends) - seg)) / np.where(seg > 0, seg, 1.0), 0.0)
        return j + np.clip(f, 0.0, 1.0)

    def ring(self, extra=()):
        """Loop parameters for meshing: every segment's start, arcs every
        ``_ARC_STEP``, plus ``extra``; sorted, in [0, n)."""
        us = []
        for j in range(self.n):
            if self.arc[j]:
                m = max(1, math.ceil(self.dth[j] / _ARC_STEP))
                us.append(j + np.arange(m) / m)
            elif self.length0[j] > 0:
                us.append(np.array([float(j)]))
        us = np.concatenate(us + [np.mod(np.asarray(extra, np.float64), self.n)])
        us = np.unique(np.round(us, 12))
        return us

    def polygon(self, d=0.0, per_segment=512):
        """The loop at offset ``d`` as a dense closed polygon (K, 2)."""
        u = (np.arange(self.n)[:, None] + np.arange(per_segment) / per_segment).ravel()
        return self.point(u, d)[0]


def plan_ring(spec: SeatSpec, offset: float = 0.0):
    """The plan's loop ``offset`` metres behind the stands' front edge, for meshing (the
    apron inside the stands): points (K, 2) counter-clockwise and outward normals."""
    spec = _checked(spec)
    loop = _Loop(spec)
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
        if t and tier.setback < _BACK_WALL[1] and tier.lift - tier.slab < _HEADROOM:
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
    poly = _Loop(spec).polygon()
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


# --- the cross-section ---------------------------------------------------------------

@dataclass(frozen=True)
class _Tiers:
    """Where the tiers lie for a number of rows per tier (arrays per tier)."""

    rows: tuple
    front: np.ndarray        # offset of the first row's front edge
    back: np.ndarray         # offset of the last row's back edge
    z0: np.ndarray           # first tread's height
    zlast: np.ndarray        # last tread's height
    top: np.ndarray          # back wall's top


def _place_tiers(spec, rows) -> _Tiers:
    front, back, z0, zlast, top = [], [], [], [], []
    for t, (tier, n) in enumerate(zip(spec.tiers, rows)):
        if t == 0:
            f, z = tier.setback, tier.lift
        else:
            f, z = max(back[-1] + tier.setback, front[-1]), zlast[-1] + tier.lift
        front.append(f)
        back.append(f + n * tier.tread)
        z0.append(z)
        zlast.append(z + (n - 1) * tier.riser)
        top.append(zlast[-1] + tier.riser + _BACK_WALL[0])
    return _Tiers(tuple(rows), *(np.array(v) for v in (front, back, z0, zlast, top)))


def _profile(spec, tiers: _Tiers, t):
    """Tier ``t``'s cross-section as (P, 2) (offset, height): from the ground (or the
    top of the tier below's back wall, under an overhang) to its front, up the rows
    and down its back wall to the ground. Returns (profile, index of the first
    tread's front point)."""
    tier, n = spec.tiers[t], tiers.rows[t]
    front, z0 = tiers.front[t], tiers.z0[t]
    r = np.arange(n)
    z = z0 + r * tier.riser
    steps = np.column_stack([front + r * tier.tread, z, front + (r + 1) * tier.tread, z])
    back = tiers.back[t] + _BACK_WALL[1]
    tail = [(tiers.back[t], tiers.top[t]), (back, tiers.top[t]), (back, 0.0)]
    support = tiers.back[t - 1] + _BACK_WALL[1] if t else front
    if front >= support:
        head = [(front, 0.0)]
    else:
        head = [(support, tiers.top[t - 1]), (support, z0 - tier.slab), (front, z0 - tier.slab)]
    return np.vstack([head, steps.reshape(-1, 2), tail]), len(head)


# --- aisles, blocks, seats along the rows --------------------------------------------

@dataclass(frozen=True)
class _Rows:
    """Every row of the bowl (tier by tier) and every block of every row."""

    tier: np.ndarray         # per row
    index: np.ndarray        # per row: row within its tier
    front: np.ndarray        # per row: offset of its front edge
    z: np.ndarray            # per row: tread height
    lens: np.ndarray         # per row: (n,) segment lengths on its seat line
    block_row: np.ndarray    # per block of a row: the row
    block_section: np.ndarray
    block_segment: np.ndarray
    count: np.ndarray        # seats the block holds (before tunnels)
    first: np.ndarray        # arc length of its first seat on the row's seat line
    step: np.ndarray         # arc length from seat to seat (a chord of the seat pitch)
    sections: int
    section_team: np.ndarray


def _aisles(spec, loop, d):
    """Loop parameters of a tier's aisles, from its front seat line at offset ``d``."""
    lens = loop.lengths(d)
    unit = spec.aisle_every * spec.seat_pitch + spec.aisle_width
    us = []
    for j in range(loop.n):
        if lens[j] <= 1e-9:
            continue
        k = max(1, round(lens[j] / unit)) if spec.aisle_every > 0 else 1
        us.append(j + np.arange(k) / k)
    return np.concatenate(us)


def _rows(spec, loop, tiers: _Tiers) -> _Rows:
    away = loop.ends.get(spec.away_end, -1)
    per_tier, sections = [], 0
    teams = []
    for t, n in enumerate(tiers.rows):
        tier = spec.tiers[t]
        r = np.arange(n)
        front = tiers.front[t] + r * tier.tread
        seat_d = front + spec.seat_setback
        ua = _aisles(spec, loop, tiers.front[t] + spec.seat_setback)
        m = len(ua)
        s_a = loop.s_of_u(ua[None, :], seat_d[:, None])                   # (n, m)
        perimeter = loop.lengths(seat_d).sum(-1)
        s_b = np.concatenate([s_a[:, 1:], s_a[:, :1] + perimeter[:, None]], axis=1)
        start = s_a + 0.5 * spec.aisle_width
        usable = s_b - 0.5 * spec.aisle_width - start
        segment = np.floor(ua).astype(np.int64)
        # the step along the row that puts neighbours a seat pitch apart in a straight
        # line: on an arc of radius R, the arc whose chord is the pitch
        radius = loop.r0[segment][None, :] + seat_d[:, None]
        half = np.minimum(0.5 * spec.seat_pitch / np.where(loop.arc[segment], radius, 1.0), 1.0)
        step = np.where(loop.arc[segment], 2 * radius * np.arcsin(half), spec.seat_pitch)
        count = np.where(usable >= spec.seat_width,
                         np.floor((usable - spec.seat_width) / step + 1e-9) + 1, 0)
        first = start + 0.5 * (usable - (count - 1) * step)
        per_tier.append((np.full(n, t), r, front, tiers.z0[t] + r * tier.riser,
                         loop.lengths(seat_d), np.repeat(r, m), sections + np.tile(np.arange(m), n),
                         np.tile(segment, n), count.astype(np.int64).ravel(), first.ravel(),
                         step.ravel()))
        teams.append(np.where(segment == away, AWAY, HOME))
        sections += m
    cols = [np.concatenate(c) for c in zip(*per_tier)]
    offsets = np.cumsum([0] + list(tiers.rows))[:-1]
    block_tier = np.repeat(np.arange(len(tiers.rows)),
                           [len(p[5]) for p in per_tier])
    cols[5] = cols[5] + offsets[block_tier]         # the row's index in the whole bowl
    return _Rows(*cols, sections=sections, section_team=np.concatenate(teams).astype(np.int32))


def _tunnel_spans(spec, loop, tiers: _Tiers):
    """Each tunnel's (u_lo, u_hi) on the loop, from its width on the first tier's front
    seat line; a CrowdError if two overlap."""
    d = tiers.front[0] + spec.seat_setback
    if not spec.tunnels:
        return []
    poly_u = (np.arange(loop.n)[:, None] + np.arange(2048) / 2048).ravel()
    pts = loop.point(poly_u, 0.0)[0]
    polar = np.arctan2(pts[:, 1], pts[:, 0])
    spans, intervals = [], []
    perimeter = loop.lengths(d).sum()
    for tun in spec.tunnels:
        diff = np.angle(np.exp(1j * (polar - math.radians(tun.angle))))
        s_c = float(loop.s_of_u(poly_u[np.argmin(np.abs(diff))], d))
        lo, hi = s_c - 0.5 * tun.width, s_c + 0.5 * tun.width
        spans.append((float(loop.u_of_s(lo, d)), float(loop.u_of_s(hi, d))))
        intervals.append((lo % perimeter, tun.width))
    for k, (lo, w) in enumerate(intervals):
        for i, (lo2, w2) in enumerate(intervals[:k]):
            if (lo2 - lo) % perimeter < w or (lo - lo2) % perimeter < w2:
                raise CrowdError(f"seat generator: tunnels[{k}]: overlaps tunnels[{i}]")
    return spans


def _seat_line(spec, loop, rows: _Rows, spans, blocks=None):
    """The seats along the rows: (block, index in block, arc length) per seat, tunnel
    gaps left out; only ``blocks`` (indices) when given."""
    count = rows.count if blocks is None else rows.count[blocks]
    ids = np.arange(len(rows.count)) if blocks is None else blocks
    block = np.repeat(ids, count)
    index = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    s = rows.first[block] + index * rows.step[block]
    keep = np.ones(len(s), bool)
    row = rows.block_row[block]
    perimeter = rows.lens.sum(-1)
    d = rows.front + spec.seat_setback
    half = 0.5 * spec.seat_width
    for tun, (u_lo, u_hi) in zip(spec.tunnels, spans):
        cut = (rows.tier == 0) & (rows.index < tun.rows)          # per row
        hit = cut[row]
        if not hit.any():
            continue
        lo = loop.s_of_u(np.full(len(d), u_lo), d)
        span = np.mod(loop.s_of_u(np.full(len(d), u_hi), d) - lo, perimeter)
        r = row[hit]
        rel = np.mod(s[hit] - lo[r], perimeter[r])
        keep[np.flatnonzero(hit)[(rel < span[r] + half) | (rel > perimeter[r] - half)]] = False
    return block[keep], index[keep], s[keep]


def _count(spec, loop, rows: _Rows, spans):
    total = int(rows.count.sum())
    if spans:
        deep = max(t.rows for t in spec.tunnels)
        blocks = np.flatnonzero((rows.tier[rows.block_row] == 0)
                                & (rows.index[rows.block_row] < deep))
        total -= int(rows.count[blocks].sum()) - len(_seat_line(spec, loop, rows, spans,
                                                                 blocks)[0])
    return total


def _size(spec, loop, spans):
    """Rows per tier and the order they were added in ((tier, row) pairs), for the
    spec's seat count (or as given)."""
    given = [t.rows for t in spec.tiers]
    if spec.seats is None:
        return tuple(given), []
    rows = [1] * len(given)
    order = [(t, 0) for t in range(len(given))]
    while _count(spec, loop, _rows(spec, loop, _place_tiers(spec, rows)), spans) < spec.seats:
        if sum(rows) >= _MAX_ROWS:
            raise CrowdError(f"seat generator: seats: {spec.seats} seats need more than "
                             f"{_MAX_ROWS} rows")
        short = [t for t, (g, r) in enumerate(zip(given, rows)) if r < g]
        t = short[0] if short else int(np.argmax([g / (r + 1) for g, r in zip(given, rows)]))
        order.append((t, rows[t]))
        rows[t] += 1
    return tuple(rows), order


def _trim(spec, rows: _Rows, block, order, row_offsets):
    """Which seats to keep (bool) for exactly ``spec.seats``: the surplus leaves the
    rows added last empty, the seats kept in a row spread evenly along it."""
    keep = np.ones(len(block), bool)
    surplus = len(block) - (spec.seats if spec.seats is not None else len(block))
    seat_row = rows.block_row[block]
    for t, r in reversed(order):
        if surplus <= 0:
            break
        idx = np.flatnonzero(seat_row == row_offsets[t] + r)
        cut = min(surplus, len(idx))
        left = len(idx) - cut
        keep[idx] = False
        if left:
            keep[idx[((np.arange(left) + 0.5) * len(idx) / left).astype(np.int64)]] = True
        surplus -= cut
    return keep


# --- the stands mesh ---------------------------------------------------------------

def _sweep(loop, us, profile, closed_ring):
    """Vertices (P*K, 3) and quads (F, 4) of a (offset, height) profile swept along the
    loop parameters ``us`` (K)."""
    k = len(us)
    xy = loop.point(us[None, :], profile[:, :1])[0]                          # (P, K, 2)
    verts = np.concatenate([xy, np.broadcast_to(profile[:, None, 1:], xy.shape[:2] + (1,))],
                           axis=-1).reshape(-1, 3)
    p0, k0 = np.meshgrid(np.arange(len(profile) - 1), np.arange(k if closed_ring else k - 1),
                         indexing="ij")
    p1, k1 = p0 + 1, (k0 + 1) % k
    quads = np.stack([p0 * k + k0, p1 * k + k0, p1 * k + k1, p0 * k + k1], axis=-1)
    return verts, quads.reshape(-1, 4)


def _cap(loop, u, polygon, facing_forward):
    verts = np.column_stack([loop.point(np.full(len(polygon), u), polygon[:, 0])[0],
                             polygon[:, 1]])
    order = np.arange(len(polygon))
    return verts, (order if facing_forward else order[::-1])


def _terraces(spec, loop, tiers: _Tiers, spans):
    """(vertices, faces as lists of index arrays) of every tier's terraces."""
    parts = []
    for t in range(len(tiers.rows)):
        profile, head = _profile(spec, tiers, t)
        if t or not spans:
            parts.append(_sweep(loop, loop.ring(), profile, True))
            continue
        edges = [u for span in spans for u in span]
        ring = loop.ring(edges)
        mids = 0.5 * (ring + np.roll(ring, -1) + np.where(np.arange(len(ring)) == len(ring) - 1,
                                                          loop.n, 0))
        label = np.full(len(ring), -1)
        for k, (lo, hi) in enumerate(spans):
            inside = np.mod(mids - lo, loop.n) < np.mod(hi - lo, loop.n)
            label[inside] = k
        start = int(np.flatnonzero(label != np.roll(label, 1))[0])
        ring, label = np.roll(ring, -start), np.roll(label, -start)
        cuts = np.flatnonzero(label != np.roll(label, 1))
        for a, b in zip(cuts, np.append(cuts[1:], len(ring))):
            piece = np.append(ring[a:b], ring[b % len(ring)])
            piece = piece + loop.n * (np.diff(piece, prepend=piece[0]) < 0).cumsum()
            k = label[a]
            if k < 0:
                parts.append(_sweep(loop, piece, profile, False))
                continue
            rows_cut = min(spec.tunnels[k].rows, tiers.rows[0])
            if rows_cut >= tiers.rows[0]:
                notch = np.array([profile[0], (profile[-1][0], 0.0)])
                cap = profile
            else:
                dc = tiers.front[0] + rows_cut * spec.tiers[0].tread
                notch = np.vstack([[profile[0], (dc, 0.0)], profile[head + 2 * rows_cut:]])
                cap = np.vstack([profile[:head + 2 * rows_cut], [(dc, 0.0)]])
            parts.append(_sweep(loop, piece, notch, False))
            parts.append(_cap(loop, piece[0], cap, True))       # the walls, facing in
            parts.append(_cap(loop, piece[-1], cap, False))
    verts, faces, base = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.extend(list(f + base) if f.ndim == 2 else [f + base])
        base += len(v)
    return np.vstack(verts), faces


def _benches(spec, loop, rows: _Rows, block, index, s):
    """Vertices and quads (F, 4) of a bench box along every run of seats (a block's row,
    split by tunnels), and each quad's team."""
    if len(block) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4), np.int64), np.zeros(0, np.int32)
    new = np.ones(len(block), bool)
    new[1:] = (block[1:] != block[:-1]) | (index[1:] != index[:-1] + 1)
    first = np.flatnonzero(new)
    last = np.append(first[1:], len(block)) - 1
    b = block[first]
    row = rows.block_row[b]
    seg = rows.block_segment[b]
    lens = rows.lens[row, seg]
    before = (np.cumsum(rows.lens, axis=-1) - rows.lens)[row, seg]
    half = 0.5 * spec.seat_width
    f0 = np.clip((s[first] - half - before) / lens, 0.0, 1.0)
    f1 = np.clip((s[last] + half - before) / lens, 0.0, 1.0)
    steps = np.where(loop.arc[seg], np.ceil((f1 - f0) * loop.dth[seg] / _ARC_STEP), 1)
    steps = np.maximum(steps, 1).astype(np.int64)
    run = np.repeat(np.arange(len(b)), steps + 1)
    q = np.arange(len(run)) - np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)
    u = seg[run] + f0[run] + (f1 - f0)[run] * q / steps[run]
    front = rows.front[row][run]
    z = rows.z[row][run]
    bf, bb, bh = spec.bench
    corner_d = np.stack([front + bf, front + bf, front + bb, front + bb], axis=1)  # (S, 4)
    corner_z = np.stack([z, z + bh, z + bh, z], axis=1)
    xy = loop.point(u[:, None], corner_d)[0]
    verts = np.concatenate([xy, corner_z[..., None]], axis=-1).reshape(-1, 3)
    station = np.flatnonzero(np.append(run[1:] == run[:-1], False))     # with a next one
    c = np.arange(4)
    c1 = (c + 1) % 4
    g = station[:, None]
    sides = np.stack([4 * g + c, 4 * g + c1, 4 * (g + 1) + c1, 4 * (g + 1) + c], axis=-1)
    starts = np.cumsum(steps + 1) - (steps + 1)
    ends = starts + steps
    caps = np.concatenate([4 * starts[:, None] + c[None, ::-1], 4 * ends[:, None] + c[None, :]])
    quads = np.concatenate([sides.reshape(-1, 4), caps])
    team = rows.section_team[rows.block_section[b]]
    quad_team = np.concatenate([np.repeat(team[run[station]], 4), team, team])
    return verts, quads, quad_team


def _stands(spec, loop, tiers, rows, spans, block, index, s) -> StandsMesh:
    tv, tf = _terraces(spec, loop, tiers, spans)
    bv, bq, bteam = _benches(spec, loop, rows, block, index, s)
    sizes = np.array([len(f) for f in tf] + [4] * len(bq), np.int64)
    corners = np.concatenate([np.concatenate(tf), (bq + len(tv)).ravel()]).astype(np.int64)
    kind = np.concatenate([np.full(len(tf), CONCRETE, np.int32),
                           np.where(bteam == AWAY, AWAY_BENCH, HOME_BENCH).astype(np.int32)])
    return StandsMesh(np.vstack([tv, bv]), corners, sizes, kind)


# --- the generator -----------------------------------------------------------------

def generate_seats(spec: SeatSpec = SeatSpec()) -> SeatLayout:
    """Seats and stands for ``spec`` (see the module doc); a CrowdError names the field
    at fault."""
    spec = _checked(spec)
    loop = _Loop(spec)
    spans = _tunnel_spans(spec, loop, _place_tiers(spec, [1] * len(spec.tiers)))
    built, order = _size(spec, loop, spans)
    tiers = _place_tiers(spec, built)
    rows = _rows(spec, loop, tiers)
    block, index, s = _seat_line(spec, loop, rows, spans)
    # a seat's number: its place among the seats of its block that exist
    new = np.ones(len(block), bool)
    new[1:] = block[1:] != block[:-1]
    group_start = np.flatnonzero(new)
    number = np.arange(len(block)) - np.repeat(group_start, np.diff(np.append(group_start,
                                                                              len(block))))
    stands = _stands(spec, loop, tiers, rows, spans, block, index, s)
    capacity = len(block)
    row_offsets = np.cumsum([0] + list(built))[:-1]
    keep = _trim(spec, rows, block, order, row_offsets)
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

