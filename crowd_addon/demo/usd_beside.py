"""The demo's USD export in a process of its own, beside the frames it draws
(:class:`UsdExport`): spawned at once with the recording, it writes the whole stage,
then waits for the demo's word to put it in place, so ``stadium.usdc`` changes only
when the whole run succeeds; a demo that fails or is stopped stops it, and a child
whose parent is gone stops by itself.
"""

from __future__ import annotations

import os
import time

from ..core.base.errors import CrowdError

__all__ = ["UsdExport", "usd_summary", "USD_COUNTS"]

#: what the summary keeps of the USD export (``usd_export``): the counts a
#: ``crowd export --blend`` of the saved file reports the same
USD_COUNTS = ("frames", "agents", "shared_agents", "clip_agents", "blend_frames", "moving_agents",
              "offset_animations", "stream_animations", "characters", "files")


def usd_summary(summary: dict, res: dict, layout: str) -> None:
    """What the summary keeps of the committed USD export ``res``."""
    summary.update(usd=res["path"], usd_layout=layout, usd_bytes=res["bytes"],
                   usd_clip_agents=res["clip_agents"], usd_export=res["counts"],
                   repetition=res["repetition"])
    summary["seconds"]["usd_beside"] = round(res["seconds"], 2)


class UsdExport:
    """``export_crowd`` of ``shot`` in a process of its own (spawned: a fork would copy
    Blender's and the GL driver's threads), started at once. It writes everything,
    then waits for the demo's word before it commits (usd/files.py: the renames that
    put a stage in place), so the stage at ``path`` changes only when the whole run
    succeeds:

    - :meth:`written` waits until only the commit is left, or raises the export's
      error as a CrowdError;
    - :meth:`commit` has it commit and returns what the summary keeps;
    - :meth:`stop` ends it (the demo failed or was stopped) and removes what it had
      staged (its hidden temporary folder).

    The child also stops, removing its staging, when its parent is gone (killed
    outright), instead of exporting for nobody."""

    def __init__(self, shot, path, camera, measure, layout):
        import multiprocessing
        self._path = str(path)
        ctx = multiprocessing.get_context("spawn")
        self._recv, send = ctx.Pipe(duplex=False)
        go, self._go = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_export_in_child,
                                 args=(send, go, os.getpid(), shot, str(path), camera,
                                       measure, layout),
                                 name="crowd demo USD export", daemon=True)
        self._proc.start()
        send.close()
        go.close()

    @property
    def running(self) -> bool:
        return self._proc.is_alive() and not self._recv.poll()

    def _next(self, expected: str):
        try:
            kind, value = self._recv.recv()
        except EOFError:
            self._proc.join()
            raise CrowdError(f"the USD export process ended without a result (exit code "
                             f"{self._proc.exitcode})") from None
        if kind == "error":
            self._proc.join(timeout=60)
            raise CrowdError(f"USD export: {value}")
        assert kind == expected, kind
        return value

    def written(self) -> None:
        self._next("written")

    def commit(self) -> dict:
        self._go.send("commit")
        try:
            return self._next("done")
        finally:
            self._proc.join(timeout=60)

    def stop(self):
        from ..usd.files import remove_stale_temporaries
        if self._proc.is_alive():
            self._proc.terminate()
        self._proc.join(timeout=10)
        remove_stale_temporaries(os.path.dirname(self._path) or ".",
                                 os.path.basename(self._path))


def _export_in_child(send, go, parent, shot, path, camera, measure, layout):
    """The child's side of :class:`UsdExport`: ``("written", None)`` down ``send``
    when only the commit is left, then ``("done", summary)`` once ``go`` says
    ``"commit"``; ``("error", message)`` instead when the export fails. Stops (the
    export's staging removed) when ``go`` closes without the word or the parent
    process ``parent`` is gone."""
    import _thread
    import threading

    def tell(*message):
        try:
            send.send(message)
        except OSError:              # the parent is gone: nobody to tell
            pass

    def orphaned():                  # the parent killed outright: stop exporting
        while os.getppid() == parent:
            time.sleep(0.5)
        _thread.interrupt_main()
    threading.Thread(target=orphaned, daemon=True).start()

    def before_commit():
        tell("written", None)
        try:
            word = go.recv()
        except EOFError:
            word = None
        if word != "commit":
            raise CrowdError("the demo did not finish: its stage is not put in place")
    try:
        from ..usd.export import export_crowd
        t = time.perf_counter()
        res = export_crowd(shot, path, camera=camera, repetition=measure, layout=layout,
                           before_commit=before_commit)
        tell("done", {"path": str(res.path), "bytes": int(sum(res.files.values())),
                      "clip_agents": res.clip_agents,
                      "counts": {k: getattr(res, k) for k in USD_COUNTS},
                      "repetition": res.repetition, "seconds": time.perf_counter() - t})
    except Exception as e:  # noqa: BLE001 - the parent names it
        tell("error", f"{type(e).__name__}: {e}" if not isinstance(e, CrowdError) else str(e))
    except KeyboardInterrupt:        # orphaned: the export removed its staging
        pass
    finally:
        send.close()
