"""One shot exported in one process, whatever it came from: a shot opened by
:meth:`crowd_addon.shot_source.ShotSource.open` (a configuration or a .blend) or by
``blender -c crowd export``. Its crowd is recorded once (from the latest snapshot
before the first frame when a snapshot folder is given, leaving one at the last frame
for the next chunk) and written as UsdSkel; the repetition metric is measured through
the shot's camera. The output folder is made for the export and removed again when it
fails, so a failed export leaves nothing.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os

from ..core.base.files import folders_made, writable_dir
from ..core.shots.recorder import record
from ..core.shots.snapshot_store import ShotSnapshots, SnapshotFolder, write_snapshots
from ..core.variety.repetition import RepetitionSettings
from .export import check_export, export_crowd

__all__ = ["export_shot", "checked_output", "snapshot_shot"]


def export_shot(shot, out, agents=None, layout="instanced", snapshots=None, progress=None,
                repetition=RepetitionSettings(), animation_only=False):
    """Export ``shot`` (``config``, ``frames``, ``crowd()``, ``metric_view()``) to ``out``.
    ``snapshots``: a snapshot folder to start from and leave the last frame in;
    ``progress(stage, done, total)``; ``repetition``: the metric's settings (None: not
    measured); ``animation_only``: a chunk after the shot's first, for a stitch
    (:func:`~.export.export_crowd`). Returns ``(config, ExportResult)``."""
    # the output folder (and a snapshot folder) made here are gone again if it fails
    with checked_output(out, agents, layout, shot) as config, \
            folders_made(snapshots, "snapshot folder") if snapshots else contextlib.nullcontext():
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


@contextlib.contextmanager
def checked_output(out, agents=None, layout="instanced", shot=None):
    """``out``'s folder, made for the ``with`` block (the folders made are removed
    again when the block raises), once what an export of ``shot`` to ``out`` would
    refuse is checked, before anything is simulated: the folder can be made and
    written (:func:`~crowd_addon.core.base.files.writable_dir`), then
    :func:`~.export.check_export` (the output, the agent count, the layout, the
    meshes, the frames against the crowd's start frame). Yields ``shot``'s
    configuration (a .blend's is baked here). ``shot`` None: the output and the
    layout only (a farm's .blend shot, baked on a worker)."""
    folder = writable_dir(os.path.dirname(os.path.abspath(out)))
    with folders_made(folder):
        config = None if shot is None else shot.config
        check_export(config, out, agents, layout, None if shot is None else shot.frames)
        yield config


def snapshot_shot(shot, folder, every: int, progress=None) -> list:
    """Snapshots of ``shot``'s crowd before each ``every``-frame chunk of its frames in
    ``folder`` (created if missing, and removed again when the run fails before it
    wrote any); returns the files written."""
    with folders_made(folder, "snapshot folder"):   # gone again if nothing was written
        folder = SnapshotFolder(folder, create=True)
        return write_snapshots(shot.crowd(), folder, *shot.frames, every, progress)
