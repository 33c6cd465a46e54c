"""A crowd shot simulated once and kept, for writers (USD) and anything else that
needs every agent at every frame of a shot without running the crowd again.

:func:`record`, or a :class:`Recorder` stepped one frame at a time (a modal timer),
runs a :class:`~.crowd.Crowd` over ``first .. last`` reading only ``crowd.view`` and
keeps: the stream heads' local poses at frames ``first - (M - 1) .. last`` (the pose
history unrolled: offset ``O`` shows the head of ``F - O``), the uniques' poses at
each frame, per agent *segments* of what it plays from a frame on (a stream at an
offset, a unique, or a transition with its StartP, ``t0``, ``L`` and target; only
agents ``view.agent_changes`` reports are looked at, and only a different animation
makes a segment), agent transforms and their changes, the events fired and the tags
the stream heads crossed. :meth:`Recording.agent_poses` rebuilds any pose at any shot
frame from these alone, as the crowd computes it (a transition shows
``blend2(StartP, target, clip((F - t0) / L, 0, 1))``). Nothing costs per agent per
frame beyond vectorised work on changed agents. Record a crowd built with
``skinning="gpu"``: only local poses are needed, so no CPU skinning runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property
from numbers import Integral

import numpy as np

from . import pose as sqt
from .agents import STREAM, TRANSITION, UNIQUE
from .errors import CrowdError

__all__ = ["Recording", "Recorder", "record"]

#: a transition's fields kept besides StartP (FrameView.transitions keys)
_TARGET = ("t0", "length", "target_kind", "target_ref", "target_offset")


@dataclass(frozen=True)
class Recording:
    """A recorded shot ``first .. last`` (inclusive, ``T`` frames) of ``N`` agents,
    ``S`` streams, ``U`` uniques, poses of ``B`` bones. Read-only.

    config : the crowd's CrowdConfig. max_offset : M. stream_skeleton (S,),
    agent_skeleton (N,) : int64 indices into ``list(config.skeletons)``.
    stream_poses : (T + M - 1, S, B, 10) float32 heads at :attr:`stream_frames`;
    unique_poses : (T, U, B, 10) float32 uniques at :attr:`frames`.
    segment_* (K,) : what agents play from ``segment_frame`` on, sorted by (agent,
    frame), every agent from ``first``: kind STREAM (``ref`` stream at ``offset``),
    UNIQUE (``ref`` unique) or TRANSITION (``ref`` a row of: ``start_pose`` (K2, B, 10)
    float32 StartP, ``t0``, ``length``, ``target_kind``/``_ref``/``_offset`` (K2,)).
    position (N, 3), heading (N,) float32 at ``first``; move_* (K3,): a new position
    and heading from ``move_frame`` on, sorted by (agent, frame).
    events : ``(name, frame, agent ids)`` per event fired while recording, in order.
    stream_events : ``(stream, name, frame)`` (k,) arrays of the tags the heads
    crossed at :attr:`stream_frames`, in frame order.
    seconds : wall-clock seconds spent in the recorder.
    """

    config: object
    first: int
    last: int
    fps: float
    max_offset: int
    stream_names: tuple
    unique_names: tuple
    stream_skeleton: np.ndarray
    agent_skeleton: np.ndarray
    stream_poses: np.ndarray
    unique_poses: np.ndarray
    segment_agent: np.ndarray
    segment_frame: np.ndarray
    segment_kind: np.ndarray
    segment_ref: np.ndarray
    segment_offset: np.ndarray
    start_pose: np.ndarray
    t0: np.ndarray
    length: np.ndarray
    target_kind: np.ndarray
    target_ref: np.ndarray
    target_offset: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    move_agent: np.ndarray
    move_frame: np.ndarray
    move_position: np.ndarray
    move_heading: np.ndarray
    events: tuple
    stream_events: tuple
    seconds: float

    @property
    def agent_count(self) -> int:
        return int(self.agent_skeleton.size)

    @property
    def frames(self) -> np.ndarray:
        """(T,) int64 shot frames ``first .. last``."""
        return np.arange(self.first, self.last + 1)

    @property
    def stream_frames(self) -> np.ndarray:
        """(T + M - 1,) int64 frames of the :attr:`stream_poses` rows."""
        return np.arange(self.first - self.max_offset + 1, self.last + 1)

    @cached_property
    def static(self) -> np.ndarray:
        """(N,) bool: plays one (stream, offset) at every frame of the shot."""
        count = np.bincount(self.segment_agent, minlength=self.agent_count)
        return (count == 1) & (self.segment_kind[np.cumsum(count) - 1] == STREAM)

    @cached_property
    def moving(self) -> np.ndarray:
        """(N,) bool: position or heading changed during the shot."""
        return np.bincount(self.move_agent, minlength=self.agent_count) > 0

    def playing(self, frames, agents=None) -> tuple:
        """``(kind, ref, offset)`` of the segments ``agents`` (default all) play at
        ``frames``: (k,) arrays for one frame, (T, k) for a (T,) array of frames."""
        frame, agents, shape = self._pairs(frames, agents)
        seg = self._find(0, frame, agents)
        return tuple(a[seg].reshape(shape) for a in (self.segment_kind, self.segment_ref,
                                                     self.segment_offset))

    def agent_poses(self, frames, agents=None) -> np.ndarray:
        """Local poses ``agents`` (default all) showed at ``frames``, as the crowd
        computed them: ``(k, B, 10)`` float32 for one frame, ``(T, k, B, 10)`` for a
        (T,) array of frames."""
        frame, agents, shape = self._pairs(frames, agents)
        seg = self._find(0, frame, agents)
        kind, ref = self.segment_kind[seg], self.segment_ref[seg]
        out = self._poses(frame, kind, ref, self.segment_offset[seg])
        m = np.flatnonzero(kind == TRANSITION)
        if m.size:
            t, f = ref[m], frame[m]
            target = self._poses(f, self.target_kind[t], self.target_ref[t],
                                 self.target_offset[t])
            s = np.clip((f - self.t0[t]) / self.length[t], 0.0, 1.0)
            out[m] = sqt.blend2(self.start_pose[t], target, s.astype(np.float32))
        return out.reshape(shape + out.shape[1:])

    def agent_transforms(self, frames, agents=None) -> tuple:
        """``(position (..., k, 3) float32, heading (..., k) float32)`` of ``agents`` at
        ``frames`` (one frame, or a (T,) array of frames)."""
        frame, agents, shape = self._pairs(frames, agents)
        pos, head = self.position[agents], self.heading[agents]
        if self.move_agent.size:
            i = self._find(1, frame, agents)
            hit = (i >= 0) & (self.move_agent[np.maximum(i, 0)] == agents)
            pos[hit], head[hit] = self.move_position[i[hit]], self.move_heading[i[hit]]
        return pos.reshape(shape + (3,)), head.reshape(shape)

    # ------------------------------------------------------------------ lookups
    def _pairs(self, frames, agents) -> tuple:
        """Flat (frame, agent) pairs of ``frames`` x ``agents`` and their shape."""
        agents = np.arange(self.agent_count) if agents is None else \
            np.asarray(agents, np.int64).reshape(-1)
        f = np.asarray(frames, np.int64)
        if f.size and (f.min() < self.first or f.max() > self.last):
            raise CrowdError(f"recording: frame {frames} is outside the shot "
                             f"{self.first}-{self.last}")
        shape = f.shape + agents.shape
        return np.repeat(f.reshape(-1), agents.size), np.tile(agents, f.size), shape

    @cached_property
    def _keys(self) -> tuple:
        """Ascending search keys of the segments and of the moves."""
        span = self.last - self.first + 1
        return (self.segment_agent * span + self.segment_frame - self.first,
                self.move_agent * span + self.move_frame - self.first)

    def _find(self, table, frame, agents) -> np.ndarray:
        """Per (frame, agent) pair, the index of the agent's last segment (``table`` 0)
        or move (1) at or before ``frame``; one of an earlier agent, or -1, if none."""
        key = agents * (self.last - self.first + 1) + frame - self.first
        return np.searchsorted(self._keys[table], key, "right") - 1

    def _poses(self, frame, kind, ref, offset) -> np.ndarray:
        """(n, B, 10) poses of streams ``ref`` at ``offset`` (kind STREAM) and uniques
        ``ref`` (UNIQUE) at ``frame`` ((n,) arrays); rows of other kinds are unset."""
        out = np.empty((kind.size,) + self.stream_poses.shape[2:], np.float32)
        st, un = kind == STREAM, kind == UNIQUE
        out[st] = self.stream_poses[frame[st] - offset[st] - self.first + self.max_offset - 1,
                                    ref[st]]
        out[un] = self.unique_poses[frame[un] - self.first, ref[un]]
        return out


class Recorder:
    """Records ``crowd`` over ``first .. last`` one frame at a time.

    A crowd past ``first`` is reset to its start first. :meth:`step` runs
    ``on_frame(crowd, frame)`` (the simulation: requests, triggers, parameters, agent
    moves; from the crowd's frame on, before the shot too), steps and records; a crowd
    stepped by someone else (a preview renderer) is recorded by :meth:`capture` after
    each of its steps. :meth:`finish` returns the :class:`Recording`. Events fired
    before the recorder was made (those of ``first`` if the crowd is there) are not
    recorded. ``done``/``total``: steps (``total = last -`` the crowd's frame then).
    """

    def __init__(self, crowd, first, last, on_frame=None):
        t = time.perf_counter()
        view = crowd.view
        self.first, self.last = _check_frames(first, last, view.config.start_frame)
        self.crowd, self.on_frame = crowd, on_frame
        if view.frame > self.first:
            crowd.reset()
        self.done, self.total = 0, self.last - view.frame
        self._recorded = None                      # the last frame recorded
        self._events = []
        self._handle = crowd.on_event("*", self._on_event)
        self._seconds = time.perf_counter() - t
        self.capture()

    @property
    def finished(self) -> bool:
        return self._recorded == self.last

    def step(self) -> bool:
        """Advance the crowd one frame and record it; returns whether frames remain.
        An exception in ``on_frame`` is raised as a CrowdError naming the frame."""
        if self.finished:
            raise CrowdError(f"record: frames {self.first}-{self.last} are recorded")
        t = time.perf_counter()
        frame = self.crowd.view.frame + 1
        if self.on_frame is not None:
            try:
                self.on_frame(self.crowd, frame)
            except Exception as e:  # noqa: BLE001 - reported with its frame
                raise CrowdError(f"on_frame callback failed at frame {frame}: "
                                 f"{type(e).__name__}: {e}") from e
        self.crowd.step()
        self.done += 1
        self._seconds += time.perf_counter() - t
        self.capture()                           # counts its own time
        return not self.finished

    def capture(self):
        """Record the crowd's current frame: nothing before ``first`` or for a frame
        already recorded; a skipped frame, a crowd gone back or past ``last`` is an
        error."""
        f = self.crowd.view.frame
        if f < self.first or f == self._recorded:
            return
        expected = self.first if self._recorded is None else self._recorded + 1
        if f != expected or f > self.last:
            raise CrowdError(f"record: the crowd is at frame {f}, the recording expects "
                             f"frame {expected} of {self.first}-{self.last}")
        t = time.perf_counter()
        if self._recorded is None:
            self._start()
        else:
            self._frame(f)
        self._recorded = f
        self._seconds += time.perf_counter() - t

    def close(self):
        """Stop listening to the crowd's events (:meth:`finish` does it)."""
        if self._handle is not None:
            self.crowd.events.off(self._handle)
            self._handle = None

    def finish(self) -> Recording:
        if not self.finished:
            raise CrowdError(f"record: frame {self.last} is not recorded yet (at "
                             f"{self._recorded})")
        self.close()
        v = self.crowd.view
        seg = self._segments.columns(order_by=0)             # (agent, frame)
        tr, mv = self._transitions.columns(), self._moves.columns(order_by=0)
        return Recording(
            config=v.config, first=self.first, last=self.last, fps=v.fps,
            max_offset=v.layout.max_offset, stream_names=v.stream_names,
            unique_names=v.unique_names, stream_skeleton=v.stream_skeleton,
            agent_skeleton=v.agent_skeleton, stream_poses=self._stream_poses,
            unique_poses=self._unique_poses, segment_agent=seg[0], segment_frame=seg[1],
            segment_kind=seg[2], segment_ref=seg[3], segment_offset=seg[4],
            start_pose=tr[0], t0=tr[1], length=tr[2], target_kind=tr[3], target_ref=tr[4],
            target_offset=tr[5], position=self._position0, heading=self._heading0,
            move_agent=mv[0], move_frame=mv[1], move_position=mv[2],
            move_heading=mv[3], events=tuple(self._events),
            stream_events=tuple(self._stream_events.columns(order_by=2)),
            seconds=self._seconds)

    # ---------------------------------------------------------------- recording
    def _on_event(self, name, frame, agents):
        if self.first <= frame <= self.last:
            self._events.append((name, int(frame), np.array(agents, np.int64)))

    def _start(self):
        v = self.crowd.view
        lay, n, m = v.layout, v.agent_count, v.layout.max_offset
        frames = self.last - self.first + 1
        pose = (lay.bones, sqt.WIDTH)
        self._stream_poses = np.empty((frames + m - 1, lay.streams) + pose, np.float32)
        self._unique_poses = np.empty((frames, lay.uniques) + pose, np.float32)
        for f in range(self.first - m + 1, self.first):
            self._store(f)
        a = v.agents
        self._position0 = np.array(a.position, np.float32)
        self._heading0 = np.array(a.heading, np.float32)
        self._position, self._heading = self._position0.copy(), self._heading0.copy()
        # what each agent plays now: kind, stream/unique/slot, offset, and a
        # transition's t0, length, target kind, ref, offset (to tell a new one)
        self._playing = np.full((n, 8), -1, np.int64)
        i, b = np.zeros(0, np.int64), np.zeros(0, np.int8)
        self._segments = _Rows(i, i, b, i, i)
        self._transitions = _Rows(np.zeros((0,) + pose, np.float32), i, i, b, i, i)
        self._moves = _Rows(i, i, np.zeros((0, 3), np.float32), np.zeros(0, np.float32))
        self._stream_events = _Rows(*v.stream_events(self.first - m + 1))
        self._cursor = v.agent_changes(0).cursor
        self._store(self.first)
        self._animation(np.arange(n), self.first)

    def _frame(self, f):
        v = self.crowd.view
        self._store(f)
        self._stream_events.add(*v.stream_events(f))
        changes = v.agent_changes(self._cursor)
        self._cursor = changes.cursor
        agents = np.arange(v.agent_count) if changes.agents is None else changes.agents
        if agents.size:
            self._animation(agents, f)
            if changes.moved:
                self._move(agents, f)

    def _store(self, f):
        """The heads at ``f``, and the uniques at a shot frame ``f``."""
        v = self.crowd.view
        self._stream_poses[f - self.first + v.layout.max_offset - 1] = v.stream_poses(f)
        if f >= self.first:
            self._unique_poses[f - self.first] = v.unique_poses()

    def _animation(self, agents, f):
        """New segments for ``agents`` whose animation differs from their last one."""
        a = self.crowd.view.agents
        now = np.zeros((agents.size, 8), np.int64)
        now[:, 0], now[:, 1] = a.kind[agents], a.ref[agents]
        now[:, 2] = np.where(now[:, 0] == STREAM, a.offset[agents], 0)
        tr = np.flatnonzero(now[:, 0] == TRANSITION)
        if tr.size:
            slot = self.crowd.view.transitions(agents[tr])
            for col, k in enumerate(_TARGET, 3):
                now[tr, col] = slot[k]
        new = (now != self._playing[agents]).any(1)
        if not new.any():
            return
        ids, now = agents[new], now[new]
        self._playing[ids] = now
        kind, ref = now[:, 0].astype(np.int8), now[:, 1].copy()
        fresh = new[tr]
        if fresh.any():
            ref[kind == TRANSITION] = self._transitions.count + np.arange(int(fresh.sum()))
            self._transitions.add(slot["start_pose"][fresh],
                                  *(slot[k][fresh] for k in _TARGET))
        self._segments.add(ids, np.full(ids.size, f, np.int64), kind, ref, now[:, 2])

    def _move(self, agents, f):
        """Transforms of ``agents`` whose position or heading differs from the last."""
        a = self.crowd.view.agents
        pos, head = np.asarray(a.position[agents]), np.asarray(a.heading[agents])
        new = (pos != self._position[agents]).any(1) | (head != self._heading[agents])
        if new.any():
            ids = agents[new]
            self._position[ids], self._heading[ids] = pos[new], head[new]
            self._moves.add(ids, np.full(ids.size, f, np.int64), pos[new], head[new])


class _Rows:
    """Table rows added in batches, one array per column."""

    def __init__(self, *empty):
        self._parts, self.count = [empty], 0

    def add(self, *columns):
        self._parts.append(columns)
        self.count += len(columns[0])

    def columns(self, order_by=None) -> list:
        """The columns, rows sorted (stably) by column ``order_by`` if given."""
        cols = [np.concatenate(c) for c in zip(*self._parts)]
        if order_by is None:
            return cols
        order = np.argsort(cols[order_by], kind="stable")
        return [c[order] for c in cols]


def record(crowd, first, last, on_frame=None, progress=None) -> Recording:
    """Record ``crowd`` over ``first .. last`` in one call (:class:`Recorder` stepped to
    the end); ``progress("simulate", done, total)`` after each step."""
    recorder = Recorder(crowd, first, last, on_frame)
    try:
        while not recorder.finished:
            recorder.step()
            if progress is not None:
                progress("simulate", recorder.done, recorder.total)
        return recorder.finish()
    finally:
        recorder.close()


def _check_frames(first, last, start) -> tuple:
    for f in (first, last):
        if isinstance(f, bool) or not isinstance(f, Integral):
            raise CrowdError(f"record: frames must be whole numbers, got {first!r}, "
                             f"{last!r}")
    first, last = int(first), int(last)
    if last < first:
        raise CrowdError(f"record: frame range {first}-{last} is empty (last < first)")
    if first < int(start):
        raise CrowdError(f"record: frame range {first}-{last} starts before the crowd's "
                         f"start frame {int(start)}")
    return first, last
