"""A shot's chunked export in one process: where its crowd comes from
(:class:`ShotSource`), its chunks (:func:`chunk_ranges`, beside the output in
:func:`chunk_folder`) and the two steps a process runs for it: the snapshot pass
(:func:`write_shot_snapshots`, ``crowd snapshot``) and one chunk's export
(:func:`export_chunk`, ``crowd export``). What a Dask worker runs too (:mod:`.tasks`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from ..core.base.errors import CrowdError
from ..core.variety.repetition import RepetitionSettings

__all__ = ["ShotSource", "chunk_ranges", "chunk_folder", "chunk_path", "write_shot_snapshots",
           "export_chunk"]


@dataclass(frozen=True)
class ShotSource:
    """Where a shot's crowd comes from and how it is exported: a configuration file
    (``config``) or a .blend (``blend``, its ``scene``, ``trust_scripts``; neither: the
    .blend open in Blender), with the export's ``agents``, ``layout`` and ``substeps``
    (as ``crowd export``). ``trust_scripts`` is passed to each of the shot's tasks and
    holds for that task only: a worker that ran a trusted shot trusts nothing after it.
    A .blend whose crowd script would not run stops the shot (ScriptNotTrusted) unless
    ``ignore_scripts``: then every task leaves the script out. ``strict``: a .blend whose
    bake report has warnings stops the shot (``--strict``, BakeWarnings) before
    anything is written."""

    config: str | None = None
    blend: str | None = None
    scene: str | None = None
    trust_scripts: bool = False
    agents: int | None = None
    layout: str = "instanced"
    substeps: int = 1
    ignore_scripts: bool = False
    strict: bool = False

    def __post_init__(self):
        if self.config is not None and self.blend is not None:
            raise CrowdError("a shot comes from one --config or one --blend, not both")
        if self.trust_scripts and self.ignore_scripts:
            raise CrowdError("a shot trusts its crowd script or ignores it, not both")


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


def write_shot_snapshots(source: ShotSource, folder, frames, every, progress=None,
                         on_bake=None) -> list:
    """Snapshots of ``source``'s crowd before each ``every``-frame chunk of ``frames``
    into ``folder`` (created if missing); returns the files. What ``crowd snapshot``
    runs, and a worker for a shot's snapshot pass. ``frames`` None: a .blend's scene
    range (a configuration needs them); ``on_bake(done, total, message)``: the .blend's
    bake steps."""
    if source.config is not None:
        from ..core.authoring.config_io import load_config
        from ..core.shots.crowd import Crowd
        from ..core.shots.snapshot_store import SnapshotFolder, write_snapshots
        if frames is None:
            raise CrowdError("--frames FIRST-LAST is required with --config (a .blend "
                             "gives its scene's frame range)")
        folder = SnapshotFolder(folder, create=True)
        crowd = Crowd(load_config(source.config), skinning="gpu", substeps=source.substeps)
        return write_snapshots(crowd, folder, *frames, every, progress)
    from ..blender.cli_commands import snapshot_blend
    return snapshot_blend(folder, frames, every=every, blend=source.blend,
                          scene=source.scene, substeps=source.substeps,
                          trust_scripts=source.trust_scripts,
                          ignore_scripts=source.ignore_scripts, progress=progress,
                          on_bake=on_bake, strict=source.strict)[1]


def export_chunk(source: ShotSource, frames, out, snapshots=None, progress=None,
                 on_bake=None, repetition=RepetitionSettings()):
    """Export ``frames`` of ``source``'s shot to ``out`` exactly as ``crowd export``
    does, starting from the latest snapshot in ``snapshots`` before the first frame
    (and leaving one at the last). Returns ``(config, ExportResult)``: the crowd's
    configuration and :class:`~crowd_addon.usd.export.ExportResult`. What ``crowd
    export`` runs, and a worker for each chunk. ``frames``
    None: a .blend's scene range (a configuration needs them); ``on_bake(done, total,
    message)``: the .blend's bake steps; ``repetition``: the repetition metric's
    settings (None: not measured)."""
    if source.config is not None:
        import dataclasses

        from ..core.authoring.config_io import load_config
        from ..core.shots.crowd import Crowd
        from ..core.base.files import folders_made
        from ..core.shots.recorder import record
        from ..core.shots.snapshot_store import ShotSnapshots
        from ..gpu.preview_render import writable_dir
        from ..usd import check_export, export_crowd
        if frames is None:
            raise CrowdError("--frames FIRST-LAST is required with --config (a .blend "
                             "gives its scene's frame range)")
        config = load_config(source.config)
        crowd = Crowd(config, skinning="gpu",          # checks the agents' references
                      substeps=source.substeps)
        folder = writable_dir(os.path.dirname(os.path.abspath(out)))
        with folders_made(folder):                      # gone again if the export fails
            check_export(config, out, source.agents, source.layout)    # before simulating
            snaps = ShotSnapshots(snapshots, crowd, frames[0]) if snapshots else None
            shot = record(crowd, *frames, progress=progress)
            if snaps is not None:
                snaps.recorded()
            result = export_crowd(shot, out, agents=source.agents, progress=progress,
                                  layout=source.layout, repetition=repetition)
            if snaps is not None:
                result = dataclasses.replace(result, started_from=snaps.started_from,
                                             snapshot=snaps.keep())
        return config, result
    from ..blender.cli_commands import export_blend
    return export_blend(out, frames, blend=source.blend, scene=source.scene,
                        agents=source.agents, layout=source.layout,
                        substeps=source.substeps, snapshots=snapshots,
                        trust_scripts=source.trust_scripts,
                        ignore_scripts=source.ignore_scripts, progress=progress,
                        on_bake=on_bake, repetition=repetition, strict=source.strict)
