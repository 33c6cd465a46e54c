"""Headless command line: ``crowd <command> ...`` or ``python -m crowd_addon <command> ...``.

Commands: ``budget`` (the paper's GPU memory model and a proposed stream count and
max offset, docs/performance_budget.md), ``export`` (a crowd shot over a frame range
as UsdSkel, docs/usd_export.md), ``snapshot`` (exact snapshots of a shot for chunked
exports), ``stitch`` (chunk exports joined into one stage) and ``farm`` (a shot list
exported in chunks on one Dask cluster; all three docs/snapshots.md), ``plan`` (the M,
copies and offsets that repeat least within a memory budget, docs/variety.md),
``preview`` (a crowd rendered headless to PNG frames and an MP4, docs/preview.md),
``demo`` (the stadium demo end to end, docs/pipeline.md) and ``build-extension`` (the
Blender extension zip with its bundled wheels, ``crowd_addon/packaging.py``).

Each command is one ``add_<name>`` function that builds its subparser and one
``_run_<name>`` function that does the work, in a module of :mod:`crowd_addon.commands`
beside the others that call the same code (:mod:`~crowd_addon.commands.planning`,
:mod:`~crowd_addon.commands.export`, :mod:`~crowd_addon.commands.preview`,
:mod:`~crowd_addon.commands.demo`, :mod:`~crowd_addon.commands.extension`); this module
builds the parser and runs one. Heavy modules are imported inside the handlers so
``crowd --help`` stays fast. What needs Blender (``export --blend`` and
``preview --blend``: open a .blend, register the extension, take its frame range and
camera) goes through :mod:`crowd_addon.shot_source` to
:mod:`crowd_addon.blender.blend_shot`, imported only for them; that package never
imports this module (inside Blender, ``blender -c crowd export`` is its
own command). Exit codes: 0 success, 2 bad input (usage
errors and :class:`~crowd_addon.core.base.errors.CrowdError`, reported on stderr as
``crowd <command>: error: <message>``), 3 a .blend's crowd script that is not trusted
here (:class:`~crowd_addon.core.base.errors.ScriptNotTrusted`, reported the same way;
``--ignore-scripts`` goes on without it), 130 interrupted (Ctrl-C), 143 stopped by
SIGTERM (a farm queue or ``kill`` ending the job). Both stop the command the same way:
the exception unwinds the work, so what it staged is removed, the processes it started
are stopped and earlier outputs stay as they were (without a handler, SIGTERM would
end the process on the spot, leaving its staging and its child processes behind).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys

from .cli_args import parse_command
from .commands.demo import add_demo
from .commands.export import add_export, add_farm, add_snapshot, add_stitch
from .commands.extension import add_build_extension
from .commands.planning import add_budget, add_plan
from .commands.preview import add_preview
from .core.base.errors import CrowdError

__all__ = ["build_parser", "main", "console", "Terminated"]


class Terminated(BaseException):
    """SIGTERM, raised in the main thread of the ``crowd`` program so the command
    unwinds as on Ctrl-C (not an Exception: no ``except Exception`` swallows it)."""


def _terminated(signum, _frame):
    raise Terminated(signum)


def _stop_of(exc):
    """The KeyboardInterrupt or :class:`Terminated` that ``exc`` is, or that it was
    raised while handling (a stop that lands inside a lock's wait can leave the lock
    broken, and the error it raises then replaces the stop), else None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, (KeyboardInterrupt, Terminated)):
            return exc
        seen.add(id(exc))
        exc = exc.__context__
    return None


#: One ``add_<command>`` per subcommand.
_COMMANDS = (add_budget, add_plan, add_export, add_snapshot, add_stitch, add_farm, add_preview,
             add_demo, add_build_extension)


def build_parser() -> argparse.ArgumentParser:
    """The ``crowd`` parser with one subparser per command."""
    parser = argparse.ArgumentParser(
        prog="crowd", description="Crowd animation for Blender (after Paduraru), headless.")
    subparsers = parser.add_subparsers(dest="command", metavar="<command>")
    for add in _COMMANDS:
        add(subparsers)
    return parser


def main(argv=None) -> int:
    """Run ``crowd`` with ``argv`` (default ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    args, code = parse_command(parser, argv)
    if args is None:
        return code
    try:
        return args.handler(args)
    except CrowdError as exc:
        print(f"{parser.prog} {args.command}: error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)        # 3: ScriptNotTrusted


def console(argv=None) -> int:
    """The ``crowd`` program: :func:`main`, then out. A process that loaded the bpy
    module leaves with ``os._exit`` once its output is flushed: bpy 4.2 LTS crashes
    (SIGSEGV) in its C++ teardown at exit after our property groups were registered,
    when every file is already written, which would turn a finished run into a failed
    exit status. ``main`` itself returns normally (for callers in Python)."""
    signal.signal(signal.SIGTERM, _terminated)
    command = next((a for a in (sys.argv[1:] if argv is None else argv)
                    if not a.startswith("-")), "")
    try:
        code = main(argv)
    except BaseException as exc:            # noqa: BLE001 - re-raised unless a stop
        stop = _stop_of(exc)
        if stop is None:
            raise
        signal.signal(signal.SIGTERM, signal.SIG_IGN)     # once is enough: finish leaving
        why, code = ("interrupted", 130) if isinstance(stop, KeyboardInterrupt) else \
            ("stopped by SIGTERM", 128 + signal.SIGTERM)
        print(f"crowd {command}: {why}; earlier outputs are as they "
              f"were".replace("crowd : ", "crowd: "), file=sys.stderr)
    if "bpy" in sys.modules:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


if __name__ == "__main__":          # python -m crowd_addon.cli (as python -m crowd_addon)
    raise SystemExit(console())
