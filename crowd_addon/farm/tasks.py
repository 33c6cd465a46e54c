"""The farm's tasks as a Dask worker runs them: a shot's snapshot pass, one chunk, the
stitch (:func:`run_snapshots`, :func:`run_chunk`, :func:`run_stitch`), each attempt
written to the shot's attempts log (:func:`log_line`: time, worker, outcome; a failure
with its traceback).
"""

from __future__ import annotations

import os
import re
import socket
import sys
import time
import traceback

from .chunks import export_chunk, write_shot_snapshots

__all__ = ["run_snapshots", "run_chunk", "run_stitch", "log_line"]


def run_snapshots(source, folder, frames, every, log):
    """A worker's task: the shot's snapshot pass; returns (files, seconds, CPU
    seconds of the worker's process)."""
    _without_blender_scripts()
    t, cpu = time.perf_counter(), time.process_time()
    try:
        files = write_shot_snapshots(source, folder, frames, every)
    except BaseException as e:
        log_line(log, f"snapshots: failed on {_where()}: {type(e).__name__}: {e}", e)
        raise
    log_line(log, f"snapshots: done on {_where()} in {time.perf_counter() - t:.1f} s")
    return files, time.perf_counter() - t, time.process_time() - cpu


def run_chunk(source, frames, out, snapshots, name, log, _after=None, animation_only=False):
    """A worker's task: :func:`export_chunk`, each attempt logged in ``log``
    (``_after``: the snapshot pass's result, which Dask passes once it is done;
    ``animation_only``: every chunk but the shot's first); its summary's ``cpu`` is the
    CPU seconds of the worker's process."""
    _without_blender_scripts()
    t, cpu = time.perf_counter(), time.process_time()
    where = _where()
    try:
        os.makedirs(os.path.dirname(out), exist_ok=True)
        _, result = export_chunk(source, frames, out, snapshots,
                                 animation_only=animation_only)
    except BaseException as e:
        log_line(log, f"{name}: failed on {where} after {time.perf_counter() - t:.1f} s: "
                  f"{type(e).__name__}: {e}", e)
        raise
    log_line(log, f"{name}: done on {where} in {time.perf_counter() - t:.1f} s")
    return {"path": result.path, "frames": list(result.frames),
            "started_from": result.started_from, "seconds": result.seconds,
            "bytes": result.bytes, "events": result.events, "cpu": time.process_time() - cpu}


def run_stitch(out, chunks, log):
    """A worker's task: the chunks (their summaries) stitched; returns (StitchResult,
    seconds, CPU seconds of the worker's process)."""
    from ..usd.stitch import stitch
    t, cpu = time.perf_counter(), time.process_time()
    try:
        result = stitch([c["path"] for c in chunks], out)
    except BaseException as e:
        log_line(log, f"stitch: failed on {_where()}: {type(e).__name__}: {e}", e)
        raise
    log_line(log, f"stitch: done on {_where()} in {time.perf_counter() - t:.1f} s")
    return result, time.perf_counter() - t, time.process_time() - cpu


_BLENDER_SCRIPTS = re.compile(r"[/\\]bpy[/\\]\d+\.\d+[/\\]scripts([/\\]|$)")


def _without_blender_scripts():
    """A worker spawned by a process that had imported the bpy module inherits its
    ``sys.path``, which then holds Blender's script folders, where ``import bpy``
    finds Blender's internal ``bpy`` package instead of the module. Until bpy is
    imported here, those folders go (the module puts them back when imported)."""
    if "bpy" not in sys.modules:
        sys.path[:] = [p for p in sys.path if not _BLENDER_SCRIPTS.search(p)]


def log_line(path, line, error=None):
    """Append ``line`` to the attempts log ``path``, with ``error``'s traceback below it
    (indented): the log, not the terminal, is where a failure's traceback goes."""
    if error is not None:
        trace = "".join(traceback.format_exception(error)).rstrip("\n")
        line += "\n" + "\n".join("    " + t for t in trace.splitlines())
    with open(path, "a", encoding="utf-8") as f:
        f.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {line}\n")


def _where() -> str:
    return f"{socket.gethostname()} pid {os.getpid()}"
