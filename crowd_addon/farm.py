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

:func:`farm_export` (``crowd export --workers N``) runs the three as tasks of a Dask
cluster: a ``LocalCluster`` of ``workers`` processes by default, or an existing
scheduler. :func:`farm_export_shots` (``crowd farm SHOTS_JSON``, :func:`load_shot_list`)
runs many shots' tasks on one cluster at once. Each snapshot pass and chunk is a task
retried once, the chunks wait for their shot's snapshots and the stitch for its chunks;
progress from every worker shows as one ``chunks done/total`` count; a chunk that fails
twice is reported by name with its error, and then nothing is stitched, so a stage
already at the output is left as it was: the chunks exported again write new layer
versions and keep the ones that stage reads (usd/references.py). The report says
whether it is so: it compares the files the stage read before the run with what is
there after it. Every attempt is logged in
``<stem>.chunks/attempts.log`` (time, chunk, worker, outcome; a failure with its
traceback). A cluster that does not start (workers killed as they start: "Nanny failed
to start") or fails while the shots run is a CrowdError naming it, its traceback in
every shot's attempts log; Dask's own log lines go there too, never to the terminal.
Dask is the optional ``farm`` extra (``pip install .[farm]``); it is imported only
here, only when a cluster is used.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import re
import socket
import sys
import time
import traceback
from dataclasses import dataclass, field

from .core.base.errors import CrowdError, ScriptNotTrusted
from .core.variety.repetition import RepetitionSettings

__all__ = ["ShotSource", "FarmShot", "chunk_ranges", "chunk_folder", "write_shot_snapshots",
           "export_chunk", "farm_export", "farm_export_shots", "load_shot_list",
           "FarmResult", "summary"]


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


def _chunk_path(out, k, frames) -> str:
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
        from .core.authoring.config_io import load_config
        from .core.shots.crowd import Crowd
        from .core.shots.snapshot import SnapshotFolder, write_snapshots
        if frames is None:
            raise CrowdError("--frames FIRST-LAST is required with --config (a .blend "
                             "gives its scene's frame range)")
        folder = SnapshotFolder(folder, create=True)
        crowd = Crowd(load_config(source.config), skinning="gpu", substeps=source.substeps)
        return write_snapshots(crowd, folder, *frames, every, progress)
    from .blender.cli_commands import snapshot_blend
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

        from .core.authoring.config_io import load_config
        from .core.shots.crowd import Crowd
        from .core.base.files import folders_made
        from .core.shots.recorder import record
        from .core.shots.snapshot import ShotSnapshots
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
                                  layout=source.layout, repetition=repetition)
            if snaps is not None:
                result = dataclasses.replace(result, started_from=snaps.started_from,
                                             snapshot=snaps.keep())
        return config, result
    from .blender.cli_commands import export_blend
    return export_blend(out, frames, blend=source.blend, scene=source.scene,
                        agents=source.agents, layout=source.layout,
                        substeps=source.substeps, snapshots=snapshots,
                        trust_scripts=source.trust_scripts,
                        ignore_scripts=source.ignore_scripts, progress=progress,
                        on_bake=on_bake, repetition=repetition, strict=source.strict)


def _run_chunk(source, frames, out, snapshots, name, log, _after=None):
    """A worker's task: :func:`export_chunk`, each attempt logged in ``log``
    (``_after``: the snapshot pass's result, which Dask passes once it is done)."""
    _without_blender_scripts()
    t = time.perf_counter()
    where = _where()
    try:
        os.makedirs(os.path.dirname(out), exist_ok=True)
        _, result = export_chunk(source, frames, out, snapshots)
    except BaseException as e:
        _log(log, f"{name}: failed on {where} after {time.perf_counter() - t:.1f} s: "
                  f"{type(e).__name__}: {e}", e)
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


def _log(path, line, error=None):
    """Append ``line`` to the attempts log ``path``, with ``error``'s traceback below it
    (indented): the log, not the terminal, is where a failure's traceback goes."""
    if error is not None:
        trace = "".join(traceback.format_exception(error)).rstrip("\n")
        line += "\n" + "\n".join("    " + t for t in trace.splitlines())
    with open(path, "a", encoding="utf-8") as f:
        f.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {line}\n")


#: the level of Dask's own log lines on the terminal (its workers' included): none, as
#: a failure's traceback goes to the attempts log and its error to the command's line
_QUIET = logging.CRITICAL + 1


class _AttemptsLog(logging.Handler):
    """Dask's log records in this process (warnings and errors: a worker lost, a
    connection dropped) written to every shot's attempts log instead of the terminal."""

    def __init__(self, logs):
        super().__init__(logging.WARNING)
        self.logs = logs

    def emit(self, record):
        try:
            line = f"dask: {record.name}: {record.levelname}: {record.getMessage()}"
            for log in self.logs:
                _log(log, line, record.exc_info[1] if record.exc_info else None)
        except Exception:  # noqa: BLE001 - logging never raises
            self.handleError(record)


@contextlib.contextmanager
def _dask_logs_to(logs):
    """While the cluster runs: Dask's log records go to the shots' attempts ``logs``
    (folders made), none to the terminal."""
    for log in logs:
        os.makedirs(os.path.dirname(log), exist_ok=True)
    dask_log = logging.getLogger("distributed")
    streams = [h for h in dask_log.handlers if isinstance(h, logging.StreamHandler)
               and not isinstance(h, logging.FileHandler)]
    levels = [h.level for h in streams]
    handler = _AttemptsLog(logs)
    for h in streams:
        h.setLevel(_QUIET)
    dask_log.addHandler(handler)
    try:
        yield
    finally:
        dask_log.removeHandler(handler)
        for h, level in zip(streams, levels):
            h.setLevel(level)


def _cluster_failed(logs, what, error) -> CrowdError:
    """``error`` of the cluster itself (not of one shot's task), logged with its
    traceback in every shot's attempts log; the CrowdError that names it."""
    for log in logs:
        _log(log, f"cluster: {what}: {type(error).__name__}: {error}", error)
    more = " (and every shot's)" if len(logs) > 1 else ""
    return CrowdError(f"{what}: {type(error).__name__}: {error}; nothing was exported "
                      f"(Dask's traceback is in {logs[0]}{more})")


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


@dataclass(frozen=True)
class FarmShot:
    """One shot of a farm run: its :class:`ShotSource`, the main layer ``out``, its
    ``frames`` (first, last) and ``chunk_frames`` (None: one chunk per worker)."""

    source: ShotSource
    out: str
    frames: tuple
    chunk_frames: int | None = None


def farm_export(source: ShotSource, out, frames, workers: int = 2, scheduler=None,
                chunk_frames: int | None = None, progress=None) -> FarmResult:
    """Export ``frames`` of ``source``'s shot to ``out`` in chunks on a Dask cluster
    and stitch them (the module docstring; :func:`farm_export_shots` for one shot).
    Raises CrowdError naming what failed."""
    (result,) = farm_export_shots([FarmShot(source, out, frames, chunk_frames)], workers,
                                  scheduler, progress)
    if isinstance(result, CrowdError):
        raise result
    return result


def farm_export_shots(shots, workers: int = 2, scheduler=None, progress=None) -> list:
    """Export every :class:`FarmShot` in chunks on one Dask cluster: per shot a snapshot
    task, then its chunk tasks (each retried once), then a stitch task, all on the
    workers, every shot's tasks at once. ``chunk_frames`` defaults to one chunk per
    worker: every chunk's stream layers repeat the M - 1 history frames before it, so
    fewer, longer chunks write less. ``scheduler``: the address of a running Dask
    scheduler (``tcp://HOST:PORT``); default a ``LocalCluster`` of ``workers``
    single-threaded processes, closed at the end. ``progress("chunks", done, total)``
    over every shot's chunks. Returns per shot a :class:`FarmResult`, or a CrowdError
    naming what failed (its snapshot pass, each chunk that failed twice, or its
    stitch); a failed shot writes no stage, so one already at its output is kept."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise CrowdError(f"--workers must be at least 1, got {workers!r}")
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise CrowdError("--workers needs Dask: pip install 'crowd_addon[farm]' (dask "
                         "and distributed)") from None
    t0 = time.perf_counter()
    logs = [os.path.join(chunk_folder(shot.out), "attempts.log") for shot in shots]
    with _dask_logs_to(logs):
        cluster = None
        if scheduler:
            try:
                client = Client(scheduler, timeout=30)
            except Exception as e:  # noqa: BLE001 - OSError, a timeout, a bad address
                raise CrowdError(f"--scheduler {scheduler}: cannot connect: "
                                 f"{type(e).__name__}: {e}") from None
        else:
            try:
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, dashboard_address=":0",  # any port
                                       silence_logs=_QUIET)
                client = Client(cluster)
            except Exception as e:  # noqa: BLE001 - e.g. "Nanny failed to start"
                if cluster is not None:
                    cluster.close()
                _forget_closed_servers()
                raise _cluster_failed(logs, f"the local Dask cluster of {workers} worker"
                                      f"{'s' if workers > 1 else ''} did not start", e) \
                    from None
        return _run_shots(client, cluster, shots, workers, progress, logs, t0)


def _run_shots(client, cluster, shots, workers, progress, logs, t0) -> list:
    """:func:`farm_export_shots` once the cluster is up (closed at the end)."""
    from dask.distributed import as_completed
    try:
        plans = [_submit(client, shot, workers, k) for k, shot in enumerate(shots)]
        chunk_futures = [f for p in plans for f in p["chunks"]]
        done = 0
        for _ in as_completed(chunk_futures):
            done += 1
            if progress is not None:
                progress("chunks", done, len(chunk_futures))
        results = [_collect(p, t0) for p in plans]
    except CrowdError:
        raise
    except Exception as e:  # noqa: BLE001 - the cluster failed (a shot's task is named)
        raise _cluster_failed(logs, "the Dask cluster failed while the shots ran", e) \
            from None
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
        _forget_closed_servers()
    return results


def _forget_closed_servers():
    """Let the schedulers this process started and closed go. Dask memoises, per
    bound method, whether a handler takes a comm (``distributed.core._expects_comm``,
    a cache without a bound), which keeps every scheduler ever started alive with its
    tasks: farm exports one after another in one process (a Blender session) grew
    without end. Clearing the memo costs Dask one signature check per handler. Each
    scheduler's scratch folder, gone once it closed, also leaves an import cache entry
    behind."""
    try:
        from distributed import core
        core._expects_comm.cache_clear()
    except (ImportError, AttributeError):    # another Dask: nothing of it to clear
        pass
    for path in [p for p in sys.path_importer_cache if "dask-scratch-space" in p]:
        if not os.path.isdir(path):
            sys.path_importer_cache.pop(path, None)


def _submit(client, shot, workers, k) -> dict:
    """Submit one shot's tasks: snapshots, chunks (after the snapshots), stitch (after
    the chunks)."""
    first, last = int(shot.frames[0]), int(shot.frames[1])
    size = shot.chunk_frames or max(1, math.ceil((last - first + 1) / workers))
    ranges = chunk_ranges(first, last, size)
    folder = chunk_folder(shot.out)
    snaps_dir = os.path.join(folder, "snapshots")
    log = os.path.join(folder, "attempts.log")
    os.makedirs(folder, exist_ok=True)
    before = _stage_state(shot.out)          # before any task can touch a file of it
    tag = f"{os.getpid()}-{time.time_ns()}-{k}"
    snaps = client.submit(_run_snapshots, shot.source, snaps_dir, (first, last), size, log,
                          key=f"crowd-snapshots-{tag}", retries=1, pure=False)
    names = [f"chunk {j} (frames {a}-{b})" for j, (a, b) in enumerate(ranges)]
    chunks = [client.submit(_run_chunk, shot.source, (a, b), _chunk_path(shot.out, j, (a, b)),
                            snaps_dir, names[j], log, snaps, key=f"crowd-chunk-{tag}-{j}",
                            retries=1, pure=False)
              for j, (a, b) in enumerate(ranges)]
    stitched = client.submit(_run_stitch, shot.out, chunks, log, key=f"crowd-stitch-{tag}",
                             pure=False)
    return {"shot": shot, "names": names, "snapshots": snaps, "chunks": chunks,
            "stitch": stitched, "before": before}


def _collect(plan, t0):
    """A shot's FarmResult, or a CrowdError naming what failed."""
    out = plan["shot"].out
    where = f"{out}: "
    if plan["snapshots"].status == "error":
        if isinstance(plan["snapshots"].exception(), ScriptNotTrusted):
            return ScriptNotTrusted(where + str(plan["snapshots"].exception()))
        return CrowdError(where + f"the snapshot pass failed twice: "
                                  f"{_error(plan['snapshots'])}; nothing was exported")
    failed = [f"{name} failed twice: {_error(f)}"
              for name, f in zip(plan["names"], plan["chunks"]) if f.status == "error"]
    attempts = f"every attempt is in {os.path.join(chunk_folder(out), 'attempts.log')}"
    if failed:
        whole, state = _as_it_was(out, plan["before"])
        return CrowdError(where + "; ".join(failed) + (
            f"; nothing was stitched ({state}; {attempts})" if whole else
            f"; nothing was stitched, but {state} ({attempts})"))
    try:
        stitched, stitch_s = plan["stitch"].result()
    except Exception as e:  # noqa: BLE001 - reported with its shot
        whole, state = _as_it_was(out, plan["before"])
        return CrowdError(where + f"the stitch failed: {type(e).__name__}: {e}; "
                          + (state if whole else f"and {state}"))
    files, snap_s = plan["snapshots"].result()
    chunks = [f.result() for f in plan["chunks"]]
    return FarmResult(stitched, chunks, files, {
        "snapshots": snap_s, "chunks": max(c["seconds"]["total"] for c in chunks),
        "stitch": stitch_s, "total": time.perf_counter() - t0})


def _stage_state(out):
    """The files the stage at ``out`` reads (itself, and every layer, clip and texture
    it names, transitively), each with its size and modification time (None: missing);
    None when there is no stage at ``out``. A failed run compares this with what is
    there after it (:func:`_as_it_was`)."""
    if not os.path.isfile(out):
        return None
    from .usd.references import referenced_files
    files = {os.path.normpath(os.path.abspath(out))} | referenced_files([out])
    return {f: _stat(f) for f in sorted(files)}


def _stat(path):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


def _as_it_was(out, before) -> tuple:
    """``(whole, words)``: whether the stage at ``out`` is as it was before a run that
    stitched nothing (every file it read still there, unchanged), and the words that
    say so, or what is gone or changed."""
    if before is None:
        if os.path.lexists(out):
            return False, f"a stage appeared at {out} during the run (none was there)"
        return True, f"there was no stage at {out}, and there is none"
    now = {f: _stat(f) for f in before}
    present = [f for f, st in before.items() if st is not None]
    gone = [f for f in present if now[f] is None]
    changed = [f for f in present if now[f] is not None and now[f] != before[f]]
    base = os.path.dirname(os.path.abspath(out))

    def names(files):
        shown = ", ".join(os.path.relpath(f, base) for f in files[:3])
        return shown + (f" and {len(files) - 3} more" if len(files) > 3 else "")
    if gone or changed:
        what = "; ".join(x for x in (
            f"{len(gone)} gone ({names(gone)})" if gone else "",
            f"{len(changed)} changed ({names(changed)})" if changed else "") if x)
        return False, (f"{out} is not as it was: of the {len(present)} files it read, "
                       f"{what}")
    words = f"{out} is as it was, with all {len(present)} files it reads in place"
    missing = [f for f, st in before.items() if st is None]
    if missing:
        words = (f"{out} is as it was, with {len(present)} files it reads in place and "
                 f"{len(missing)} already missing before this run ({names(missing)})")
    return True, words


def _run_snapshots(source, folder, frames, every, log):
    """A worker's task: the shot's snapshot pass; returns (files, seconds)."""
    _without_blender_scripts()
    t = time.perf_counter()
    try:
        files = write_shot_snapshots(source, folder, frames, every)
    except BaseException as e:
        _log(log, f"snapshots: failed on {_where()}: {type(e).__name__}: {e}", e)
        raise
    _log(log, f"snapshots: done on {_where()} in {time.perf_counter() - t:.1f} s")
    return files, time.perf_counter() - t


def _run_stitch(out, chunks, log):
    """A worker's task: the chunks (their summaries) stitched; returns (StitchResult,
    seconds)."""
    from .usd.stitch import stitch
    t = time.perf_counter()
    try:
        result = stitch([c["path"] for c in chunks], out)
    except BaseException as e:
        _log(log, f"stitch: failed on {_where()}: {type(e).__name__}: {e}", e)
        raise
    _log(log, f"stitch: done on {_where()} in {time.perf_counter() - t:.1f} s")
    return result, time.perf_counter() - t


def _where() -> str:
    return f"{socket.gethostname()} pid {os.getpid()}"


def _error(future) -> str:
    e = future.exception()
    return f"{type(e).__name__}: {e}"


#: what a shot of a shot list may say, with its JSON type
_SHOT_KEYS = {"config": str, "blend": str, "scene": str, "trust_scripts": bool,
              "ignore_scripts": bool, "strict": bool, "out": str,
              "frames": str, "agents": int, "layout": str, "substeps": int,
              "chunk_frames": int}


def load_shot_list(path) -> list:
    """The :class:`FarmShot` list of a shot list file (docs/snapshots.md): JSON
    ``{"shots": [{"config" | "blend": ..., "frames": "FIRST-LAST", "out": ..., ...}]}``,
    paths relative to the file's folder. Every problem is a CrowdError naming the
    file, the shot and the key."""
    from .cli_args import frame_range
    from .core.authoring.config import MAX_SUBSTEPS, USD_LAYOUTS
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise CrowdError(f"{path}: no such shot list") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise CrowdError(f"{path}: not a JSON shot list: {e}") from None
    shots = data.get("shots") if isinstance(data, dict) else None
    if not isinstance(shots, list) or not shots:
        raise CrowdError(f'{path}: needs {{"shots": [...]}} with at least one shot')
    base = os.path.dirname(os.path.abspath(path))
    out, outs = [], set()
    for i, shot in enumerate(shots):
        where = f"{path}: shot {i}"
        if not isinstance(shot, dict):
            raise CrowdError(f"{where}: must be an object")
        for key, value in shot.items():
            kind = _SHOT_KEYS.get(key)
            if kind is None:
                raise CrowdError(f"{where}: unknown key {key!r} (known: {sorted(_SHOT_KEYS)})")
            if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
                raise CrowdError(f"{where}: {key!r} must be a {kind.__name__}, got {value!r}")
        for key in ("out", "frames"):
            if key not in shot:
                raise CrowdError(f"{where}: {key!r} is required")
        if ("config" in shot) == ("blend" in shot):
            raise CrowdError(f"{where}: give one of 'config' and 'blend'")
        try:
            frames = frame_range(shot["frames"])
        except Exception as e:  # noqa: BLE001 - argparse's type error, named here
            raise CrowdError(f"{where}: 'frames': {e}") from None
        if shot.get("trust_scripts") and shot.get("ignore_scripts"):
            raise CrowdError(f"{where}: 'trust_scripts' and 'ignore_scripts' exclude each "
                             "other")
        if shot.get("layout", "instanced") not in USD_LAYOUTS:
            raise CrowdError(f"{where}: 'layout' must be one of {list(USD_LAYOUTS)}")
        if not 1 <= shot.get("substeps", 1) <= MAX_SUBSTEPS:
            raise CrowdError(f"{where}: 'substeps' must be 1..{MAX_SUBSTEPS}")
        for key in ("agents", "chunk_frames"):
            if key in shot and shot[key] < 1:
                raise CrowdError(f"{where}: {key!r} must be at least 1")
        target = os.path.normpath(os.path.join(base, shot["out"]))
        if target in outs:
            raise CrowdError(f"{where}: 'out' {shot['out']!r} is another shot's output too")
        outs.add(target)

        def at(key):
            return os.path.normpath(os.path.join(base, shot[key])) if key in shot else None
        source = ShotSource(config=at("config"), blend=at("blend"), scene=shot.get("scene"),
                            trust_scripts=shot.get("trust_scripts", False),
                            ignore_scripts=shot.get("ignore_scripts", False),
                            agents=shot.get("agents"), layout=shot.get("layout", "instanced"),
                            substeps=shot.get("substeps", 1),
                            strict=shot.get("strict", False))
        out.append(FarmShot(source, target, frames, shot.get("chunk_frames")))
    return out


def summary(result: FarmResult) -> dict:
    """The stitched stage's summary, the chunks and the seconds (JSON types)."""
    import dataclasses
    s = result.stitch
    return {**dataclasses.asdict(s), "bytes": s.bytes, "chunk_exports": result.chunks,
            "snapshots": result.snapshots,
            "seconds": {k: round(v, 3) for k, v in result.seconds.items()}}
