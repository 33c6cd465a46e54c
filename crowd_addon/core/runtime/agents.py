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

from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError

__all__ = ["STREAM", "UNIQUE", "TRANSITION", "assign_offsets", "assign_streams", "AgentIndex",
           "AgentState", "AgentChanges"]

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
        new = np.unique(agents[~self.stale[agents]])
        self.stale[agents] = True
        self.overlay = np.concatenate([self.overlay, new])
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


@dataclass(frozen=True)
class AgentChanges:
    """Agents changed since a reader's cursor (:meth:`AgentState.changes_since`).

    ``agents``: (k,) int64 ascending ids, or None when every agent must be treated as
    changed (the first read, after a reset, or when the reader fell too far behind);
    ``moved``: whether a position or heading may have changed; ``cursor``: pass it to
    the next call.
    """

    agents: np.ndarray | None
    moved: bool
    cursor: int


class AgentState:
    """What each agent plays and where it stands, with a log of who changed.

    Arrays (all ``(N, ...)``), read-only views for everyone else (change them with
    :meth:`set_animation` and :meth:`place`, which log the change):

    kind : (N,) int8 ``STREAM``/``UNIQUE``/``TRANSITION``; ref : (N,) int64 stream,
    unique or slot index; offset : (N,) int64 stream offset ``O``;
    position : (N, 3) float32 metres; heading : (N,) float32 radians about +Z;
    color : (N, 3) float32 RGB in 0..1; scale : (N,) float32 uniform scale of the
    body; palette : (N, 4, 3) float32 the colours of its character's palette
    materials (-1: none); scale and palette are set once, from the configuration.

    Readers (a renderer's instance texture, a recorder) keep a cursor and ask
    :meth:`changes_since` for the agents changed since, so nobody compares N-sized
    arrays per frame. The log keeps the newest ``max(N, 4096)`` logged ids; a reader
    whose cursor is older than what was forgotten is told to read every agent.
    """

    def __init__(self, position, heading, color, scale=None, palette=None):
        self.count = int(np.asarray(heading).shape[0])
        self._position = np.array(position, np.float32).reshape(self.count, 3)
        self._heading = np.array(heading, np.float32).reshape(self.count)
        self._color = np.array(color, np.float32).reshape(self.count, 3)
        self._scale = np.ones(self.count, np.float32) if scale is None else \
            np.array(scale, np.float32).reshape(self.count)
        self._palette = np.full((self.count, 4, 3), -1.0, np.float32) if palette is None \
            else np.array(palette, np.float32).reshape(self.count, 4, 3)
        self._kind = np.zeros(self.count, np.int8)
        self._ref = np.zeros(self.count, np.int64)
        self._offset = np.zeros(self.count, np.int64)
        self._serial = 1
        self._floor = 1                   # a cursor below this reads "everything"
        self._log = []                    # (serial, agents, moved); serials consecutive
        self._head = 0                    # the oldest entry still kept
        self._logged = 0
        self._keys = None
        self.index = None

    def index_by(self, keys):
        """Keep :attr:`index` (an :class:`AgentIndex`) of ``keys(agents) -> (k,)`` int64,
        the key of what each agent plays, up to date with every change."""
        self._keys = keys
        self.index = AgentIndex(keys(np.arange(self.count)))

    kind = property(lambda self: _read_only(self._kind))
    ref = property(lambda self: _read_only(self._ref))
    offset = property(lambda self: _read_only(self._offset))
    position = property(lambda self: _read_only(self._position))
    heading = property(lambda self: _read_only(self._heading))
    color = property(lambda self: _read_only(self._color))
    scale = property(lambda self: _read_only(self._scale))
    palette = property(lambda self: _read_only(self._palette))

    def reset(self, kind, ref, offset):
        """Every agent's animation reference at once; every agent counts as changed."""
        self._kind[:] = kind
        self._ref[:] = ref
        self._offset[:] = offset
        self._all_changed()

    def _all_changed(self):
        """Regroup the index and tell every reader to read every agent."""
        if self._keys is not None:
            self.index = AgentIndex(self._keys(np.arange(self.count)))
        self._serial += 1
        self._floor = self._serial
        self._log, self._head, self._logged = [], 0, 0

    #: the arrays a snapshot keeps (see :mod:`.snapshot`)
    STATE = ("kind", "ref", "offset", "position", "heading", "color")

    def state(self) -> dict:
        """The agent arrays a :mod:`.snapshot` keeps (views: the snapshot copies)."""
        return {k: getattr(self, "_" + k) for k in self.STATE}

    def set_state(self, state: dict):
        """Back to a :meth:`state`; every agent counts as changed (like :meth:`reset`)."""
        for k in self.STATE:
            getattr(self, "_" + k)[...] = state[k]
        self._all_changed()

    def set_animation(self, agents, kind, ref, offset=None):
        """Agents ``agents`` (k,) now play ``(kind, ref)`` (scalars or (k,) arrays), at
        ``offset`` when given (streams); logged as changed."""
        agents = np.asarray(agents, np.int64)
        self._kind[agents] = kind
        self._ref[agents] = ref
        if offset is not None:
            self._offset[agents] = offset
        if self.index is not None and agents.size:
            self.index.set(agents, self._keys(agents))
        self._record(agents, False)

    def place(self, agents, position=None, heading=None, color=None):
        """Move, turn or recolour agents ``agents`` (k,): ``position`` (k, 3) or (3,),
        ``heading`` (k,) or scalar radians, ``color`` (k, 3) or (3,); finite values
        only. Logged as changed (and moved, for a position or heading)."""
        agents = self.ids(agents)
        values = {}
        for name, value, shape in (("position", position, (agents.size, 3)),
                                   ("heading", heading, (agents.size,)),
                                   ("color", color, (agents.size, 3))):
            if value is None:
                continue
            try:
                v = np.broadcast_to(np.asarray(value, np.float32), shape)
            except ValueError:
                raise CrowdError(f"place agents: {name} of shape {np.shape(value)} does not "
                                 f"fit {agents.size} agents {shape}") from None
            if not np.isfinite(v).all():
                raise CrowdError(f"place agents: {name} must be finite")
            values[name] = v
        for name, v in values.items():
            getattr(self, "_" + name)[agents] = v
        self._record(agents, "position" in values or "heading" in values)

    def ids(self, agents) -> np.ndarray:
        """Agent ids as a flat int64 array (any shape is flattened), checked."""
        a = np.asarray(agents).reshape(-1)
        if a.size and not np.issubdtype(a.dtype, np.integer):
            raise CrowdError(f"agent ids must be integers, got {a.dtype}")
        a = a.astype(np.int64)
        bad = np.flatnonzero((a < 0) | (a >= self.count))
        if bad.size:
            raise CrowdError(f"agent id {int(a[bad[0]])} out of range 0..{self.count - 1}")
        return a

    def changes_since(self, cursor: int) -> AgentChanges:
        """The agents changed after ``cursor`` (0 for a new reader)."""
        if cursor < self._floor:
            return AgentChanges(None, True, self._serial)
        kept = len(self._log) - self._head
        start = self._head + max(0, cursor - (self._serial - kept))
        new = [(a, m) for _, a, m in self._log[start:]]
        if not new:
            return AgentChanges(np.zeros(0, np.int64), False, self._serial)
        agents = np.unique(np.concatenate([a for a, _ in new]))
        return AgentChanges(agents, any(m for _, m in new), self._serial)

    def _record(self, agents, moved):
        if agents.size == 0:
            return
        self._serial += 1
        self._log.append((self._serial, agents.copy(), bool(moved)))
        self._logged += agents.size
        limit = max(self.count, 4096)
        while self._logged > limit:          # forget the oldest: their readers read all
            serial, dropped, _ = self._log[self._head]
            self._head += 1
            self._logged -= dropped.size
            self._floor = serial
        if self._head > 1024 and 2 * self._head > len(self._log):
            del self._log[:self._head]
            self._head = 0


def _read_only(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v
