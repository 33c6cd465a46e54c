"""The ``crowd`` command of Blender's ``-c`` option, on the open .blend::

      blender -b scene.blend -c crowd export --out shot.usdc [--frames 1-300]

registered by the extension (:func:`register_command`, from :mod:`.registration`). It
exports the open file's scene (:func:`crowd_command`): the scene opened as
:class:`.blend_shot.BlendShot` opens a .blend for the ``crowd`` program (``crowd export
--blend``, through :class:`crowd_addon.shot_source.ShotSource`), the shot written by
:func:`crowd_addon.usd.shot_export.export_shot`, as ``crowd export`` writes it.

This module never imports the headless command line; its ``export`` options are the
scene-facing subset of ``crowd export`` (``--scene``, ``--out``, ``--frames``,
``--agents``, ``--json``). Exit codes: 0 success, 2 bad input (reported on stderr as
``crowd export: error: <message>``, nothing written; also ``--strict`` when the
bake report has warnings), 3 a crowd script that is not trusted here (the same way;
``--ignore-scripts`` goes on without it). The bake report's notes go to stderr, one
line each (``crowd export: warning: ...``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from types import SimpleNamespace

from ..cli_args import add_shot_arguments, parse_command, progress_printer, repetition_settings
from ..core.base.errors import CrowdError
from ..core.variety.repetition import describe

__all__ = ["build_parser", "crowd_command", "register_command", "unregister_command",
           "command_registered"]

_handle = None          # the registered "crowd" command of Blender's -c option


# ------------------------------------------------------------- blender -c crowd

def build_parser() -> argparse.ArgumentParser:
    """The parser of Blender's ``-c crowd`` command (prog ``crowd``)."""
    parser = argparse.ArgumentParser(
        prog="crowd", description="The crowd extension's commands inside Blender, on the "
                                  "open .blend. The headless tools (budget, preview, demo, "
                                  "export --config) are the crowd program.")
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    p = sub.add_parser(
        "export", help="export the open scene's crowd shot to USD (UsdSkel)",
        description="Bake the scene's Crowd settings and write the shot as UsdSkel "
                    "(docs/usd_export.md); nothing is written unless it all succeeds.",
        epilog="example: blender -b scene.blend -c crowd export --out shot.usdc "
               "--frames 1-300 (default: the scene's frame range)")
    add_shot_arguments(p)
    return parser


def crowd_command(argv) -> int:
    """``blender -b scene.blend -c crowd <command> ...``: run a command on the open
    file and return the exit code (progress on stderr, a summary on stdout)."""
    args, code = parse_command(build_parser(), list(argv))
    if args is None:
        return code
    try:
        import bpy
        if not bpy.data.filepath:
            raise CrowdError("no .blend is open (blender -b SCENE_BLEND -c crowd export ...)")
        from ..usd.shot_export import export_shot
        from .blend_shot import BlendShot, blender_output_to_stderr
        # the open file's scene, as ShotSource.open opens a .blend for the crowd program
        source = SimpleNamespace(blend=None, scene=args.scene, substeps=args.substeps,
                                 trust_scripts=args.trust_scripts,
                                 ignore_scripts=args.ignore_scripts, strict=args.strict)
        with blender_output_to_stderr():
            shot = BlendShot(source, args.frames, on_bake=lambda done, total, message: print(
                f"crowd export: {message}", file=sys.stderr, flush=True))
            _, result = export_shot(shot, args.out, agents=args.agents, layout=args.layout,
                                    snapshots=args.snapshots,
                                    progress=progress_printer("crowd export"),
                                    repetition=repetition_settings(args),
                                    animation_only=args.animation_only)
    except CrowdError as exc:
        print(f"crowd {args.command}: error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)        # 3: a crowd script not trusted
    if args.json:
        print(json.dumps({**dataclasses.asdict(result), "bytes": result.bytes}))
    else:
        print(f"wrote {result.path} and {len(result.files) - 1} layers in "
              f"{result.layers_dir} ({result.bytes:,} B): {result.agents:,} agents, frames "
              f"{result.frames[0]}-{result.frames[1]}, {result.seconds['total']:.1f} s")
        if result.repetition is not None:
            print(f"  {describe(result.repetition)}")
    return 0


def register_command() -> None:
    """Register the ``crowd`` command of Blender's ``-c`` option (Blender 4.2+; once)."""
    global _handle
    import bpy
    if _handle is None and hasattr(bpy.utils, "register_cli_command"):
        _handle = bpy.utils.register_cli_command("crowd", crowd_command)


def unregister_command() -> None:
    """Take the ``crowd`` command away again (nothing when it is not registered)."""
    global _handle
    if _handle is not None:
        import bpy
        bpy.utils.unregister_cli_command(_handle)
        _handle = None


def command_registered() -> bool:
    """Whether the ``crowd`` command of Blender's ``-c`` option is registered."""
    return _handle is not None
