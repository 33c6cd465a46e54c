"""Agent animation references and the index that finds agents by reference.

An agent plays one of (paper s.4.1):

* a stream ``s`` at offset ``O`` (``kind == STREAM``, ``ref == s``): its pose is the
  stream's history ``PH_s(O)``, i.e. the stream head ``O`` frames ago;
* a unique animation ``u`` (``kind == UNIQUE``, ``ref == u``);
* a transition slot ``k`` (``kind == TRANSITION``, ``ref == k``) while blending.

Agents are arrays, never Python objects: ``kind (N,) int8``, ``ref (N,) int32``,
``offset (N,) int32``. Nothing here costs CPU per agent per frame.
"""

from __future__ import annotations

import numpy as np

from .errors import CrowdError

__all__ = ["STREAM", "UNIQUE", "TRANSITION", "assign_offsets", "assign_streams", "AgentIndex"]

STREAM, UNIQUE, TRANSITION = 0, 1, 2


def assign_offsets(count, max_offset, distribution="uniform", seed=0, mean=None, std=None,
                   offsets=None) -> np.ndarray:
    """Offsets in ``0 .. M-1`` per agent.

    Parameters
    ----------
    count : number of agents.
    max_offset : M.
    distribution : ``"uniform"`` (every offset equally likely), ``"normal"`` (mean
        ``mean`` default ``(M-1)/2``, deviation ``std`` default ``M/6``, rounded and
        clipped into range), or ``"given"`` with ``offsets``.
    seed : random seed (deterministic for equal inputs).
    """
    if count < 0:
        raise CrowdError(f"agents: count must be >= 0, got {count}")
    if max_offset < 1:
        raise CrowdError(f"agents: max offset M must be >= 1, got {max_offset}")
    rng = np.random.default_rng(seed)
    if distribution == "uniform":
        return rng.integers(0, max_offset, count).astype(np.int32)
    if distribution == "normal":
        mu = (max_offset - 1) / 2 if mean is None else float(mean)
        sd = max_offset / 6 if std is None else float(std)
        if not (np.isfinite(mu) and np.isfinite(sd) and sd >= 0):
            raise CrowdError("agents: normal offsets need a finite mean and std >= 0")
        return np.clip(np.rint(rng.normal(mu, sd, count)), 0, max_offset - 1).astype(np.int32)
    if distribution == "given":
        o = np.asarray(offsets)
        if o.shape != (count,):
            raise CrowdError(f"agents: {o.shape} given offsets for {count} agents")
        check_offsets(o, max_offset)
        return o.astype(np.int32)
    raise CrowdError(f"agents: unknown offset distribution {distribution!r} "
                     "(uniform, normal, given)")


def assign_streams(count, streams, weights=None, seed=0) -> np.ndarray:
    """Stream index per agent, drawn from ``range(streams)`` with optional weights."""
    if streams < 1:
        raise CrowdError("agents: needs at least one stream")
    rng = np.random.default_rng(seed)
    p = None
    if weights is not None:
        p = np.asarray(weights, np.float64)
        if p.shape != (streams,) or (p < 0).any() or p.sum() <= 0:
            raise CrowdError(f"agents: stream weights must be {streams} non-negative values "
                             "with a positive sum")
        p = p / p.sum()
    return rng.choice(streams, size=count, p=p).astype(np.int32)


def check_offsets(offsets, max_offset, what="agent"):
    o = np.asarray(offsets)
    if o.size and not np.issubdtype(o.dtype, np.integer):
        if not np.all(np.isfinite(o)) or not np.all(o == np.round(o)):
            raise CrowdError(f"{what} offsets must be whole frames")
    bad = np.flatnonzero((o < 0) | (o >= max_offset))
    if bad.size:
        raise CrowdError(f"{what} {int(bad[0])}: offset {o.reshape(-1)[bad[0]]} is outside "
                         f"0..{max_offset - 1} (M = {max_offset})")


class AgentIndex:
    """Finds the agents that play a given reference key, without per-frame sorting.

    Keys are integers (the crowd uses ``stream * M + offset`` for streamed agents and
    ``S * M + unique`` for unique ones). A sorted copy is rebuilt only after many
    changes; changes since the last rebuild live in a small overlay.
    """

    def __init__(self, keys: np.ndarray):
        self.keys = np.asarray(keys, np.int64).copy()
        self._rebuild()

    def _rebuild(self):
        self.order = np.argsort(self.keys, kind="stable")
        self.sorted_keys = self.keys[self.order]
        self.stale = np.zeros(self.keys.shape[0], bool)
        self.overlay = np.zeros(0, np.int64)

    def set(self, agents: np.ndarray, keys: np.ndarray):
        agents = np.asarray(agents, np.int64)
        self.keys[agents] = keys
        self.stale[agents] = True
        self.overlay = np.union1d(self.overlay, agents)
        if self.overlay.size > max(1024, self.keys.shape[0] // 8):
            self._rebuild()

    def lookup(self, keys: np.ndarray):
        """Agents for each key: ``(ids, which)`` where ``which`` indexes ``keys``."""
        keys = np.asarray(keys, np.int64)
        ids, which = _ranges(self.sorted_keys, keys, self.order, np.arange(keys.size))
        keep = ~self.stale[ids]
        ids, which = ids[keep], which[keep]
        if self.overlay.size:
            # agents changed since the rebuild: the same search the other way round,
            # each overlay agent's key among the sorted query keys
            srt = np.argsort(keys, kind="stable")
            which2, ids2 = _ranges(keys[srt], self.keys[self.overlay], srt, self.overlay)
            ids = np.concatenate([ids, ids2])
            which = np.concatenate([which, which2])
        return ids, which


def _ranges(sorted_keys, queries, sorted_values, query_values):
    """Every (value of a sorted key equal to a query, value of that query) pair:
    ``(sorted_values[j], query_values[i])`` for all ``sorted_keys[j] == queries[i]``."""
    lo = np.searchsorted(sorted_keys, queries, "left")
    counts = np.searchsorted(sorted_keys, queries, "right") - lo
    total = int(counts.sum())
    if total == 0:
        return sorted_values[:0], query_values[:0]
    pos = np.repeat(lo - np.cumsum(counts) + counts, counts) + np.arange(total)
    return sorted_values[pos], np.repeat(query_values, counts)
