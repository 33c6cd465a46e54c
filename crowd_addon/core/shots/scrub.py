"""How a crowd moves through its frames (``Crowd.advance_to``): forward by stepping,
back by replaying from the start or from the nearest snapshot kept, and what a replay
would not make again.

A change made from outside a step (a request, a parameter, a trigger, a move, a
restore) is not made again by a re-simulation, so the snapshots taken after it no
longer show the run's frames: :meth:`Scrub.changed` forgets them, and going back before
such a change forgets those taken after it (:meth:`Scrub.replay_from`). Steps, resets
and restores run :meth:`Scrub.inside`, where changes are the crowd's own.
"""

from __future__ import annotations

from contextlib import contextmanager

from ..base.bounds import MAX_RUN_FRAMES, check_run, whole_frame
from . import crowd_state
from .snapshot_store import SnapshotCache

__all__ = ["Scrub"]


class Scrub:
    """A crowd's snapshots kept (``snapshots``: a SnapshotCache once :meth:`keep` is
    called) and the frames of changes made from outside a step."""

    def __init__(self, crowd):
        self.crowd = crowd
        self.snapshots = None
        self._quiet = 0                # > 0 inside step/reset/restore: not a user's change
        self._outside = []             # frames of changes made from outside a step

    @contextmanager
    def inside(self):
        """Changes made in this block are the crowd's own (a step, reset or restore)."""
        self._quiet += 1
        try:
            yield
        finally:
            self._quiet -= 1

    def keep(self, every, max_bytes):
        """Keep a snapshot every ``every`` frames, at most ``max_bytes`` (None: stop)."""
        self.snapshots = None if every is None else SnapshotCache(every, max_bytes)
        self._outside = []
        self.stepped()
        return self.snapshots

    def stepped(self):
        """After a step: keep this frame when it is on the snapshot grid of a run from
        the start frame."""
        c = self.crowd
        if self.snapshots is not None and c._origin == c.config.start_frame \
                and self.snapshots.wants(c.frame, c._origin):
            self.snapshots.add(c.snapshot(), c._origin)

    def changed(self):
        """The run changes here (not replayed by a re-simulation): later snapshots go."""
        if self._quiet == 0 and self.snapshots is not None:
            self.snapshots.drop_after(self.crowd.frame)
            self._outside.append(self.crowd.frame)

    def replay_from(self, frame):
        """The run is replayed from ``frame``: changes made from outside a step at or
        after it are not made again, so the snapshots taken after the first of them
        go."""
        lost = [f for f in self._outside if f >= frame]
        if lost and self.snapshots is not None:
            self.snapshots.drop_after(min(lost))
        self._outside = [f for f in self._outside if f < frame]

    def jump_snapshot(self, frame: int):
        """The kept snapshot :meth:`advance_to` would start from to reach ``frame``
        (None when it steps on from here or resets)."""
        c = self.crowd
        if self.snapshots is None or frame <= c.config.start_frame:
            return None
        snap = self.snapshots.nearest(int(frame) - 1)
        if snap is None or not (frame < c.frame or snap.frame > c.frame):
            return None
        return snap

    def advance_to(self, frame: int):
        """``Crowd.advance_to``: checked, then from a snapshot, a reset or here."""
        c = self.crowd
        frame = whole_frame(frame, "advance_to")
        start = c.config.start_frame
        snap = self.jump_snapshot(frame)
        # where the run starts: the snapshot, or here, or the frame reset to (going
        # back); a replay below only drops snapshots after the one jumped from
        origin = snap.frame if snap is not None else \
            c.frame if frame >= c.frame else min(start, frame)
        check_run("advance_to", origin, frame,
                  f"advance_to({origin + MAX_RUN_FRAMES}) first, then on from there, each "
                  "call at most that many frames further")
        if frame < c.frame and self._outside:   # replayed from there: changes lost
            self.replay_from(snap.frame if snap is not None else start)
            snap = self.jump_snapshot(frame)
        if snap is not None:
            with self.inside():
                crowd_state.set_state(c, snap.state())   # one of ours: already checked
        elif frame < c.frame:
            c.reset(start if frame >= start else frame)
        while c.frame < frame:
            c.step()
