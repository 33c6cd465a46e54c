"""The paper's two animation pools (s.4.1-4.2): streams with their pose history, and
uniques.

:class:`StreamPool` is the only code that knows the ring rule: frame ``F`` of the
streams is written to history slice ``F mod M``, and an agent at offset ``O`` shows
slice ``(F - O) mod M`` (the pose the head had ``O`` frames ago, ``PH_s(O)``); and the
only code that knows an agent's index key ``stream * M + offset`` (unique ``u`` has key
``S * M + u``, :meth:`UniquePool.key`). In the pose texture a history slice is ``S``
consecutive rows, so stream ``s`` at slice ``k`` is logical row ``k * S + s``.
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from .agents import check_offsets
from ..base.errors import CrowdError
from ..base.state import assign

__all__ = ["StreamPool", "UniquePool", "resolve_index", "stream_key"]


def resolve_index(names, target, what: str) -> int:
    """Index of ``target`` (a name in ``names`` or an index) among ``what``s."""
    if isinstance(target, str):
        if target not in names:
            raise CrowdError(f"unknown {what} {target!r} (known: {list(names)})")
        return list(names).index(target)
    if isinstance(target, (int, np.integer)) and not isinstance(target, bool) \
            and 0 <= int(target) < len(names):
        return int(target)
    raise CrowdError(f"unknown {what} index {target!r} ({len(names)} {what}s)")


def stream_key(stream, offset, max_offset):
    """The key of agents playing ``(stream, offset)``: ``stream * M + offset``, unique
    per pair (``divmod(key, M)`` gives them back); a unique's key is past every
    stream's (:meth:`UniquePool.key`). The agent index, event delivery and the USD
    export's offset animations share it."""
    return stream * max_offset + offset


class StreamPool:
    """``S`` streams evaluated once a frame, each with an ``M``-frame pose history.

    Attributes
    ----------
    names : list of S names; skeleton : (S,) int64 skeleton index per stream.
    max_offset : M; count : S.
    history : (M, S, B, 10) float32 local-pose ring (a view into the crowd's pose
        storage when the GPU skins).
    """

    def __init__(self, names, skeleton, max_offset: int, history: np.ndarray, tag_names):
        self.names = list(names)
        self.count = len(self.names)
        self.skeleton = np.asarray(skeleton, np.int64)
        self.max_offset = int(max_offset)
        self.history = history
        self._records = sqt.records(history)          # whole-bone gathers and scatters
        self._tag_names = np.asarray(list(tag_names), object)
        self.clear_events()

    # ------------------------------------------------------------- the ring rule
    def slice(self, frame, offset=0):
        """History slice of ``PH(offset)`` at ``frame``: ``(frame - offset) mod M``
        (ints or int arrays)."""
        return (frame - offset) % self.max_offset

    def row(self, frame, stream, offset=0):
        """Logical pose-texture row of stream ``stream`` at ``offset`` at ``frame``."""
        return self.slice(frame, offset) * self.count + stream

    def key(self, stream, offset):
        """Index key of agents playing ``(stream, offset)`` (:func:`stream_key`)."""
        return stream_key(stream, offset, self.max_offset)

    @property
    def key_count(self) -> int:
        return self.count * self.max_offset

    def poses(self, frame, stream, offset) -> np.ndarray:
        """``(k, B, 10)`` local poses ``PH_stream(offset)`` at ``frame`` ((k,) arrays)."""
        at = self.slice(frame, offset)
        if np.ndim(at) == 0 and np.ndim(stream) == 0:
            return self.history[at, stream]
        return sqt.from_records(self._records[at, stream])

    def store(self, frame: int, poses: np.ndarray):
        """Write the heads' poses ``(S, B, 10)`` of ``frame`` into the ring."""
        self._records[self.slice(frame)] = sqt.records(np.ascontiguousarray(poses))

    def head_poses(self, frame: int, now: int) -> np.ndarray:
        """A copy of every head's pose ``(S, B, 10)`` at ``frame``, one of the last M
        frames before ``now``."""
        if not now - self.max_offset < frame <= now:
            raise CrowdError(f"stream poses: frame {frame} is not in the history "
                             f"(frames {now - self.max_offset + 1}..{now})")
        return self.history[self.slice(frame)].copy()

    def index(self, target) -> int:
        return resolve_index(self.names, target, "stream")

    def check_offsets(self, offsets, what="agent"):
        check_offsets(offsets, self.max_offset, what)

    def offsets_for(self, offset, count: int) -> np.ndarray:
        """``offset`` (a scalar or ``count`` values) as ``(count,)`` int64 offsets of a
        transition request, checked against 0..M-1."""
        off = np.asarray(offset).reshape(-1)
        if off.size not in (1, count):
            raise CrowdError(f"transition: {off.size} offsets for {count} agents")
        check_offsets(off, self.max_offset, "transition")
        return np.broadcast_to(off, (count,)).astype(np.int64)

    def state(self) -> dict:
        """What a :mod:`.snapshot` keeps: the history ring and the crossings log."""
        return {"history": self.history, "log_stream": self._log_stream,
                "log_name": self._log_name, "log_frame": self._log_frame}

    def set_state(self, state: dict):
        logs = [np.array(state[k], np.int64).reshape(-1)
                for k in ("log_stream", "log_name", "log_frame")]
        if len({a.size for a in logs}) != 1:
            raise ValueError("the event log's arrays differ in length")
        if not (((logs[0] >= 0) & (logs[0] < self.count)).all()
                and ((logs[1] >= 0) & (logs[1] < len(self._tag_names))).all()):
            raise ValueError("the event log names a stream or tag that does not exist")
        assign(self.history, state["history"])
        self._log_stream, self._log_name, self._log_frame = logs

    # ------------------------------------------------------------------ events
    def clear_events(self):
        self._log_stream = np.zeros(0, np.int64)
        self._log_name = np.zeros(0, np.int64)
        self._log_frame = np.zeros(0, np.int64)

    def log_events(self, frame: int, streams: np.ndarray, names: np.ndarray):
        """Keep the tags ``names`` (k,) (tag indices) the heads of ``streams`` (k,)
        crossed at ``frame``; crossings older than M frames are dropped."""
        self._log_stream = np.concatenate([self._log_stream, streams])
        self._log_name = np.concatenate([self._log_name, names])
        self._log_frame = np.concatenate([self._log_frame,
                                          np.full(streams.size, frame, np.int64)])
        live = frame - self._log_frame < self.max_offset
        self._log_stream = self._log_stream[live]
        self._log_name = self._log_name[live]
        self._log_frame = self._log_frame[live]

    def crossings_reaching(self, frame: int):
        """``(keys, tag indices)`` of the logged crossings that agents see at
        ``frame``: a crossing at frame ``f`` reaches offset ``frame - f``."""
        return self.key(self._log_stream, frame - self._log_frame), self._log_name

    def events_since(self, since_frame: int):
        """``(stream, name, frame)`` arrays of crossings at frames ``>= since_frame``."""
        keep = self._log_frame >= int(since_frame)
        return (self._log_stream[keep].copy(), self._tag_names[self._log_name[keep]],
                self._log_frame[keep].copy())


class UniquePool:
    """``U`` unique animations: one agent's own, current pose only (no history).

    Attributes
    ----------
    names : list of U names; skeleton : (U,) int64 skeleton index per unique.
    poses : (U, B, 10) float32 current poses (a view into the pose storage when the
        GPU skins).
    start : (U,) int64 frame each unique's clock started (its time is
        ``frame - start``).
    key_base : the first index key of uniques (``S * M``).
    """

    def __init__(self, names, skeleton, poses: np.ndarray, key_base: int):
        self.names = list(names)
        self.count = len(self.names)
        self.skeleton = np.asarray(skeleton, np.int64)
        self.poses = poses
        self.start = np.zeros(self.count, np.int64)
        self.key_base = int(key_base)

    def state(self) -> dict:
        """What a :mod:`.snapshot` keeps: current poses and clock starts."""
        return {"poses": self.poses, "start": self.start}

    def set_state(self, state: dict):
        self.poses[...] = state["poses"]
        self.start[...] = state["start"]

    def key(self, unique):
        return self.key_base + unique

    def times(self, frame: int) -> np.ndarray:
        """(U,) float64 clip time of each unique at ``frame``."""
        return (frame - self.start).astype(np.float64)

    def restart(self, unique: int, frame: int):
        """Unique ``unique`` plays from its beginning at ``frame``."""
        self.start[unique] = frame

    def index(self, target) -> int:
        return resolve_index(self.names, target, "unique")
