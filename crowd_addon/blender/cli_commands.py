"""Command-line exports of a Blender scene: ``crowd export --blend`` and ``blender -c crowd``.

Two front ends, one exporter (:func:`.export.export_scene`, the scene's Crowd
settings baked as the panel does):

- the headless ``crowd`` program (:mod:`crowd_addon.cli`) imports this module only
  for ``crowd export --blend SCENE_BLEND ...`` and calls :func:`export_blend`, which
  opens the file (the ``bpy`` module) and registers the extension when needed;
- inside Blender, the extension registers the ``crowd`` command of Blender's ``-c``
  option (:func:`register_command`, from :mod:`.registration`)::

      blender -b scene.blend -c crowd export --out shot.usdc --frames 1-300

  which exports the open file's scene (:func:`crowd_command`).

This module never imports the headless command line; its ``export`` options are the
scene-facing subset of ``crowd export`` (``--scene``, ``--out``, ``--frames``,
``--agents``, ``--json``). Exit codes: 0 success, 2 bad input (reported on stderr as
``crowd export: error: <message>``, nothing written).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys

from ..cli_args import add_shot_arguments, parse_command, progress_printer
from ..core.errors import CrowdError

__all__ = ["open_scene", "export_blend", "build_parser", "crowd_command", "register_command",
           "unregister_command", "command_registered"]

_handle = None          # the registered "crowd" command of Blender's -c option


def open_scene(blend: str | None = None, scene: str | None = None):
    """The Blender scene to export: the active (or ``scene``-named) scene of the .blend
    ``blend`` opened here, or of the file already open (inside Blender). Registers
    the extension when the scene has no Crowd settings yet. Raises CrowdError."""
    try:
        import bpy
    except ImportError:
        raise CrowdError("give --config CROWD_JSON, or --blend with the bpy module "
                         "installed (pip install bpy)") from None
    if blend:
        if not os.path.isfile(blend):
            raise CrowdError(f"{blend}: no such .blend file")
        try:
            bpy.ops.wm.open_mainfile(filepath=os.path.abspath(blend))
        except RuntimeError as e:            # not a .blend, damaged, from a newer Blender
            reason = str(e).strip().splitlines()[-1] if str(e).strip() else "unreadable"
            raise CrowdError(f"{blend}: Blender cannot open it as a .blend file "
                             f"({reason})") from None
    elif not bpy.data.filepath:
        raise CrowdError("give --config CROWD_JSON or --blend SCENE_BLEND (no .blend is "
                         "open)")
    found = bpy.context.scene if scene is None else bpy.data.scenes.get(scene)
    if found is None:
        raise CrowdError(f"no scene {scene!r} in {bpy.data.filepath} (scenes: "
                         f"{[s.name for s in bpy.data.scenes]})")
    if not hasattr(found, "crowd"):             # outside an installed extension
        from .registration import register
        register()
    return found


def export_blend(out: str, frames: tuple, *, blend: str | None = None,
                 scene: str | None = None, agents: int | None = None, progress=None,
                 on_bake=None):
    """Export the Crowd settings of a .blend's scene (:func:`open_scene`) as UsdSkel.

    ``out``, ``frames`` (first, last), ``agents``, ``progress(stage, done, total)`` and
    ``on_bake(done, total, message)`` are those of :func:`.export.export_scene`.
    Returns ``(config, result)``: the baked ``CrowdConfig`` and the ``ExportResult``.
    """
    found = open_scene(blend, scene)
    from .export import export_scene
    return export_scene(found, out, frames, agents=agents, progress=progress,
                        on_bake=on_bake)


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
               "--frames 1-300")
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
        _, result = export_blend(
            args.out, args.frames, scene=args.scene, agents=args.agents,
            progress=progress_printer("crowd export"),
            on_bake=lambda done, total, message: print(
                f"crowd export: {message}", file=sys.stderr, flush=True))
    except CrowdError as exc:
        print(f"crowd {args.command}: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps({**dataclasses.asdict(result), "bytes": result.bytes}))
    else:
        print(f"wrote {result.path} and {len(result.files) - 1} layers in "
              f"{result.layers_dir} ({result.bytes:,} B): {result.agents:,} agents, frames "
              f"{result.frames[0]}-{result.frames[1]}, {result.seconds['total']:.1f} s")
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
