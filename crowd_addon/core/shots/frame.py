"""The frame (paper s.4.2): what one :meth:`Crowd.step <.crowd.Crowd.step>` does, as
tasks in a dependency graph (s.4.4-4.5), and the history warm-up of a reset.

Frame ``F``: queued requests take free slots; every stream root is evaluated once and
written to the history, uniques to their current poses (the trees batched by kind,
depth and height); slots whose target is already in history blend first, those that
need this frame's target after it; finished slots hand their agents over; the
skinning mode writes the rows that changed; event tags reach the agents.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..anim.graph import DependencyGraph
from ..anim.sub_keys import on_grid
from ..runtime.events import deliver

__all__ = ["Frame", "StepReport"]


@dataclass(frozen=True)
class StepReport:
    frame: int
    ms: float
    upload_bytes: int
    transitions_active: int
    transitions_started: int
    transitions_finished: int
    events: int


class Frame:
    """A crowd's frame tasks, in ``graph`` (a :class:`~.graph.DependencyGraph`)."""

    def __init__(self, crowd, stream_speed, stream_phase):
        self.crowd = crowd
        self.speed = np.asarray(stream_speed, np.float64)
        self.phase = np.asarray(stream_phase, np.float64)
        #: the streams at another speed than 1, whose times move on the sub-frame grid
        #: their clips are resampled at (:mod:`~..anim.sub_keys`)
        self.gridded = np.flatnonzero(self.speed != 1.0)
        self.finished = 0
        self.graph = self._build()

    def _build(self) -> DependencyGraph:
        c, g = self.crowd, DependencyGraph()
        g.add("transitions.partition", self._partition_transitions)
        g.add("transitions.ready", lambda: self._blend("ready"),
              after=["transitions.partition"])
        names = []
        for i, b in enumerate(c.evaluator.evaluate_order):
            name = f"controllers.{type(b).__qualname__.split('.')[0]}@{b.height}#{i}"
            lower = [n for n, bb in zip(names, c.evaluator.evaluate_order)
                     if bb.height < b.height]
            g.add(name, (lambda b=b: b.evaluate(c.evaluator.ctx)), after=lower)
            names.append(name)
        g.add("roots.store", self.store_roots, after=names)
        g.add("transitions.waiting", lambda: self._blend("waiting"),
              after=["transitions.partition", "roots.store"])
        g.add("transitions.finish", self._finish_transitions,
              after=["transitions.ready", "transitions.waiting"])
        g.add("skinning", c.skinning.slots_blended,
              after=["roots.store", "transitions.finish"])
        g.add("events", lambda: self.deliver_events(True),
              after=["roots.store", "transitions.finish"])
        return g

    def step(self) -> StepReport:
        """Frame ``crowd.frame + 1``; what it cost."""
        c = self.crowd
        t_start = time.perf_counter()
        mark = c.storage.mark()
        if c.show is not None:
            c.show.before_step(c.frame + 1)
        started = c.slots.serve_queue()
        c.frame += 1
        self.finished = 0
        c._events_fired = 0
        c.evaluator.prepare(self.root_times(c.frame))
        self.graph.run()
        self.store_substeps()
        ms = (time.perf_counter() - t_start) * 1e3
        c._steps += 1
        c._ms_total += ms
        return StepReport(c.frame, ms, c.storage.bytes_since(mark),
                          int(c.slots.active.sum()), started, self.finished,
                          c._events_fired)

    def warm_up(self, f0):
        """Fill the history: the streams evaluated at ``f0 - M + 1 .. f0``, tags crossed
        logged (dispatched at ``f0`` only)."""
        c = self.crowd
        for f in range(f0 - c.streams.max_offset + 1, f0 + 1):
            c.frame = f
            c.evaluator.prepare(self.root_times(f))
            c.evaluator.evaluate()
            self.store_roots()
            self.store_substeps()
            self.deliver_events(dispatch=(f == f0))

    def root_times(self, frame, sub=0.0):
        """Root times at ``frame + sub``: a stream's ``phase + speed * t``
        (:class:`~.config.AnimationDef`; on the sub-frame grid for a speed other than
        1), a unique's own clock."""
        t = float(frame) + sub
        streams = self.phase + self.speed * t
        if self.gridded.size:
            streams[self.gridded] = on_grid(streams[self.gridded])
        return np.concatenate([streams, self.crowd.uniques.times(frame) + sub])

    def store_roots(self):
        c = self.crowd
        poses = c.evaluator.ctx.poses[c.evaluator.root_index]
        c.streams.store(c.frame, poses[:c.streams.count])
        c.uniques.poses[:] = poses[c.streams.count:]
        c.skinning.roots_stored(c.frame)

    def store_substeps(self):
        """The streams' and uniques' poses at ``frame + k / N`` from the state reached
        now (nothing without substeps)."""
        c = self.crowd
        c.subs.store(c.streams.slice(c.frame), lambda t: c.evaluator.poses_ahead(
            self.root_times(c.frame, t)))

    def deliver_events(self, dispatch):
        """Deliver this frame's tags (during the history warm-up: only log them)."""
        c = self.crowd
        roots, names = c.evaluator.ctx.take_events()
        c._events_fired += deliver(c.frame, roots, names, c.streams, c.uniques,
                                   c.agents.index, c.events if dispatch else None,
                                   c.bank.tag_names)

    # ---------------------------------------------------------------- transitions
    def _partition_transitions(self):
        self._tr, self._s = self.crowd.slots.partition(), {}

    def _blend(self, which):
        self._s[which] = self.crowd.skinning.blend(self._tr[which], self.crowd.frame)

    def _finish_transitions(self):
        self.finished = self.crowd.slots.finish(
            np.concatenate([self._tr["ready"], self._tr["waiting"]]),
            np.concatenate([self._s["ready"], self._s["waiting"]]))
