"""Selections: which agents a cue reaches (by a value, inside a box, a random
fraction) and the agents near others (a reaction's ``radius``), as sorted index arrays.

The Blender side builds a cue's agents with the first three (``blender/show_data.py``);
the show's runner (:mod:`crowd_addon.core.shots.show_runner`) finds a reaction's
neighbours with :func:`neighbours` on a grid from :func:`neighbour_grid`, kept until
the agents move.
"""

from __future__ import annotations

import numpy as np

from ..base.errors import CrowdError
from ..base.bounds import finite

__all__ = ["select_inside", "select_value", "select_fraction", "neighbours", "neighbour_grid"]

_OPS = {"==": np.equal, "!=": np.not_equal, "<": np.less, "<=": np.less_equal,
        ">": np.greater, ">=": np.greater_equal}


def select_value(values: np.ndarray, op: str, value: float) -> np.ndarray:
    """Indices where ``values op value`` (op one of ``== != < <= > >=``)."""
    if op not in _OPS:
        raise CrowdError(f"selection: op must be one of {sorted(_OPS)}, got {op!r}")
    return np.flatnonzero(_OPS[op](np.asarray(values), value))


def select_inside(positions: np.ndarray, world_to_local: np.ndarray, low, high) -> np.ndarray:
    """Indices of ``positions`` (n, 3) inside the box ``low .. high`` of the space that
    the 4x4 ``world_to_local`` maps to (an object's bounds)."""
    p = np.asarray(positions, np.float64)
    m = np.asarray(world_to_local, np.float64)
    local = p @ m[:3, :3].T + m[:3, 3]
    return np.flatnonzero(((local >= np.asarray(low)) & (local <= np.asarray(high))).all(1))


def select_fraction(ids: np.ndarray, fraction: float, seed: int) -> np.ndarray:
    """A random ``fraction`` (0..1) of ``ids``, sorted, the same for equal inputs."""
    f = finite(fraction, "selection: fraction")
    if not 0 <= f <= 1:
        raise CrowdError(f"selection: fraction must be in 0..1, got {f:g}")
    ids = np.asarray(ids, np.int64)
    keep = int(round(f * ids.size))
    order = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x5E1EC7]).permutation(ids.size)
    return np.sort(ids[order[:keep]])


def neighbours(positions: np.ndarray, ids: np.ndarray, radius: float, grid=None):
    """Agents within ``radius`` of any of ``ids`` (themselves included), sorted; ``grid``
    from :func:`neighbour_grid` to reuse. Cost grows with the agents near ``ids``, not with N."""
    ids = np.asarray(ids, np.int64)
    if ids.size == 0 or radius <= 0:
        return np.unique(ids)
    order, keys, cells = grid if grid is not None else neighbour_grid(positions, radius)
    pos = np.asarray(positions, np.float64)
    near = []
    offsets = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    for d in offsets:            # 27 neighbouring cells, each a vectorised range lookup
        want = _cell_key(cells[ids] + d)
        lo = np.searchsorted(keys, want, "left")
        hi = np.searchsorted(keys, want, "right")
        counts = hi - lo
        if counts.sum() == 0:
            continue
        src = np.repeat(ids, counts)
        cand = order[np.repeat(lo - np.cumsum(counts) + counts, counts)
                     + np.arange(counts.sum())]
        close = np.einsum("ij,ij->i", pos[cand] - pos[src], pos[cand] - pos[src]) \
            <= radius * radius
        near.append(cand[close])
    return np.unique(np.concatenate(near + [ids]))


def _cell_key(cells: np.ndarray) -> np.ndarray:
    c = cells.astype(np.int64) + (1 << 20)
    return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]


def neighbour_grid(positions, radius):
    cells = np.floor(np.asarray(positions, np.float64) / radius).astype(np.int64)
    keys = _cell_key(cells)
    order = np.argsort(keys, kind="stable")
    return order, keys[order], cells
