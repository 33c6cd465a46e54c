"""Snapshots kept: the cache a crowd jumps from when scrubbing
(:class:`SnapshotCache`), and folders of snapshot files a chunked export starts its
chunks from (:class:`SnapshotFolder`, :func:`write_snapshots`,
:class:`ShotSnapshots`; docs/snapshots.md).
"""

from __future__ import annotations

import os

import numpy as np

from ..base.bounds import MAX_RUN_FRAMES, check_run, whole_frame
from ..base.errors import CrowdError
from .driver import FrameDriver
from .snapshot import Snapshot, load_snapshot

__all__ = ["SnapshotCache", "SnapshotFolder", "write_snapshots", "ShotSnapshots"]


class SnapshotCache:
    """Snapshots of one crowd's run every :attr:`every` frames, within ``max_bytes``:
    what lets a crowd jump to any frame by stepping at most ``every - 1`` frames from
    the nearest one (:meth:`Crowd.advance_to <.crowd.Crowd.advance_to>`).

    Frames ``origin + k * every`` are kept as the crowd steps past them. When the next
    one would pass ``max_bytes``, :attr:`every` doubles and the snapshots off the new
    grid are dropped, so a long shot always fits and the farthest a jump re-simulates
    grows with it. :attr:`requested` is the spacing asked for; :attr:`fits` is False
    when not even one snapshot fits in ``max_bytes`` (then none is kept).
    """

    def __init__(self, every: int = 30, max_bytes: int = 2 << 30):
        if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
            raise CrowdError(f"snapshots: every must be a whole number of frames >= 1, "
                             f"got {every!r}")
        if isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, np.integer)) \
                or max_bytes < 0:
            raise CrowdError(f"snapshots: the memory cap must be bytes >= 0, got "
                             f"{max_bytes!r}")
        self.requested = self.every = int(every)
        self.max_bytes = int(max_bytes)
        self.fits = True
        self._snaps = {}

    def __len__(self) -> int:
        return len(self._snaps)

    @property
    def frames(self) -> list:
        return sorted(self._snaps)

    @property
    def nbytes(self) -> int:
        return sum(s.nbytes for s in self._snaps.values())

    def wants(self, frame: int, origin: int) -> bool:
        """Whether the crowd at ``frame`` (of a run started at ``origin``) is one to keep."""
        return (frame - origin) % self.every == 0 and frame not in self._snaps and self.fits

    def add(self, snap: Snapshot, origin: int):
        """Keep ``snap`` (taken where :meth:`wants` said so), thinning to stay in the cap."""
        if snap.nbytes > self.max_bytes:
            self.fits = False
            return
        self._snaps[snap.frame] = snap
        while self.nbytes > self.max_bytes:
            self.every *= 2
            self._snaps = {f: s for f, s in self._snaps.items()
                           if (f - origin) % self.every == 0}

    def nearest(self, frame: int) -> Snapshot | None:
        """The kept snapshot at ``frame`` or the latest before it (None if none)."""
        before = [f for f in self._snaps if f <= frame]
        return self._snaps[max(before)] if before else None

    def drop_after(self, frame: int):
        """Forget the snapshots past ``frame`` (the run changed there)."""
        self._snaps = {f: s for f, s in self._snaps.items() if f <= frame}

    def clear(self):
        self._snaps = {}
        self.fits = True


class SnapshotFolder:
    """A folder of snapshot files, one per (crowd configuration, samples per frame,
    frame): ``snap_<digest[:16]>_s<substeps>_f<frame>.npz``, so several shots may
    share one folder. What ``crowd snapshot`` writes and ``crowd export --snapshots``
    starts from (docs/snapshots.md)."""

    def __init__(self, path, create: bool = False):
        self.path = os.fspath(path)
        if create:
            try:
                os.makedirs(self.path, exist_ok=True)
            except OSError as e:
                raise CrowdError(f"{self.path}: cannot create the snapshot folder: {e}") \
                    from None
        if not os.path.isdir(self.path):
            raise CrowdError(f"{self.path}: no such snapshot folder")

    @staticmethod
    def _stem(crowd) -> str:
        return f"snap_{crowd.config_digest[:16]}_s{crowd.substeps}_f"

    def file(self, crowd, frame: int) -> str:
        """The file of ``crowd``'s snapshot at ``frame``."""
        return os.path.join(self.path, f"{self._stem(crowd)}{int(frame)}.npz")

    def frames(self, crowd) -> list:
        """Frames of the snapshots of ``crowd``'s configuration here, ascending."""
        stem, out = self._stem(crowd), []
        for name in os.listdir(self.path):
            if name.startswith(stem) and name.endswith(".npz"):
                try:
                    out.append(int(name[len(stem):-4]))
                except ValueError:
                    continue
        return sorted(out)

    def save(self, crowd) -> str:
        """Write ``crowd``'s snapshot now; returns the file."""
        path = self.file(crowd, crowd.frame)
        crowd.snapshot().save(path)
        return path

    def start(self, crowd, first: int):
        """Restore into ``crowd`` the latest snapshot of it here before ``first`` (at
        frame ``first - 1`` or earlier) when that is ahead of the crowd; returns its
        frame, or None when there is none (the crowd is left as it was)."""
        usable = [f for f in self.frames(crowd) if crowd.frame < f < first]
        if not usable:
            return None
        crowd.restore(load_snapshot(self.file(crowd, usable[-1])))
        return usable[-1]


def write_snapshots(crowd, folder: SnapshotFolder, first: int, last: int, every: int,
                    progress=None) -> list:
    """Step ``crowd`` to ``last`` (from the latest snapshot in ``folder`` before
    ``first`` when there is one) and write a snapshot at ``first - 1`` and every
    ``every`` frames after it (the frame before each ``every``-frame chunk of
    ``first .. last``; none before the start frame, where a chunk needs none) and at
    ``last``. Returns the files written.
    ``progress(done, total)`` after each step. A pass that would step more than
    :data:`~.bounds.MAX_RUN_FRAMES` frames is refused before its first step."""
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise CrowdError(f"snapshots: every must be a whole number of frames >= 1, "
                         f"got {every!r}")
    first, last = whole_frame(first, "snapshots"), whole_frame(last, "snapshots")
    if first > last:
        raise CrowdError(f"snapshots: frames {first}-{last}: the first is after the last")
    folder.start(crowd, first)
    end = crowd.frame + MAX_RUN_FRAMES
    check_run("snapshots", crowd.frame, last,              # before the first step
              f"write them in passes of at most {MAX_RUN_FRAMES:,} frames into the same "
              f"folder, each going on from the last snapshot there (crowd snapshot "
              f"--frames {min(first, end)}-{end}, then --frames {end + 1}-{end + MAX_RUN_FRAMES}, "
              "and so on)")
    start = crowd.config.start_frame              # a new crowd is there already
    wanted = {f for f in range(first - 1, last + 1, every) if f > start} | {last}
    written = []

    def keep(crowd):                                # a FrameDriver's consumer
        if crowd.frame in wanted:
            written.append(folder.save(crowd))
    keep(crowd)
    FrameDriver(crowd, consumers=[keep]).run(last, progress)
    return written


class ShotSnapshots:
    """An export's use of a snapshot folder: the crowd starts from the latest snapshot
    of it there before the shot's first frame (:attr:`started_from`, None when there
    is none), and leaves one at the shot's last frame for the next chunk: taken by
    :meth:`recorded` once the shot is simulated, written by :meth:`keep` once the
    export succeeded."""

    def __init__(self, path, crowd, first: int):
        self.folder = SnapshotFolder(path, create=True)
        self.crowd = crowd
        self.started_from = self.folder.start(crowd, first)
        self._snap = None

    def recorded(self):
        self._snap = self.crowd.snapshot()

    def keep(self) -> str:
        path = self.folder.file(self.crowd, self._snap.frame)
        self._snap.save(path)
        return path
