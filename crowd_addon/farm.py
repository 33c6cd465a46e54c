"""Chunked exports, one process or a Dask cluster (``crowd export --workers N``).

A shot's export split in chunks runs in three steps, each its own function so a
render-farm queue can run them as plain command lines too (docs/snapshots.md):

1. :func:`write_shot_snapshots` (``crowd snapshot``): one cheap pass of the simulation
   writes the snapshot before each chunk;
2. :func:`export_chunk` (``crowd export --frames A-B --snapshots DIR``), once per
   chunk, anywhere: the crowd built as a single export builds it, started from the
   chunk's snapshot;
3. :func:`crowd_addon.usd.stitch.stitch` (``crowd stitch``): the chunks joined into one
   stage.

:func:`farm_export` runs the three on a Dask cluster: a ``LocalCluster`` of ``workers``
processes by default, or an existing scheduler. Each chunk is a task retried once;
progress from every worker shows as one ``chunks done/total`` count; a chunk that fails
twice is reported by name with its error, and then nothing is stitched, so a stage
already at the output is left as it was. Every attempt is logged in
``<stem>.chunks/attempts.log`` (time, chunk, worker, outcome). Dask is the optional ``farm`` extra
(``pip install .[farm]``); it is imported only here, only when a cluster is used.
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
import sys
import time
from dataclasses import dataclass, field

from .core.errors import CrowdError

__all__ = ["ShotSource", "chunk_ranges", "chunk_folder", "write_shot_snapshots",
           "export_chunk", "farm_export", "FarmResult"]


@dataclass(frozen=True)
class ShotSource:
    """Where a shot's crowd comes from and how it is exported: a configuration file
    (``config``) or a .blend (``blend``, its ``scene``, ``trust_scripts``; neither: the
    .blend open in Blender), with the export's ``agents``, ``layout`` and ``substeps``
    (as ``crowd export``)."""

    config: str | None = None
    blend: str | None = None
    scene: str | None = None
    trust_scripts: bool = False
    agents: int | None = None
    layout: str = "instanced"
    substeps: int = 1

    def __post_init__(self):
        if self.config is not None and self.blend is not None:
            raise CrowdError("a shot comes from one --config or one --blend, not both")


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


def _chunk_path(out, k, frames) -> str:
    ext = os.path.splitext(os.fspath(out))[1]
    return os.path.join(chunk_folder(out), f"c{k:04d}_{frames[0]}-{frames[1]}", f"shot{ext}")


def write_shot_snapshots(source: ShotSource, folder, frames, every, progress=None) -> list:
    """Snapshots of ``source``'s crowd before each ``every``-frame chunk of ``frames``
    into ``folder`` (created if missing); returns the files."""
    if source.config is not None:
        from .core.config_io import load_config
        from .core.crowd import Crowd
        from .core.snapshot import SnapshotFolder, write_snapshots
        crowd = Crowd(load_config(source.config), skinning="gpu", substeps=source.substeps)
        return write_snapshots(crowd, SnapshotFolder(folder, create=True), *frames, every,
                               progress)
    from .blender.cli_commands import snapshot_blend
    return snapshot_blend(folder, frames, every=every, blend=source.blend,
                          scene=source.scene, substeps=source.substeps,
                          trust_scripts=source.trust_scripts, progress=progress)[1]


def export_chunk(source: ShotSource, frames, out, snapshots=None, progress=None,
                 on_bake=None):
    """Export ``frames`` of ``source``'s shot to ``out`` exactly as ``crowd export``
    does, starting from the latest snapshot in ``snapshots`` before the first frame
    (and leaving one at the last). Returns the :class:`~crowd_addon.usd.export.
    ExportResult`. What ``crowd export`` runs, and a worker for each chunk. ``frames``
    None: a .blend's scene range (a configuration needs them); ``on_bake(done, total,
    message)``: the .blend's bake steps."""
    if source.config is not None:
        import dataclasses

        from .core.config_io import load_config
        from .core.crowd import Crowd
        from .core.files import folders_made
        from .core.recorder import record
        from .core.snapshot import ShotSnapshots
        from .gpu.preview_render import writable_dir
        from .usd import check_export, export_crowd
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
                                  layout=source.layout)
            if snaps is not None:
                result = dataclasses.replace(result, started_from=snaps.started_from,
                                             snapshot=snaps.keep())
        return config, result
    from .blender.cli_commands import export_blend
    return export_blend(out, frames, blend=source.blend, scene=source.scene,
                        agents=source.agents, layout=source.layout,
                        substeps=source.substeps, snapshots=snapshots,
                        trust_scripts=source.trust_scripts, progress=progress,
                        on_bake=on_bake)


def _run_chunk(source, frames, out, snapshots, name, log):
    """A worker's task: :func:`export_chunk`, each attempt logged in ``log``."""
    _without_blender_scripts()
    t = time.perf_counter()
    where = f"{socket.gethostname()} pid {os.getpid()}"
    try:
        os.makedirs(os.path.dirname(out), exist_ok=True)
        _, result = export_chunk(source, frames, out, snapshots)
    except BaseException as e:
        _log(log, f"{name}: failed on {where} after {time.perf_counter() - t:.1f} s: "
                  f"{type(e).__name__}: {e}")
        raise
    _log(log, f"{name}: done on {where} in {time.perf_counter() - t:.1f} s")
    return {"path": result.path, "frames": list(result.frames),
            "started_from": result.started_from, "seconds": result.seconds,
            "bytes": result.bytes, "events": result.events}


_BLENDER_SCRIPTS = re.compile(r"[/\\]bpy[/\\]\d+\.\d+[/\\]scripts([/\\]|$)")


def _without_blender_scripts():
    """A worker spawned by a process that had imported the bpy module inherits its
    ``sys.path``, which then holds Blender's script folders, where ``import bpy``
    finds Blender's internal ``bpy`` package instead of the module. Until bpy is
    imported here, those folders go (the module puts them back when imported)."""
    if "bpy" not in sys.modules:
        sys.path[:] = [p for p in sys.path if not _BLENDER_SCRIPTS.search(p)]


def _log(path, line):
    with open(path, "a", encoding="utf-8") as f:
        f.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {line}\n")


@dataclass(frozen=True)
class FarmResult:
    """A chunked export: the stitched stage (``stitch``, a StitchResult), the chunks'
    summaries (``chunks``: path, frames, started_from, seconds, bytes, events), the
    snapshot pass's files, and seconds per step (``snapshots``, ``chunks``,
    ``stitch``, ``total``)."""

    stitch: object
    chunks: list
    snapshots: list
    seconds: dict = field(default_factory=dict)


def farm_export(source: ShotSource, out, frames, workers: int = 2, scheduler=None,
                chunk_frames: int | None = None, progress=None) -> FarmResult:
    """Export ``frames`` of ``source``'s shot to ``out`` in chunks on a Dask cluster
    and stitch them (the module docstring). ``chunk_frames`` defaults to one chunk per
    worker: every chunk's stream layers repeat the M - 1 history frames before it, so
    fewer, longer chunks write less. ``scheduler``: the address of a running Dask
    scheduler (``tcp://HOST:PORT``); default a ``LocalCluster`` of ``workers``
    single-threaded processes, closed at the end. ``progress(stage, done, total)``:
    ``snapshots``, ``chunks`` (one count over every worker) and the stitch's stages."""
    from .usd.stitch import stitch
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise CrowdError(f"--workers must be at least 1, got {workers!r}")
    first, last = int(frames[0]), int(frames[1])
    size = chunk_frames or max(1, math.ceil((last - first + 1) / workers))
    ranges = chunk_ranges(first, last, size)
    folder = chunk_folder(out)
    snaps_dir = os.path.join(folder, "snapshots")
    t0 = time.perf_counter()
    seconds = {}
    snaps = write_shot_snapshots(source, snaps_dir, (first, last), size,
                                 None if progress is None else
                                 (lambda d, n: progress("snapshots", d, n)))
    seconds["snapshots"] = time.perf_counter() - t0
    t = time.perf_counter()
    summaries = _run_on_cluster(source, out, ranges, snaps_dir, workers, scheduler,
                                progress)
    seconds["chunks"] = time.perf_counter() - t
    t = time.perf_counter()
    stitched = stitch([s["path"] for s in summaries], out, progress=progress)
    seconds["stitch"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    return FarmResult(stitched, summaries, snaps, seconds)


def _run_on_cluster(source, out, ranges, snaps_dir, workers, scheduler, progress) -> list:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise CrowdError("--workers needs Dask: pip install 'crowd_addon[farm]' (dask "
                         "and distributed)") from None
    cluster = None
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout=30)
            except OSError as e:
                raise CrowdError(f"--scheduler {scheduler}: cannot connect: {e}") from None
        else:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
            client = Client(cluster)
        try:
            names = [f"chunk {k} (frames {a}-{b})" for k, (a, b) in enumerate(ranges)]
            log = os.path.join(chunk_folder(out), "attempts.log")
            futures = [client.submit(_run_chunk, source, (a, b), _chunk_path(out, k, (a, b)),
                                     snaps_dir, names[k], log, key=f"crowd-chunk-{k}-{a}-{b}-"
                                     f"{os.getpid()}-{time.time_ns()}", retries=1, pure=False)
                       for k, (a, b) in enumerate(ranges)]
            which = {f.key: k for k, f in enumerate(futures)}
            results, failed = [None] * len(ranges), []
            done = 0
            for f in as_completed(futures):
                k = which[f.key]
                if f.status == "error":
                    failed.append(f"{names[k]} failed twice: {_error(f)}")
                else:
                    results[k] = f.result()
                done += 1
                if progress is not None:
                    progress("chunks", done, len(ranges))
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
    if failed:
        raise CrowdError("; ".join(failed) + f"; nothing was stitched ({out} is as it "
                         f"was; every attempt is in "
                         f"{os.path.join(chunk_folder(out), 'attempts.log')})")
    return results


def _error(future) -> str:
    e = future.exception()
    return f"{type(e).__name__}: {e}"


def summary_json(result: FarmResult) -> str:
    """One JSON object: the stitched stage's summary, the chunks and the seconds."""
    import dataclasses
    s = result.stitch
    return json.dumps({**dataclasses.asdict(s), "bytes": s.bytes,
                       "chunk_exports": result.chunks,
                       "snapshots": result.snapshots,
                       "seconds": {k: round(v, 3) for k, v in result.seconds.items()}})
