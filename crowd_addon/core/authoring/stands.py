"""The stands' mesh (:class:`StandsMesh`): each tier's terraces swept along the plan's
loop, tunnels cut into the first tier's front rows with walls at their sides, and a
bench box along every run of seats, of the seats' team (:func:`stands_mesh`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .seat_plan import ARC_STEP, Tiers, tier_profile
from .seat_rows import Rows
from .seat_spec import AWAY

__all__ = ["StandsMesh", "stands_mesh", "CONCRETE", "HOME_BENCH", "AWAY_BENCH"]

#: face kinds of :class:`StandsMesh`: terraces, a home bench, an away bench
CONCRETE, HOME_BENCH, AWAY_BENCH = 0, 1, 2


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


def _terraces(spec, loop, tiers: Tiers, spans):
    """(vertices, faces as lists of index arrays) of every tier's terraces."""
    parts = []
    for t in range(len(tiers.rows)):
        profile, head = tier_profile(spec, tiers, t)
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


def _benches(spec, loop, rows: Rows, block, index, s):
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
    steps = np.where(loop.arc[seg], np.ceil((f1 - f0) * loop.dth[seg] / ARC_STEP), 1)
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


def stands_mesh(spec, loop, tiers, rows, spans, block, index, s) -> StandsMesh:
    tv, tf = _terraces(spec, loop, tiers, spans)
    bv, bq, bteam = _benches(spec, loop, rows, block, index, s)
    sizes = np.array([len(f) for f in tf] + [4] * len(bq), np.int64)
    corners = np.concatenate([np.concatenate(tf), (bq + len(tv)).ravel()]).astype(np.int64)
    kind = np.concatenate([np.full(len(tf), CONCRETE, np.int32),
                           np.where(bteam == AWAY, AWAY_BENCH, HOME_BENCH).astype(np.int32)])
    return StandsMesh(np.vstack([tv, bv]), corners, sizes, kind)
