"""A shot's chunked export in one process (its crowd from a
:class:`~crowd_addon.shot_source.ShotSource`): its chunks (:func:`chunk_ranges`,
beside the output in :func:`chunk_folder`), the checks before any of it runs
(:func:`chunked_output`) and the two steps a process runs for it: the snapshot pass
(:func:`write_shot_snapshots`, ``crowd snapshot``) and one chunk's export
(:func:`export_chunk`, ``crowd export``). What a Dask worker runs too (:mod:`.tasks`).
"""

from __future__ import annotations

import contextlib
import os

from ..core.base.errors import CrowdError
from ..core.variety.repetition import RepetitionSettings
from ..shot_source import ShotSource

__all__ = ["chunk_ranges", "chunk_folder", "chunk_path", "chunked_output",
           "write_shot_snapshots", "export_chunk"]


def chunk_ranges(first: int, last: int, size: int) -> list:
    """``[(a, b)]`` consecutive chunks of ``size`` frames covering ``first .. last``."""
    if size < 1:
        raise CrowdError(f"chunks must be at least 1 frame long, got {size}")
    return [(a, min(a + size - 1, last)) for a in range(first, last + 1, size)]


def chunk_folder(out) -> str:
    """The folder of ``out``'s chunks and snapshots: ``<stem>.chunks`` beside it."""
    out = os.path.abspath(os.fspath(out))
    return os.path.join(os.path.dirname(out),
                        os.path.splitext(os.path.basename(out))[0] + ".chunks")


def chunk_path(out, k, frames) -> str:
    ext = os.path.splitext(os.fspath(out))[1]
    return os.path.join(chunk_folder(out), f"c{k:04d}_{frames[0]}-{frames[1]}", f"shot{ext}")


@contextlib.contextmanager
def chunked_output(source: ShotSource, out, frames):
    """``out``'s folder, made for the ``with`` block (removed again if it raises and
    nothing else is in it), once what the chunked export of ``frames`` of ``source``'s
    shot to ``out`` would refuse is checked, before any task runs or anything is
    written: all that ``crowd export`` checks first
    (:func:`~crowd_addon.usd.shot_export.checked_output`: the output, the agent count,
    the layout, the meshes, the frames against the crowd's start frame), then that its
    chunk folder can be made. A .blend's configuration is baked by the snapshot pass,
    so only its output and layout are checked here (the rest on the workers). Raises
    CrowdError."""
    from ..core.base.files import writable_dir
    from ..usd.shot_export import checked_output
    shot = source.open(frames) if source.config is not None else None
    with checked_output(out, source.agents, source.layout, shot):
        writable_dir(chunk_folder(out))
        yield


def write_shot_snapshots(source: ShotSource, folder, frames, every, progress=None,
                         on_bake=None) -> list:
    """Snapshots of ``source``'s crowd before each ``every``-frame chunk of ``frames``
    into ``folder`` (created if missing), with a .blend's bake for the chunks
    (:mod:`crowd_addon.blender.bake_cache`); returns the files. What ``crowd snapshot``
    runs, and a worker for a shot's snapshot pass. ``frames`` None: a .blend's scene
    range (a configuration needs them); ``on_bake(done, total, message)``: the .blend's
    bake steps."""
    from ..usd.shot_export import snapshot_shot
    with source.quietly():          # a .blend's bake is kept for the chunks
        return snapshot_shot(source.open(frames, on_bake, keep_bake=folder), folder,
                             every, progress)


def export_chunk(source: ShotSource, frames, out, snapshots=None, progress=None,
                 on_bake=None, repetition=RepetitionSettings(), animation_only=False):
    """Export ``frames`` of ``source``'s shot to ``out`` exactly as ``crowd export``
    does, starting from the latest snapshot in ``snapshots`` before the first frame
    (and leaving one at the last; a .blend's bake kept there is read, not baked
    again). Returns ``(config, ExportResult)``: the crowd's configuration and
    :class:`~crowd_addon.usd.export.ExportResult`. What ``crowd export`` runs, and a
    worker for each chunk. ``frames``
    None: a .blend's scene range (a configuration needs them); ``on_bake(done, total,
    message)``: the .blend's bake steps; ``repetition``: the repetition metric's
    settings (None: not measured); ``animation_only``: a chunk after the shot's first,
    written only for the stitch (no agent prims)."""
    from ..usd.shot_export import export_shot
    with source.quietly():          # a .blend's bake kept by the snapshot pass
        shot = source.open(frames, on_bake, reuse_bake=snapshots)
        return export_shot(shot, out, agents=source.agents, layout=source.layout,
                           snapshots=snapshots, progress=progress, repetition=repetition,
                           animation_only=animation_only)
