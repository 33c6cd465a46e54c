"""``crowd preview``: a crowd rendered headless to PNG frames and an MP4
(docs/preview.md), its subparser and handler, on :mod:`crowd_addon.gpu.preview_render`;
the shot from :mod:`crowd_addon.shot_source` (``--blend``: a .blend baked and seen
through its camera, :mod:`crowd_addon.blender.blend_shot`, imported only then).
"""

from __future__ import annotations

import os
import sys

from ..cli_args import (add_repetition_arguments, add_trust_argument, frame_number,
                        int_at_least, path_arg, repetition_settings)
from ..core.base.errors import CrowdError

__all__ = ["add_preview"]


def add_preview(subparsers) -> None:
    from ..gpu.preview_render import BACKENDS  # no GL imported: just the names

    p = subparsers.add_parser(
        "preview",
        help="render a crowd headless to PNG frames (and an MP4)",
        description="Run a saved crowd configuration (or a .blend's Crowd settings) and "
                    "draw it with the GPU renderer (instanced skinning from the pose "
                    "texture) through a camera that frames the whole crowd, or the "
                    "scene's camera, headless: frame_<F>.png per frame in the output "
                    "folder, and preview.mp4 with --mp4 (imageio-ffmpeg). Works without "
                    "a GPU (Mesa llvmpipe). See docs/preview.md.",
        epilog="example: crowd preview --config crowd.json --out shots/preview --frames "
               "48 --mp4")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--config", type=path_arg, metavar="CROWD_JSON",
                     help="crowd configuration manifest written by config_io.save_config")
    src.add_argument("--blend", type=path_arg, metavar="SCENE_BLEND",
                     help="a .blend whose scene has Crowd settings, baked first (needs the "
                          "bpy module)")
    p.add_argument("--scene", default=None, metavar="NAME",
                   help="scene of the .blend (default: the active scene)")
    p.add_argument("--camera", default=None, metavar="NAME",
                   help="a camera object of the .blend's scene to render through "
                        "(default: the scene camera; without one, or with --config, a "
                        "camera that frames the whole crowd)")
    p.add_argument("--out", required=True, type=path_arg, metavar="DIR",
                   help="folder for the frames (created if missing)")
    p.add_argument("--frames", type=int_at_least(1), metavar="N",
                   help="number of frames to render (default, from a .blend: up to the "
                        "scene's last frame; with --config it must be given)")
    p.add_argument("--start", type=frame_number, default=None, metavar="F",
                   help="first frame drawn: frame F of the shot, the crowd run from its "
                        "start through every cue before F (default: the configuration's "
                        "start frame, the scene's for a .blend)")
    p.add_argument("--width", type=int_at_least(1), default=None,
                   help="image width in pixels (default: the scene's render resolution "
                        "with --blend, else 960)")
    p.add_argument("--height", type=int_at_least(1), default=None,
                   help="image height in pixels (default: the scene's render resolution "
                        "with --blend, else 540)")
    p.add_argument("--mp4", action="store_true",
                   help="also write preview.mp4 (H.264 at the crowd's fps; needs an even "
                        "width and height)")
    p.add_argument("--backend", choices=BACKENDS, default="moderngl",
                   help="renderer: moderngl (headless EGL) or blender (Blender's gpu "
                        "module through bpy) (default: %(default)s)")
    p.add_argument("--no-shadows", dest="shadows", action="store_false",
                   help="with --blend: no sun shadows (they cost about as much again as "
                        "the crowd at 65k agents on a software rasterizer)")
    p.add_argument("--samples", type=int_at_least(0), default=4, metavar="N",
                   help="anti-aliasing, samples a pixel (a k x k grid: 4, 9, 16...), "
                        "moderngl backend (Blender's gpu module draws without); 0: "
                        "none (default: %(default)s)")
    p.add_argument("--lod", choices=("on", "off"), default="on",
                   help="levels of detail: on (each agent's level by its height in "
                        "pixels) or off (every agent drawn with its full mesh: the judge "
                        "of what the levels lose, far slower) (default: %(default)s)")
    add_repetition_arguments(p)
    p.add_argument("--json", action="store_true",
                   help="print the summary as one JSON object")
    add_trust_argument(p)
    p.set_defaults(handler=_run_preview)


def _run_preview(args) -> int:
    import json

    from ..core.variety.repetition import describe
    from ..gpu.preview_render import render_preview
    shown = [-1]

    def progress(done, total):
        if done * 10 // total > shown[0] or done == total:
            shown[0] = done * 10 // total
            print(f"crowd preview: frame {done}/{total}", file=sys.stderr, flush=True)

    from ..core.base.files import writable_dir
    from ..shot_source import ShotSource
    source = ShotSource(config=args.config, blend=args.blend, scene=args.scene,
                        trust_scripts=args.trust_scripts, ignore_scripts=args.ignore_scripts,
                        strict=args.strict)
    with source.quietly():
        shot = source.open(on_bake=lambda done, total, message: print(
            f"crowd preview: {message}", file=sys.stderr, flush=True), frames_needed=False)
        if shot.scene is None:
            if args.camera is not None:
                raise CrowdError("--camera needs --blend (a configuration has no cameras)")
            if args.frames is None:
                raise CrowdError("--frames N is required with --config (a .blend gives its "
                                 "scene's frame range)")
            first, frames, view, camera = args.start, args.frames, None, None
            size = (args.width or 960, args.height or 540)
        else:                   # the scene's frames, size and camera, through its camera
            from ..blender.blend_shot import preview_view
            first, frames, size, view, camera = preview_view(
                shot, args.start, args.frames, (args.width, args.height), args.camera)
        writable_dir(args.out)                          # checked before the bake
        if args.backend == "blender":       # bpy runs in background mode: wake its GPU
            from ..blender.headless_gpu import init_headless_gpu
            init_headless_gpu()
        config, crowd = shot.config, shot.crowd()
        if shot.scene is None:
            around = {}
        else:                   # drawn in the scene's own geometry, lit by its sun
            from ..blender.blend_shot import preview_scene
            around = dict(preview_scene(shot), shadows=args.shadows)
        r = render_preview(crowd, args.out, frames, start=first, size=size, mp4=args.mp4,
                           backend=args.backend, progress=progress, camera=view,
                           samples=args.samples, repetition=repetition_settings(args),
                           lod=args.lod == "on", **around)
    s = r.seconds
    if args.json:
        print(json.dumps({
            "out": args.out, "pngs": r.pngs, "mp4": r.mp4, "frames": list(r.frames),
            "size": list(r.size), "agents": r.agents, "backend": r.backend,
            "device": r.device, "camera": camera, "upload_bytes_per_frame": r.upload_bytes,
            "repetition": r.repetition, "seconds": s}))
        return 0
    n = len(r.pngs)
    print("\n".join([
        f"wrote {n} frame{'s' if n != 1 else ''} ({r.frames[0]}-{r.frames[1]}) to "
        f"{args.out}: {os.path.basename(r.pngs[0])} .. {os.path.basename(r.pngs[-1])}, "
        f"{r.size[0]} x {r.size[1]}",
        *([f"  {r.mp4}: {n} frames at {config.fps:g} fps"] if r.mp4 else []),
        f"  {r.agents:,} agents, {r.backend} on {r.device}, "
        + (f"camera {camera!r}, " if camera else "") +
        f"{r.upload_bytes:,} B uploaded per frame (median)",
        *([f"  {describe(r.repetition)}"] if r.repetition else []),
        f"  {s['total']:.1f} s, {n / s['total']:.1f} frames/s (simulate {s['simulate']:.1f} s, "
        f"sync {s['sync']:.1f} s, render {s['render']:.1f} s, write {s['write']:.1f} s)"]))
    return 0
