"""Timing variation that keeps sharing: a template stream becomes a few streams.

An animator authors one stream (a *template*: a named controller tree) and asks for
its agents to play it at speeds spread over ``speed_min .. speed_max`` and in
``copies`` phase-shifted copies (:class:`Timing`). The crowd never plays anything per
agent: the template becomes ``speed_streams x copies`` streams (:func:`expand`), each
the same tree at one speed (the centres of ``speed_streams`` equal parts of the
range) and one phase; every agent draws a speed in the range and takes the stream of
the nearest speed, and a copy at random (:func:`choose_variants`). CPU cost stays per
stream, and the streams are ordinary ones: exports, snapshots and the GPU see
nothing new.

Copy ``c`` of a stream at speed ``v`` starts ``c x v x M`` frames into the tree, so
its offsets ``0 .. M-1`` show the poses the first copy would show at offsets ``c M ..
(c + 1) M - 1``: copies extend the pose history a template's agents are spread over
(for clips at least ``copies x M`` frames long) without a longer ring.

The stream of the speed nearest 1 (the lower on a tie), first copy, keeps the
template's name, so a cue or a script that names the template still finds it; the
others are named ``"<template> <speed>x"`` and ``"... #<copy>"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError
from .repetition import OFFSET_TOLERANCE

__all__ = ["Timing", "expand", "choose_variants", "spread_offsets", "MAX_GENERATED",
           "SPREAD_NEIGHBOURS", "SPREAD_GAP"]

#: the most streams one template may become
MAX_GENERATED = 256
#: neighbours (nearest in the ground plane) whose offsets :func:`spread_offsets` keeps
#: apart
SPREAD_NEIGHBOURS = 8
#: the least gap :func:`spread_offsets` keeps between neighbours' offsets: the
#: repetition metric's default offset tolerance (frames closer than this look alike)
SPREAD_GAP = OFFSET_TOLERANCE


@dataclass(frozen=True)
class Timing:
    """Timing variation of one template stream (the defaults: none, one stream)."""

    speed_min: float = 1.0
    speed_max: float = 1.0
    speed_streams: int = 1
    copies: int = 1

    def check(self, what: str) -> "Timing":
        """This timing, or a CrowdError naming ``what`` and the field at fault."""
        lo, hi = float(self.speed_min), float(self.speed_max)
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
            raise CrowdError(f"{what}: the speed range must be finite with 0 < min <= max, "
                             f"got {self.speed_min!r} .. {self.speed_max!r}")
        for name in ("speed_streams", "copies"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or int(v) < 1:
                raise CrowdError(f"{what}: {name.replace('_', ' ')} must be a whole number "
                                 f">= 1, got {v!r}")
        if self.count > MAX_GENERATED:
            raise CrowdError(f"{what}: {self.speed_streams} speeds x {self.copies} copies "
                             f"make {self.count} streams, more than {MAX_GENERATED}")
        if lo == hi and self.speed_streams > 1:
            raise CrowdError(f"{what}: {self.speed_streams} speed streams need a speed range "
                             f"(min {lo:g} = max {hi:g}); widen it or use 1")
        return self

    @property
    def count(self) -> int:
        """Streams the template becomes."""
        return int(self.speed_streams) * int(self.copies)

    def speeds(self) -> np.ndarray:
        """(speed_streams,) float64: the centres of equal parts of the range."""
        n = int(self.speed_streams)
        lo, hi = float(self.speed_min), float(self.speed_max)
        return lo + (hi - lo) * (np.arange(n) + 0.5) / n

    def base(self) -> int:
        """Index of the variant that keeps the template's name: speed nearest 1 (the
        lower on a tie), first copy."""
        return int(np.argmin(np.abs(self.speeds() - 1.0))) * int(self.copies)


def expand(name: str, timing: Timing, max_offset: int, origin: float = 0.0) -> list:
    """``[(stream name, speed, phase)]`` of the template ``name``'s streams, variant
    ``i = speed_index x copies + copy`` at place ``i``. At frame ``origin`` (a scene's
    start frame) every first copy's tree time is ``origin``, as the template's; the
    speeds part from there."""
    timing = timing.check(f"stream {name!r}")
    speeds = timing.speeds()
    base = timing.base()
    several = timing.speed_streams > 1
    out = []
    for k, v in enumerate(speeds):
        for c in range(int(timing.copies)):
            i = k * int(timing.copies) + c
            label = name if i == base else " ".join(
                [name] + ([f"{v:.3g}x"] if several else []) + ([f"#{c + 1}"] if c else []))
            out.append((label, float(v), float(c * v * max_offset + (1.0 - v) * origin)))
    return out


def choose_variants(count: int, timing: Timing, seed: int) -> np.ndarray:
    """(count,) int64 variant of each of ``count`` agents of one template: a speed
    drawn uniformly over the range, the stream of the nearest speed, and a copy at
    random; seeded."""
    rng = np.random.default_rng(seed)
    speeds = timing.speeds()
    drawn = rng.uniform(float(timing.speed_min), float(timing.speed_max), count)
    nearest = np.abs(drawn[:, None] - speeds[None, :]).argmin(1) if speeds.size > 1 \
        else np.zeros(count, np.int64)
    copy = rng.integers(0, int(timing.copies), count)
    return nearest.astype(np.int64) * int(timing.copies) + copy


def spread_offsets(positions, streams, max_offset: int, seed: int,
                   neighbours: int = SPREAD_NEIGHBOURS, rounds: int = 32) -> np.ndarray:
    """(n,) int32 offsets in ``0 .. M-1`` such that agents near each other that play
    the same stream are out of step (the *Spread* offset mode).

    Offsets start uniform at random; then, a few rounds over all agents at once, an
    agent whose offset is within ``gap`` frames of one of its ``neighbours`` nearest
    agents (in x, y) on the same stream draws again, with probability 1/2 so that two
    such agents seldom both move. ``gap`` is ``M / (2 neighbours + 1)`` frames, but at
    least :data:`SPREAD_GAP` (what the repetition metric calls in step) and at most
    ``(M - 1) / 2``: wide enough that no neighbour is in step, narrow enough that a
    free offset exists for most agents (a short M with many same-stream neighbours
    may leave a few in step). Seeded; numpy only, no loop per agent. Agents with
    stream ``-1`` (on a unique) keep their uniform draw."""
    from .repetition import nearest_neighbours
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    st = np.asarray(streams, np.int64).reshape(-1)
    m = int(max_offset)
    rng = np.random.default_rng(seed)
    off = rng.integers(0, m, st.size)
    if st.size < 2 or m < 2:
        return off.astype(np.int32)
    nb = nearest_neighbours(pos[:, :2], min(int(neighbours), st.size - 1))
    same = (nb >= 0) & (st[np.maximum(nb, 0)] == st[:, None]) & (st[:, None] >= 0)
    gap = min(max(SPREAD_GAP, m // (2 * int(neighbours) + 1)), (m - 1) // 2)
    for _ in range(int(rounds)):
        clash = same & (np.abs(off[:, None] - off[np.maximum(nb, 0)]) <= gap)
        redo = np.flatnonzero(clash.any(1) & (rng.random(st.size) < 0.5))
        if not clash.any():
            break
        off[redo] = rng.integers(0, m, redo.size)
    return off.astype(np.int32)
