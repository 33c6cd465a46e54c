"""One shot exported in one process, whatever it came from: a shot opened by
:meth:`crowd_addon.shot_source.ShotSource.open` (a configuration or a .blend) or by
``blender -c crowd export``. Its crowd is recorded once (from the latest snapshot
before the first frame when a snapshot folder is given, leaving one at the last frame
for the next chunk) and written as UsdSkel; the repetition metric is measured through
the shot's camera. The output folder is made for the export and removed again when it
fails, so a failed export leaves nothing.
"""

from __future__ import annotations

import dataclasses
import os
from contextlib import nullcontext

from ..core.base.files import folders_made, writable_dir
from ..core.shots.recorder import record
from ..core.shots.snapshot_store import ShotSnapshots, SnapshotFolder, write_snapshots
from ..core.variety.repetition import RepetitionSettings
from .export import check_export, export_crowd

__all__ = ["export_shot", "snapshot_shot"]


def export_shot(shot, out, agents=None, layout="instanced", snapshots=None, progress=None,
                repetition=RepetitionSettings(), animation_only=False):
    """Export ``shot`` (``config``, ``frames``, ``crowd()``, ``metric_view()``) to ``out``.
    ``snapshots``: a snapshot folder to start from and leave the last frame in;
    ``progress(stage, done, total)``; ``repetition``: the metric's settings (None: not
    measured); ``animation_only``: a chunk after the shot's first, for a stitch
    (:func:`~.export.export_crowd`). Returns ``(config, ExportResult)``."""
    folder = writable_dir(os.path.dirname(os.path.abspath(out)))
    # the output folder (and a snapshot folder) made here are gone again if it fails
    with folders_made(folder), folders_made(snapshots, "snapshot folder") if snapshots \
            else nullcontext():
        config = shot.config                        # a .blend's bake runs here
        check_export(config, out, agents, layout)   # before simulating
        crowd = shot.crowd()
        snaps = ShotSnapshots(snapshots, crowd, shot.frames[0]) if snapshots else None
        recording = record(crowd, *shot.frames, progress=progress)
        kept = []
        if snaps is not None:
            snaps.recorded()
        camera, settings = shot.metric_view(repetition)
        # the last frame's snapshot is written before the export is put in place: a
        # snapshot that cannot be written fails the export with nothing replaced
        result = export_crowd(recording, out, agents=agents, progress=progress,
                              layout=layout, camera=camera, repetition=settings,
                              animation_only=animation_only,
                              before_commit=None if snaps is None else
                              lambda: kept.append(snaps.keep()))
        if snaps is not None:
            result = dataclasses.replace(result, started_from=snaps.started_from,
                                         snapshot=kept[0])
    return config, result


def snapshot_shot(shot, folder, every: int, progress=None) -> list:
    """Snapshots of ``shot``'s crowd before each ``every``-frame chunk of its frames in
    ``folder`` (created if missing, and removed again when the run fails before it
    wrote any); returns the files written."""
    with folders_made(folder, "snapshot folder"):   # gone again if nothing was written
        folder = SnapshotFolder(folder, create=True)
        return write_snapshots(shot.crowd(), folder, *shot.frames, every, progress)
