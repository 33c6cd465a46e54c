"""Command-line runs of a Blender scene: ``crowd export --blend``, ``crowd preview
--blend`` and ``blender -c crowd``.

- the headless ``crowd`` program (:mod:`crowd_addon.commands`, :mod:`crowd_addon.farm`)
  imports this module only for ``crowd export --blend SCENE_BLEND ...`` and
  ``crowd preview --blend ...`` and
  calls :func:`export_blend` (the scene's Crowd settings baked as the panel does and
  written by :func:`.scene_export.export_scene`) or :func:`preview_blend` (baked with
  :func:`.scene_config.config_from_scene`, rendered through a scene camera), which
  open the file (the ``bpy`` module) and register the extension when needed. The
  scene's frame range and camera are the defaults; Blender's own log lines go to
  stderr, so stdout holds only the summary;
- inside Blender, the extension registers the ``crowd`` command of Blender's ``-c``
  option (:func:`register_command`, from :mod:`.registration`)::

      blender -b scene.blend -c crowd export --out shot.usdc [--frames 1-300]

  which exports the open file's scene (:func:`crowd_command`).

This module never imports the headless command line; its ``export`` options are the
scene-facing subset of ``crowd export`` (``--scene``, ``--out``, ``--frames``,
``--agents``, ``--json``). Exit codes: 0 success, 2 bad input (reported on stderr as
``crowd export: error: <message>``, nothing written; also ``--strict`` when the
bake report has warnings), 3 a crowd script that is not trusted here (the same way;
``--ignore-scripts`` goes on without it).

Every command prints the scene bake's report (``config.bake_report``,
:func:`report_bake`) on stderr, one line per note (``crowd export: warning: ...``).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import sys

from ..cli_args import add_shot_arguments, parse_command, progress_printer, repetition_settings
from ..core.base.errors import CrowdError
from ..core.variety.repetition import RepetitionSettings, describe

_DEFAULT = RepetitionSettings()

__all__ = ["open_scene", "export_blend", "preview_blend", "snapshot_blend", "scene_frames",
           "blend_shot",
           "blender_output_to_stderr", "build_parser", "crowd_command", "register_command",
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


@contextlib.contextmanager
def blender_output_to_stderr():
    """For the ``with`` block, whatever is written to the process's standard output
    (Blender's own log lines such as ``Read blend: ...``, which its C code writes
    there) goes to standard error, so a command's stdout holds only its summary
    (``--json``: one JSON object)."""
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:                             # no standard output at all
        yield
        return
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        _flush_c_stdio()
        os.dup2(saved, 1)
        os.close(saved)


def _flush_c_stdio():
    try:
        import ctypes
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):     # no C library to flush (Windows)
        pass


def scene_frames(scene, frames=None) -> tuple:
    """``frames`` (first, last), or the scene's frame range when None."""
    return (scene.frame_start, scene.frame_end) if frames is None else tuple(frames)


def _check_script(scene, trust_scripts: bool, ignore_scripts: bool) -> None:
    """A scene whose crowd script would not run here stops the command
    (:func:`.crowd_script.check_script`: ScriptNotTrusted, exit code 3)."""
    from .crowd_script import check_script
    check_script(scene, trust_scripts, ignore_scripts)


def blend_shot(frames: tuple | None = None, *, blend: str | None = None,
               scene: str | None = None, trust_scripts: bool = False,
               ignore_scripts: bool = False) -> tuple:
    """What a chunked export of a .blend (``crowd export --workers N --blend``) checks
    before its cluster starts: the scene opened (:func:`open_scene`), its crowd script
    trusted (or ``ignore_scripts``) as every task will need it, and the shot's frames,
    ``frames`` or the scene's frame range. Returns ``(first, last)``."""
    with blender_output_to_stderr():
        found = open_scene(blend, scene)
        _check_script(found, trust_scripts, ignore_scripts)
        return tuple(int(f) for f in scene_frames(found, frames))


def report_bake(config, on_bake, strict: bool = False) -> None:
    """Pass each note of the bake report (:func:`crowd_addon.core.bake.bake_report.report_of`:
    the bake's remarks, the meshes', the LOD levels refused) to ``on_bake(done, total,
    message)`` as ``warning: ...`` or ``note: ...``: the commands print them on stderr.
    ``strict``: a report with warnings then raises
    :class:`~crowd_addon.core.bake.bake_report.BakeWarnings` (exit code 2)."""
    from ..core.bake.bake_report import report_of
    report = report_of(config)
    if on_bake is not None:
        for note in report:
            on_bake(1, 1, note.line)
    report.check_strict(strict)


def export_blend(out: str, frames: tuple | None = None, *, blend: str | None = None,
                 scene: str | None = None, agents: int | None = None, progress=None,
                 on_bake=None, trust_scripts: bool = False, layout: str = "instanced",
                 substeps: int = 1, snapshots: str | None = None, repetition=_DEFAULT,
                 ignore_scripts: bool = False, strict: bool = False):
    """Export the Crowd settings of a .blend's scene (:func:`open_scene`) as UsdSkel.

    ``out``, ``agents``, ``layout``, ``substeps``, ``snapshots``, ``repetition``,
    ``progress(stage, done, total)`` and ``on_bake(done, total, message)`` are those of
    :func:`.scene_export.export_scene`; ``frames`` (first, last)
    defaults to the scene's frame range. The folder of ``out`` is created when
    missing, and removed again when the export fails. Blender's own output goes to
    stderr (:func:`blender_output_to_stderr`). Returns ``(config, result)``: the baked
    ``CrowdConfig`` and the ``ExportResult``. ``trust_scripts``: run the scene's crowd
    script in this call even where scripts in .blend files are not trusted; it trusts
    nothing after the call (a later call, or another file, is not trusted by it). A
    script that would not run stops the export before anything is written
    (:class:`~crowd_addon.core.base.errors.ScriptNotTrusted`), unless ``ignore_scripts``:
    then the shot is exported without it. The bake report's notes reach ``on_bake``;
    ``strict``: warnings among them stop the export before anything is written
    (:class:`~crowd_addon.core.bake.bake_report.BakeWarnings`).
    """
    with blender_output_to_stderr():        # from the import of bpy on (5.2 logs then)
        from ..core.base.files import folders_made
        from ..gpu.preview_render import writable_dir
        from .scene_export import export_scene
        found = open_scene(blend, scene)
        _check_script(found, trust_scripts, ignore_scripts)
        folder = writable_dir(os.path.dirname(os.path.abspath(out)))
        with folders_made(folder):
            return export_scene(found, out, scene_frames(found, frames), agents=agents,
                                progress=progress, on_bake=on_bake, layout=layout,
                                substeps=substeps, snapshots=snapshots,
                                repetition=repetition, trust_script=trust_scripts,
                                ignore_script=ignore_scripts, strict=strict)


def preview_blend(out: str, frames: int | None = None, *, blend: str | None = None,
                  scene: str | None = None, start: int | None = None,
                  camera: str | None = None, size=(None, None), mp4: bool = False,
                  backend: str = "moderngl", progress=None, on_bake=None,
                  trust_scripts: bool = False, samples: int = 4, shadows: bool = True,
                  repetition=_DEFAULT, lod: bool = True, ignore_scripts: bool = False,
                  strict: bool = False):
    """Render the Crowd settings of a .blend's scene (:func:`open_scene`) headless to
    PNG frames (:func:`crowd_addon.gpu.preview_render.render_preview`), drawn in the
    scene's own geometry and lit by its sun (:mod:`.scene_geometry`).

    ``start`` defaults to the scene's start frame and ``frames`` (a count) to the frames
    from there to the scene's end; ``camera`` names a camera object of the scene (default:
    the scene camera; with none, a camera framing the crowd); ``size`` (width, height)
    in pixels, either None for the scene's render resolution (its percentage applied).
    The camera, the frames and the output folder are checked before the bake.
    Blender's own output goes to stderr. ``trust_scripts`` and ``ignore_scripts`` as
    :func:`export_blend`;
    ``samples``: anti-aliasing of the moderngl backend; ``shadows``: the sun's
    shadows; ``repetition``: the repetition metric's settings (None: not measured);
    ``lod``: False draws every agent with its full mesh; ``strict``: the bake report's
    warnings stop it before rendering (:func:`report_bake`). Returns ``(config, result,
    camera object name or None)``.
    """
    with blender_output_to_stderr():        # from the import of bpy on (5.2 logs then)
        from ..gpu.preview_render import render_preview, writable_dir
        from .cameras import camera_from_object, find_camera, scene_size
        from .scene_config import build_crowd, config_from_scene
        from .scene_geometry import scene_geometry, scene_light
        found = open_scene(blend, scene)
        _check_script(found, trust_scripts, ignore_scripts)
        first = found.frame_start if start is None else int(start)
        if frames is None:
            frames = found.frame_end - first + 1
            if frames < 1:
                raise CrowdError(f"--start {first} is after scene {found.name!r}'s last "
                                 f"frame {found.frame_end}; give --frames")
        size = scene_size(found, size)
        obj = find_camera(found, camera)
        view = None if obj is None else camera_from_object(obj, size[0] / size[1])
        writable_dir(out)
        if backend == "blender":                # bpy runs in background mode: wake its GPU
            from .headless_gpu import init_headless_gpu
            init_headless_gpu()
        config = config_from_scene(found, on_bake)
        report_bake(config, on_bake, strict)
        crowd, note = build_crowd(found, config,       # with the scene's crowd script
                                  trust_script=trust_scripts,
                                  ignore_script=ignore_scripts)
        if note and on_bake is not None:
            on_bake(1, 1, note)
        result = render_preview(crowd, out, frames, start=first, size=size, mp4=mp4,
                                backend=backend, progress=progress, camera=view,
                                scene=scene_geometry(found), light=scene_light(found),
                                samples=samples, shadows=shadows, repetition=repetition,
                                lod=lod)
    return config, result, None if obj is None else obj.name


def plan_blend(*, blend: str | None = None, scene: str | None = None, settings=_DEFAULT,
               trust_scripts: bool = False, on_bake=None, ignore_scripts: bool = False,
               strict: bool = False):
    """What ``crowd plan --blend`` plans from: the scene's Crowd settings baked
    (:func:`open_scene`, as the exports bake them) and the camera and settings of its
    repetition metric (:func:`.cameras.metric_view`: the scene camera at the render
    size; None: the caller frames the agents). Returns ``(config, camera, settings)``.
    ``trust_scripts`` and ``ignore_scripts`` are accepted as the other commands take
    them; no crowd is built here, so no crowd script runs. ``strict``: the bake
    report's warnings stop it (:func:`report_bake`)."""
    with blender_output_to_stderr():
        from .cameras import metric_view
        from .scene_config import config_from_scene
        found = open_scene(blend, scene)
        config = config_from_scene(found, on_bake)
        report_bake(config, on_bake, strict)
        camera, settings = metric_view(found, settings)
        return config, camera, settings


def snapshot_blend(out: str, frames: tuple | None = None, *, every: int,
                   blend: str | None = None, scene: str | None = None, substeps: int = 1,
                   trust_scripts: bool = False, progress=None, on_bake=None,
                   ignore_scripts: bool = False, strict: bool = False):
    """Write snapshots of a .blend's scene crowd (:func:`open_scene`, baked as the
    exports bake it, with its crowd script) into the folder ``out``:
    :func:`crowd_addon.core.shots.snapshot_store.write_snapshots` over ``frames`` (default: the
    scene's frame range) every ``every`` frames; ``trust_scripts`` and
    ``ignore_scripts`` as :func:`export_blend`; ``strict``: the bake report's warnings
    stop it before any snapshot (:func:`report_bake`). Returns ``(config, files
    written)``."""
    with blender_output_to_stderr():
        from ..core.shots.snapshot_store import SnapshotFolder, write_snapshots
        from .scene_config import build_crowd, config_from_scene
        found = open_scene(blend, scene)
        _check_script(found, trust_scripts, ignore_scripts)
        first, last = scene_frames(found, frames)
        folder = SnapshotFolder(out, create=True)
        config = config_from_scene(found, on_bake)
        report_bake(config, on_bake, strict)
        crowd, note = build_crowd(found, config, substeps=substeps,
                                  trust_script=trust_scripts,
                                  ignore_script=ignore_scripts)
        if note and on_bake is not None:
            on_bake(1, 1, note)
        return config, write_snapshots(crowd, folder, first, last, every, progress)


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
        _, result = export_blend(
            args.out, args.frames, scene=args.scene, agents=args.agents,
            layout=args.layout, substeps=args.substeps, snapshots=args.snapshots,
            repetition=repetition_settings(args),
            trust_scripts=args.trust_scripts, ignore_scripts=args.ignore_scripts,
            strict=args.strict, progress=progress_printer("crowd export"),
            on_bake=lambda done, total, message: print(
                f"crowd export: {message}", file=sys.stderr, flush=True))
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
