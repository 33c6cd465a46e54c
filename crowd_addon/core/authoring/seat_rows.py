"""The seat generator's rows: the aisles that split each tier into blocks (its
sections), every row and block of the bowl (:class:`Rows`), the seats along the rows
with the tunnels' gaps left out (:func:`seat_line`), and the rows built for a seat
count (:func:`size_rows`, :func:`trim`). The rules are described in :mod:`.seats`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError
from .seat_plan import Tiers, place_tiers
from .seat_spec import AWAY, HOME

__all__ = ["Rows", "bowl_rows", "tunnel_spans", "seat_line", "size_rows", "trim"]

_MAX_ROWS = 2000                  # rows of the whole bowl when sizing it for a seat count


@dataclass(frozen=True)
class Rows:
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


def bowl_rows(spec, loop, tiers: Tiers) -> Rows:
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
                         loop.lengths(seat_d), np.repeat(r, m),
                         sections + np.tile(np.arange(m), n), np.tile(segment, n),
                         count.astype(np.int64).ravel(), first.ravel(), step.ravel()))
        teams.append(np.where(segment == away, AWAY, HOME))
        sections += m
    cols = [np.concatenate(c) for c in zip(*per_tier)]
    offsets = np.cumsum([0] + list(tiers.rows))[:-1]
    block_tier = np.repeat(np.arange(len(tiers.rows)),
                           [len(p[5]) for p in per_tier])
    cols[5] = cols[5] + offsets[block_tier]         # the row's index in the whole bowl
    return Rows(*cols, sections=sections, section_team=np.concatenate(teams).astype(np.int32))


def tunnel_spans(spec, loop, tiers: Tiers):
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


def seat_line(spec, loop, rows: Rows, spans, blocks=None):
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


def _count(spec, loop, rows: Rows, spans):
    total = int(rows.count.sum())
    if spans:
        deep = max(t.rows for t in spec.tunnels)
        blocks = np.flatnonzero((rows.tier[rows.block_row] == 0)
                                & (rows.index[rows.block_row] < deep))
        total -= int(rows.count[blocks].sum()) - len(seat_line(spec, loop, rows, spans,
                                                                 blocks)[0])
    return total


def size_rows(spec, loop, spans):
    """Rows per tier and the order they were added in ((tier, row) pairs), for the
    spec's seat count (or as given)."""
    given = [t.rows for t in spec.tiers]
    if spec.seats is None:
        return tuple(given), []
    rows = [1] * len(given)
    order = [(t, 0) for t in range(len(given))]
    while _count(spec, loop, bowl_rows(spec, loop, place_tiers(spec, rows)), spans) < spec.seats:
        if sum(rows) >= _MAX_ROWS:
            raise CrowdError(f"seat generator: seats: {spec.seats} seats need more than "
                             f"{_MAX_ROWS} rows")
        short = [t for t, (g, r) in enumerate(zip(given, rows)) if r < g]
        t = short[0] if short else int(np.argmax([g / (r + 1) for g, r in zip(given, rows)]))
        order.append((t, rows[t]))
        rows[t] += 1
    return tuple(rows), order


def trim(spec, rows: Rows, block, order, row_offsets):
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
