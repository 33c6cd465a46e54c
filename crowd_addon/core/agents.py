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

    Keys are small non-negative integers (the crowd uses ``stream * M + offset`` for
    streamed agents and ``S * M + unique`` for unique ones, so fewer than the pose
    texture's rows). The agents are kept grouped by key (a radix argsort, O(N)) with
    each key's first position, so a lookup is two array reads per key. Agents changed
    since the last regrouping live in a small overlay searched apart; the index
    regroups once the overlay passes ``max(256, N / 64)`` agents.
    """

    def __init__(self, keys: np.ndarray):
        self.keys = np.asarray(keys, np.int64).copy()
        if self.keys.size and self.keys.min() < 0:
            raise ValueError("AgentIndex: keys must be >= 0")
        self.key_count = int(self.keys.max()) + 1 if self.keys.size else 1
        self._rebuild()

    def _rebuild(self):
        small = np.int16 if self.key_count <= np.iinfo(np.int16).max else np.int32
        self.order = np.argsort(self.keys.astype(small), kind="stable")   # radix sort
        counts = np.bincount(self.keys, minlength=self.key_count)
        self.first = np.concatenate([[0], np.cumsum(counts)])             # (K + 1,)
        self.stale = np.zeros(self.keys.shape[0], bool)
        self.overlay = np.zeros(0, np.int64)

    def set(self, agents: np.ndarray, keys: np.ndarray):
        agents = np.asarray(agents, np.int64)
        keys = np.asarray(keys, np.int64)
        self.keys[agents] = keys
        if keys.size and int(keys.max()) >= self.key_count:
            self.key_count = int(keys.max()) + 1
            self._rebuild()
            return
        self.stale[agents] = True
        self.overlay = np.union1d(self.overlay, agents)
        if self.overlay.size > max(256, self.keys.shape[0] // 64):
            self._rebuild()

    def lookup(self, keys: np.ndarray):
        """Agents for each key: ``(ids, which)`` where ``which`` indexes ``keys``."""
        keys = np.asarray(keys, np.int64)
        known = np.clip(keys, 0, self.key_count - 1)
        lo = np.where(keys == known, self.first[known], 0)
        counts = np.where(keys == known, self.first[known + 1], 0) - lo
        total = int(counts.sum())
        pos = np.repeat(lo - np.cumsum(counts) + counts, counts) + np.arange(total)
        ids = self.order[pos]
        which = np.repeat(np.arange(keys.size), counts)
        keep = ~self.stale[ids]
        ids, which = ids[keep], which[keep]
        if self.overlay.size:
            # agents changed since the regrouping: each one's key among the sorted
            # query keys
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
