"""The seat generator's plan and cross-section: :class:`Loop`, the stands' front edge
round the pitch and the loops offset behind it (a point is a loop parameter ``u`` and
an offset ``d``), and where each tier lies for its rows (:func:`place_tiers`) with its
profile (:func:`tier_profile`). The geometry is described in :mod:`.seats`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .seat_spec import SeatSpec

__all__ = ["Loop", "Tiers", "place_tiers", "tier_profile", "ARC_STEP", "BACK_WALL"]

ARC_STEP = math.radians(5.0)      # the stands mesh's resolution along arcs
BACK_WALL = (0.6, 0.4)            # a tier's back wall: above its last riser, thickness
_LINE, _ARC = 0, 1


# --- the plan ------------------------------------------------------------------------

class Loop:
    """The inner loop as segments (lines and arcs), counter-clockwise from the south end
    of the east stand, and the loops offset from it."""

    def __init__(self, spec: SeatSpec):
        big_a = 0.5 * spec.pitch[0] + spec.margin[0]
        big_b = 0.5 * spec.pitch[1] + spec.margin[1]
        r = spec.corner_radius
        segs = []           # (kind, a, b, c, d): line (p0, tangent, normal, length)
        if spec.plan == "rect":
            a, b = big_a - r, big_b - r
            lines = (((big_a, -b), (0, 1), (1, 0), 2 * b),
                     ((a, big_b), (-1, 0), (0, 1), 2 * a),
                     ((-big_a, b), (0, -1), (-1, 0), 2 * b),
                     ((-a, -big_b), (1, 0), (0, -1), 2 * a))
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
        ``ARC_STEP``, plus ``extra``; sorted, in [0, n)."""
        us = []
        for j in range(self.n):
            if self.arc[j]:
                m = max(1, math.ceil(self.dth[j] / ARC_STEP))
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


# --- the cross-section ---------------------------------------------------------------

@dataclass(frozen=True)
class Tiers:
    """Where the tiers lie for a number of rows per tier (arrays per tier)."""

    rows: tuple
    front: np.ndarray        # offset of the first row's front edge
    back: np.ndarray         # offset of the last row's back edge
    z0: np.ndarray           # first tread's height
    zlast: np.ndarray        # last tread's height
    top: np.ndarray          # back wall's top


def place_tiers(spec, rows) -> Tiers:
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
        top.append(zlast[-1] + tier.riser + BACK_WALL[0])
    return Tiers(tuple(rows), *(np.array(v) for v in (front, back, z0, zlast, top)))


def tier_profile(spec, tiers: Tiers, t):
    """Tier ``t``'s cross-section as (P, 2) (offset, height): from the ground (or the
    top of the tier below's back wall, under an overhang) to its front, up the rows
    and down its back wall to the ground. Returns (profile, index of the first
    tread's front point)."""
    tier, n = spec.tiers[t], tiers.rows[t]
    front, z0 = tiers.front[t], tiers.z0[t]
    r = np.arange(n)
    z = z0 + r * tier.riser
    steps = np.column_stack([front + r * tier.tread, z, front + (r + 1) * tier.tread, z])
    back = tiers.back[t] + BACK_WALL[1]
    tail = [(tiers.back[t], tiers.top[t]), (back, tiers.top[t]), (back, 0.0)]
    support = tiers.back[t - 1] + BACK_WALL[1] if t else front
    if front >= support:
        head = [(front, 0.0)]
    else:
        head = [(support, tiers.top[t - 1]), (support, z0 - tier.slab), (front, z0 - tier.slab)]
    return np.vstack([head, steps.reshape(-1, 2), tail]), len(head)
