"""The one loop that steps a crowd: every command, the viewport, the recorder and the
farm move a crowd through its frames with a :class:`FrameDriver`.

A step into frame ``F`` runs ``before_step(crowd, F)`` first (the simulation's hook:
requests, triggers, parameters, moves; the one hook name), then the crowd's step, then
each consumer ``consumer(crowd)`` (a recorder's capture, a renderer's frame, a
contact sheet, a snapshot writer), in order. :meth:`FrameDriver.seek` jumps as the
crowd's own replay does (back from its start or a kept snapshot, forward by stepping;
its show runs, the hook does not), for scrubbing and for starting a shot at a frame.
"""

from __future__ import annotations

import time

from ..base.errors import CrowdError

__all__ = ["FrameDriver"]


class FrameDriver:
    """Steps ``crowd`` (a :class:`~.crowd.Crowd`) and hands each frame to
    ``consumers``. ``seconds`` is the time spent in the hook and the steps (consumers
    excluded); ``steps`` the frames stepped."""

    def __init__(self, crowd, before_step=None, consumers=()):
        if before_step is not None and not callable(before_step):
            raise CrowdError(f"before_step must be a function (crowd, frame), got "
                             f"{before_step!r}")
        self.crowd = crowd
        self.before_step = before_step
        self.consumers = list(consumers)
        self.seconds = 0.0
        self.steps = 0

    def step(self):
        """Step into the next frame: the hook, the step, the consumers. An exception in
        the hook is raised as a CrowdError naming the frame (nothing stepped). Returns
        the crowd's StepReport."""
        t = time.perf_counter()
        frame = self.crowd.frame + 1
        if self.before_step is not None:
            try:
                self.before_step(self.crowd, frame)
            except Exception as e:  # noqa: BLE001 - reported with its frame
                raise CrowdError(f"before_step callback failed at frame {frame}: "
                                 f"{type(e).__name__}: {e}") from e
        report = self.crowd.step()
        self.steps += 1
        self.seconds += time.perf_counter() - t
        self.hand_over()
        return report

    def hand_over(self):
        """Give the crowd's current frame to every consumer."""
        for consume in self.consumers:
            consume(self.crowd)

    def run(self, last: int, progress=None):
        """Step until the crowd is at ``last``; ``progress(done, total)`` after each
        step."""
        total = int(last) - self.crowd.frame
        for done in range(1, total + 1):
            self.step()
            if progress is not None:
                progress(done, total)

    def seek(self, frame: int):
        """Jump to ``frame`` (``Crowd.advance_to``: back from the start or the nearest
        kept snapshot, forward by stepping; the hook does not run, the consumers are
        not given the frames passed). Returns the frame reached."""
        t = time.perf_counter()
        self.crowd.advance_to(frame)
        self.seconds += time.perf_counter() - t
        return self.crowd.frame
