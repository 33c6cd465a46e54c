"""Running a crowd over a shot into a :class:`~.recording.Recording`, once.

:func:`record` runs a :class:`~.crowd.Crowd` over ``first .. last`` with a
:class:`~.driver.FrameDriver` whose consumer is a :class:`Recorder` (a caller that
steps one frame at a time, a modal timer, drives its own FrameDriver with the
recorder's :meth:`~Recorder.capture`). The recorder reads only ``crowd.view``: see
:mod:`.recording` for what is kept. Before anything runs, shots are refused that would
simulate more than :data:`MAX_PREROLL` frames before their first frame, step more than
:data:`~.bounds.MAX_RUN_FRAMES` frames in all, or whose poses would take more than
:data:`MAX_BYTES`.
"""

from __future__ import annotations

import time
from numbers import Integral

import numpy as np

from ..base import pose as sqt
from ..runtime.agents import STREAM, TRANSITION
from ..base.errors import CrowdError
from .driver import FrameDriver
from .recording import TARGET_FIELDS, Recording

__all__ = ["Recorder", "record", "check_frames", "MAX_PREROLL", "MAX_BYTES"]


class Recorder:
    """Records ``crowd`` over ``first .. last``: give it each frame the crowd reaches
    (:meth:`capture`, a :class:`~.driver.FrameDriver` consumer).

    A crowd past ``first`` is reset to its start first. :meth:`finish` returns the
    :class:`Recording`. Events fired before the recorder was made (those of ``first``
    if the crowd is there) are not recorded.
    """

    def __init__(self, crowd, first, last):
        t = time.perf_counter()
        view = crowd.view
        self.first, self.last = check_frames(first, last, view.config.start_frame)
        _check_cost(view, self.first, self.last)
        self.crowd = crowd
        if view.frame > self.first:
            crowd.reset()
        self._recorded = None                      # the last frame recorded
        self._events = []
        self._handle = crowd.on_event("*", self._on_event)
        self._seconds = time.perf_counter() - t
        self.capture()

    @property
    def finished(self) -> bool:
        return self._recorded == self.last

    def capture(self, crowd=None):
        """Record the crowd's current frame: nothing before ``first`` or for a frame
        already recorded; a skipped frame, a crowd gone back or past ``last`` is an
        error. (``crowd``: the crowd a FrameDriver hands over, this recorder's.)"""
        if crowd is not None and crowd is not self.crowd:
            raise CrowdError("record: given another crowd's frame")
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

    def finish(self, stepped: float = 0.0) -> Recording:
        """The Recording (``stepped``: seconds the crowd's steps took, counted in its
        ``seconds`` with the recorder's own)."""
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
            color=self._color0, scale=np.array(v.agents.scale, np.float32),
            palette=np.array(v.agents.palette, np.float32),
            substeps=v.substeps,
            stream_subposes=self._stream_sub, unique_subposes=self._unique_sub,
            move_agent=mv[0], move_frame=mv[1], move_position=mv[2],
            move_heading=mv[3], events=tuple(self._events),
            **self._look_fields(v),
            stream_events=tuple(self._stream_events.columns(order_by=2)),
            seconds=self._seconds + float(stepped))

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
        subs = v.substeps - 1
        self._stream_sub = np.empty((frames + m - 1, subs, lay.streams) + pose, np.float32)
        self._unique_sub = np.empty((frames, subs, lay.uniques) + pose, np.float32)
        for f in range(self.first - m + 1, self.first):
            self._store(f)
        a = v.agents
        self._position0 = np.array(a.position, np.float32)
        self._heading0 = np.array(a.heading, np.float32)
        self._color0 = np.array(a.color, np.float32)
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
        # looks: every agent's (target, start, blend, stop) at ``first`` where it has a
        # target, then a row per agent whose look changed (only after view.looks.version
        # moved: a look starts or stops)
        looks = v.looks
        self._look_version = looks.version
        self._look_now = [np.array(getattr(looks, k)) for k in looks.STATE]
        self._looks = _Rows(i, i, i, i, np.zeros(0), i)
        ids = np.flatnonzero(self._look_now[0] >= 0)
        if ids.size:
            self._looks.add(ids, np.full(ids.size, self.first, np.int64),
                            *(a[ids] for a in self._look_now))

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
        if v.looks.version != self._look_version:
            self._look(f)

    def _look(self, f):
        """A row for each agent whose look differs from its last one."""
        looks = self.crowd.view.looks
        self._look_version = looks.version
        now = [np.asarray(getattr(looks, k)) for k in looks.STATE]
        new = np.zeros(now[0].size, bool)
        for a, b in zip(now, self._look_now):
            new |= a != b
        ids = np.flatnonzero(new)
        if ids.size:
            for a, b in zip(now, self._look_now):
                b[ids] = a[ids]
            self._looks.add(ids, np.full(ids.size, f, np.int64), *(a[ids] for a in now))

    def _look_fields(self, v) -> dict:
        """The Recording's look fields: the rows (sorted by agent, then frame), each
        agent's lag, the targets and the rigs' chains."""
        rows = self._looks.columns(order_by=0)
        return dict(look_agent=rows[0], look_frame=rows[1], look_target=rows[2],
                    look_start=rows[3], look_blend=rows[4], look_stop=rows[5],
                    look_lags=v.look_lags, look_targets=v.look_targets,
                    look_chains=v.look_chains)

    def _store(self, f):
        """The heads at ``f``, and the uniques at a shot frame ``f``."""
        v = self.crowd.view
        row = f - self.first + v.layout.max_offset - 1
        self._stream_poses[row] = v.stream_poses(f)
        for k in range(1, v.substeps):
            self._stream_sub[row, k - 1] = v.stream_poses(f, sub=k)
        if f >= self.first:
            self._unique_poses[f - self.first] = v.unique_poses()
            for k in range(1, v.substeps):
                self._unique_sub[f - self.first, k - 1] = v.unique_poses(sub=k)

    def _animation(self, agents, f):
        """New segments for ``agents`` whose animation differs from their last one."""
        a = self.crowd.view.agents
        now = np.zeros((agents.size, 8), np.int64)
        now[:, 0], now[:, 1] = a.kind[agents], a.ref[agents]
        now[:, 2] = np.where(now[:, 0] == STREAM, a.offset[agents], 0)
        tr = np.flatnonzero(now[:, 0] == TRANSITION)
        if tr.size:
            slot = self.crowd.view.transitions(agents[tr])
            for col, k in enumerate(TARGET_FIELDS, 3):
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
                                  *(slot[k][fresh] for k in TARGET_FIELDS))
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


def record(crowd, first, last, before_step=None, progress=None) -> Recording:
    """Record ``crowd`` over ``first .. last`` in one call: a FrameDriver with
    ``before_step(crowd, frame)`` (the simulation) and the :class:`Recorder`;
    ``progress("simulate", done, total)`` after each step."""
    recorder = Recorder(crowd, first, last)
    try:
        driver = FrameDriver(crowd, before_step, [recorder.capture])
        driver.run(recorder.last, None if progress is None else
                   (lambda done, total: progress("simulate", done, total)))
        return recorder.finish(driver.seconds)
    finally:
        recorder.close()


#: The most frames a recording may simulate before its first frame (an hour at 30 fps).
MAX_PREROLL = 108_000
#: The most bytes a recording's poses may take.
MAX_BYTES = 32 * 2**30


def _check_cost(view, first, last):
    """Refuse shots that would simulate for hours before their first frame or whose
    poses would not fit in memory, before anything runs or is allocated."""
    preroll = first - max(view.frame, view.config.start_frame)
    if view.frame > first:
        preroll = first - view.config.start_frame
    if preroll > MAX_PREROLL:
        raise CrowdError(f"record: frame {first} is {preroll:,} frames after the crowd's "
                         f"start frame {view.config.start_frame}; all of them would be "
                         f"simulated first (at most {MAX_PREROLL:,}); move the crowd's "
                         "start frame nearer the shot")
    lay = view.layout
    frames = last - first + 1
    pose_bytes = lay.bones * 10 * 4
    need = ((frames + lay.max_offset - 1) * lay.streams + frames * lay.uniques) * pose_bytes \
        * view.substeps
    if need > MAX_BYTES:
        samples = f", {view.substeps} samples a frame" if view.substeps > 1 else ""
        raise CrowdError(f"record: frames {first}-{last} ({frames:,} frames of "
                         f"{lay.streams} streams and {lay.uniques} uniques{samples}) need "
                         f"{need / 2**30:,.1f} GiB of poses, more than "
                         f"{MAX_BYTES / 2**30:.0f} GiB; record a shorter range")
    from ..base.bounds import check_run
    check_run("record", view.config.start_frame if view.frame > first else view.frame, last,
              "record the shot in chunks, each going on from the snapshot the last one "
              "left (crowd export --frames A-B --snapshots DIR, then crowd stitch)")


def check_frames(first, last, start) -> tuple:
    """``(first, last)`` as ints, checked to be a frame range that starts at or after
    the crowd's ``start`` frame (CrowdError otherwise)."""
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
