"""The Dask cluster of a farm run: :func:`farm_export_shots` (``crowd farm``) and
:func:`farm_export` (``crowd export --workers N``) start or join one, submit every shot's
tasks (:mod:`.tasks`), count the chunks done and collect each shot's
:class:`FarmResult` or the CrowdError naming what failed; whether a failed run left the
stage at its output as it was; Dask's own log lines routed to the attempts logs;
:func:`summary` (JSON types).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import time
from dataclasses import dataclass, field

from ..core.base.errors import CrowdError, ScriptNotTrusted
from ..shot_source import ShotSource
from ..usd.files import remove_stale_temporaries
from .chunks import chunk_folder, chunk_path, chunk_ranges, chunked_output
from .tasks import log_line, run_chunk, run_snapshots, run_stitch

__all__ = ["FarmShot", "FarmResult", "farm_export", "farm_export_shots", "summary"]


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
                log_line(log, line, record.exc_info[1] if record.exc_info else None)
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
        log_line(log, f"cluster: {what}: {type(error).__name__}: {error}", error)
    more = " (and every shot's)" if len(logs) > 1 else ""
    return CrowdError(f"{what}: {type(error).__name__}: {error}; nothing was exported "
                      f"(Dask's traceback is in {logs[0]}{more})")


@dataclass(frozen=True)
class FarmResult:
    """A chunked export: the stitched stage (``stitch``, a StitchResult), the chunks'
    summaries (``chunks``: path, frames, started_from, seconds, bytes, events), the
    snapshot pass's files, seconds per step (``snapshots``, ``chunks``, ``stitch``,
    ``total``) and the CPU seconds of the workers' processes per step (``snapshots``,
    ``chunks``: all of them, ``stitch``)."""

    stitch: object
    chunks: list
    snapshots: list
    seconds: dict = field(default_factory=dict)
    cpu: dict = field(default_factory=dict)


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
    and stitch them (the module docstring; :func:`farm_export_shots` for one shot),
    once the shot is checked as ``crowd export`` checks it (:func:`.chunks.chunked_output`:
    nothing is written when it is refused). Raises CrowdError naming what failed."""
    with chunked_output(source, out, frames):
        (result,) = farm_export_shots([FarmShot(source, out, frames, chunk_frames)],
                                      workers, scheduler, progress)
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
    stitch); a failed shot writes no stage, so one already at its output is kept. The
    caller has checked each shot (:func:`.chunks.chunked_output`). Once the cluster is
    closed, what its killed exports left (a worker stopped mid-chunk by Ctrl-C, SIGTERM
    or a lost worker) is removed from every chunk folder and the output's folder."""
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
            cluster.close()         # waits until its worker processes are gone
        _forget_closed_servers()
        _remove_stale_exports(shots, workers)
    return results


def _remove_stale_exports(shots, workers):
    """The hidden temporary folders (usd/files.py) of every chunk's and every stitched
    stage's export in the run whose process is gone: a worker killed mid-export when
    the cluster closed never removed its own."""
    for shot in shots:
        paths = [chunk_path(shot.out, j, frames)
                 for j, frames in enumerate(_chunks(shot, workers)[1])]
        for path in [shot.out, *paths]:
            remove_stale_temporaries(os.path.dirname(path), os.path.basename(path))


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
    size, ranges = _chunks(shot, workers)
    folder = chunk_folder(shot.out)
    snaps_dir = os.path.join(folder, "snapshots")
    log = os.path.join(folder, "attempts.log")
    os.makedirs(folder, exist_ok=True)
    before = _stage_state(shot.out)          # before any task can touch a file of it
    tag = f"{os.getpid()}-{time.time_ns()}-{k}"
    snaps = client.submit(run_snapshots, shot.source, snaps_dir, (first, last), size, log,
                          key=f"crowd-snapshots-{tag}", retries=1, pure=False)
    names = [f"chunk {j} (frames {a}-{b})" for j, (a, b) in enumerate(ranges)]
    chunks = [client.submit(run_chunk, shot.source, (a, b), chunk_path(shot.out, j, (a, b)),
                            snaps_dir, names[j], log, snaps, j > 0,
                            key=f"crowd-chunk-{tag}-{j}", retries=1, pure=False)
              for j, (a, b) in enumerate(ranges)]
    stitched = client.submit(run_stitch, shot.out, chunks, log, key=f"crowd-stitch-{tag}",
                             pure=False)
    return {"shot": shot, "names": names, "snapshots": snaps, "chunks": chunks,
            "stitch": stitched, "before": before}


def _chunks(shot, workers) -> tuple:
    """``(size, [(a, b)])``: a shot's chunk length (``chunk_frames``, or one chunk per
    worker) and its chunks."""
    first, last = int(shot.frames[0]), int(shot.frames[1])
    size = shot.chunk_frames or max(1, math.ceil((last - first + 1) / workers))
    return size, chunk_ranges(first, last, size)


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
        stitched, stitch_s, stitch_cpu = plan["stitch"].result()
    except Exception as e:  # noqa: BLE001 - reported with its shot
        whole, state = _as_it_was(out, plan["before"])
        return CrowdError(where + f"the stitch failed: {type(e).__name__}: {e}; "
                          + (state if whole else f"and {state}"))
    files, snap_s, snap_cpu = plan["snapshots"].result()
    chunks = [f.result() for f in plan["chunks"]]
    return FarmResult(stitched, chunks, files, {
        "snapshots": snap_s, "chunks": max(c["seconds"]["total"] for c in chunks),
        "stitch": stitch_s, "total": time.perf_counter() - t0},
        {"snapshots": snap_cpu, "chunks": sum(c["cpu"] for c in chunks), "stitch": stitch_cpu})


def _error(future) -> str:
    e = future.exception()
    return f"{type(e).__name__}: {e}"


def _stage_state(out):
    """The files the stage at ``out`` reads (itself, and every layer, clip and texture
    it names, transitively), each with its size and modification time (None: missing);
    None when there is no stage at ``out``. A failed run compares this with what is
    there after it (:func:`_as_it_was`)."""
    if not os.path.isfile(out):
        return None
    from ..usd.references import referenced_files
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


def summary(result: FarmResult) -> dict:
    """The stitched stage's summary, the chunks and the seconds (JSON types)."""
    import dataclasses
    s = result.stitch
    return {**dataclasses.asdict(s), "bytes": s.bytes, "chunk_exports": result.chunks,
            "snapshots": result.snapshots,
            "seconds": {k: round(v, 3) for k, v in result.seconds.items()},
            "cpu": {k: round(v, 3) for k, v in result.cpu.items()}}
