"""The USD export commands: ``crowd export`` (a crowd shot over a frame range as
UsdSkel, docs/usd_export.md; with ``--workers`` or ``--scheduler`` in chunks on a Dask
cluster), ``crowd snapshot`` (exact snapshots of a shot for chunked exports), ``crowd
stitch`` (chunk exports joined into one stage) and ``crowd farm`` (a shot list exported
in chunks on one Dask cluster; all three docs/snapshots.md): their subparsers and
handlers, on :mod:`crowd_addon.farm` and :mod:`crowd_addon.usd`. Every shot comes from
:mod:`crowd_addon.shot_source` (a .blend's through :mod:`crowd_addon.blender`, imported
only for ``--blend``).
"""

from __future__ import annotations

import os
import sys

from ..cli_args import (add_shot_arguments, add_trust_argument, frame_range, int_at_least,
                        path_arg, progress_printer, repetition_settings)
from ..core.authoring.config import MAX_SUBSTEPS
from ..core.base.errors import CrowdError

__all__ = ["add_export", "add_farm", "add_stitch", "add_snapshot"]


# ------------------------------------------------------------------------- export

def add_export(subparsers) -> None:
    p = subparsers.add_parser(
        "export",
        help="export a crowd shot to USD (UsdSkel)",
        description="Run a saved crowd configuration over a frame range and write it as "
                    "UsdSkel: one layer per character, one baked SkelAnimation per "
                    "stream, shared offset animations, instanceable agents "
                    "(docs/usd_export.md). The main layer's extension picks the format: "
                    ".usdc or .usd binary, .usda text; its layers go to <stem>.layers/vN/ "
                    "beside it. From a .blend the frames default to its scene's frame "
                    "range. The output's folder is created if missing. Nothing is "
                    "written unless the whole export succeeds.",
        epilog="example: crowd export --config crowd.json --out shot.usdc --frames 1-300")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--config", type=path_arg, metavar="CROWD_JSON",
                     help="crowd configuration manifest written by config_io.save_config")
    src.add_argument("--blend", type=path_arg, metavar="SCENE_BLEND",
                     help="a .blend whose scene has Crowd settings (needs the bpy module; "
                          "inside Blender: blender -b scene.blend -c crowd export ...)")
    add_shot_arguments(p)
    farm = p.add_argument_group("chunks on a Dask cluster (pip install 'crowd_addon[farm]')")
    farm.add_argument("--workers", type=int_at_least(1), default=None, metavar="N",
                      help="export in chunks on a local Dask cluster of N processes, then "
                           "stitch them (docs/snapshots.md); the chunks and their "
                           "snapshots go to <out stem>.chunks/")
    farm.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                      help="run the chunks on this running Dask scheduler instead")
    farm.add_argument("--chunk-frames", type=int_at_least(1), default=None, metavar="N",
                      help="frames per chunk (default: one chunk per worker; each "
                           "chunk's stream layers repeat the M - 1 frames before it)")
    p.set_defaults(handler=_run_export)


def _run_export(args) -> int:
    import dataclasses
    import json

    from ..core.variety.repetition import describe
    from ..farm.chunks import export_chunk
    from ..shot_source import ShotSource
    source = ShotSource(config=args.config, blend=args.blend, scene=args.scene,
                        trust_scripts=args.trust_scripts, agents=args.agents,
                        layout=args.layout, substeps=args.substeps,
                        ignore_scripts=args.ignore_scripts, strict=args.strict)
    progress = progress_printer("crowd export")
    if args.workers is not None or args.scheduler is not None:
        return _run_farm_export(args, source, progress)
    config, result = export_chunk(
        source, args.frames, args.out, args.snapshots, progress=progress,
        on_bake=lambda done, total, message: print(f"crowd export: {message}",
                                                   file=sys.stderr, flush=True),
        repetition=repetition_settings(args), animation_only=args.animation_only)
    if args.json:
        print(json.dumps({**dataclasses.asdict(result), "bytes": result.bytes}))
        return 0
    s = result.seconds
    print("\n".join([
        f"wrote {result.path} and {len(result.files) - 1} layers in {result.layers_dir} "
        f"({result.bytes:,} B)",
        f"  frames {result.frames[0]}-{result.frames[1]} at {config.fps:g} fps"
        f"{f' ({result.substeps} samples a frame)' if result.substeps > 1 else ''}, "
        f"{result.agents:,} agents: {result.shared_agents:,} "
        + ("static (their offset animations are the stitch's), " if args.animation_only
           else f"on {result.offset_animations:,} shared offset animations, ")
        + f"{result.clip_agents:,} changing animation on value clips "
        f"({result.blend_frames:,} blend frames), {result.moving_agents:,} moving",
        f"  {result.stream_animations:,} stream animations, {result.characters} "
        f"character layer{'s' if result.characters != 1 else ''}"
        + ("; animation only: for crowd stitch, not a stage to open on its own"
           if args.animation_only else ""),
        f"  {s['total']:.1f} s (simulate {s['simulate']:.1f} s, author "
        f"{s['author']:.1f} s, write {s['write']:.1f} s)"]
        + ([f"  {describe(result.repetition)}"] if result.repetition else [])
        + ([f"  simulated from the snapshot at frame {result.started_from}"
            if result.started_from is not None else
            "  no snapshot of this crowd before the shot: simulated from its start frame",
            f"  left {result.snapshot} for the next chunk"] if result.snapshot else [])))
    return 0


def _run_farm_export(args, source, progress) -> int:
    import json

    from ..farm.chunks import chunk_folder
    from ..farm.cluster import farm_export, summary
    if args.snapshots is not None:
        raise CrowdError("--workers keeps its snapshots beside its chunks "
                         "(<out stem>.chunks/snapshots); leave out --snapshots")
    if args.animation_only:
        raise CrowdError("--workers writes its chunks after the first animation-only "
                         "itself; leave out --animation-only")
    # opened here once: the shot's frames (a .blend's scene range), its crowd script
    # checked before any task (nothing is baked or built here)
    with source.quietly():
        frames = source.open(args.frames).frames
    result = farm_export(source, args.out, frames, workers=args.workers or 2,
                         scheduler=args.scheduler, chunk_frames=args.chunk_frames,
                         progress=progress)
    if args.json:
        print(json.dumps(summary(result)))
        return 0
    s, sec = result.stitch, result.seconds
    print(f"wrote {s.path} ({s.layers_dir}) stitched from {len(result.chunks)} chunks in "
          f"{chunk_folder(args.out)} (the first whole, the others animation-only): frames "
          f"{s.frames[0]}-{s.frames[1]}, {s.agents:,} agents ({s.clip_agents:,} on value "
          f"clips)\n"
          f"  {sec['total']:.1f} s (snapshot pass {sec['snapshots']:.1f} s, slowest chunk "
          f"{sec['chunks']:.1f} s, stitch {sec['stitch']:.1f} s)")
    return 0


# --------------------------------------------------------------------------- farm
def add_farm(subparsers) -> None:
    p = subparsers.add_parser(
        "farm",
        help="export many shots in chunks on one Dask cluster",
        description="Export every shot of a shot list (JSON: {\"shots\": [{\"config\" or "
                    "\"blend\": ..., \"frames\": \"FIRST-LAST\", \"out\": ..., optional "
                    "\"scene\", \"trust_scripts\", \"ignore_scripts\", \"agents\", \"layout\", "
                    "\"substeps\", \"chunk_frames\", \"strict\"}]}, paths relative to the "
                    "file) as crowd "
                    "export --workers does: every shot's snapshot pass, chunks and stitch as "
                    "tasks of one Dask cluster. A shot that fails is named and writes no "
                    "stage; the others are written (docs/snapshots.md). Exit code 3 when a "
                    "shot's crowd script is not trusted (give it trust_scripts or "
                    "ignore_scripts), else 2 when a shot failed.",
        epilog="example: crowd farm shots.json --workers 8")
    p.add_argument("shots", type=path_arg, metavar="SHOTS_JSON", help="the shot list")
    p.add_argument("--workers", type=int_at_least(1), default=2, metavar="N",
                   help="local Dask worker processes (default 2)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on this running Dask scheduler instead")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object: a summary or an error per shot")
    p.set_defaults(handler=_run_farm)


def _run_farm(args) -> int:
    import json

    from ..farm.cluster import farm_export_shots, summary
    from ..farm.shot_list import load_shot_list
    shots = load_shot_list(args.shots)
    results = farm_export_shots(shots, args.workers, args.scheduler,
                                progress_printer("crowd farm"))
    failed = [r for r in results if isinstance(r, CrowdError)]
    if args.json:
        print(json.dumps({"shots": [{"error": str(r)} if isinstance(r, CrowdError)
                                    else summary(r) for r in results]}))
    else:
        for shot, r in zip(shots, results):
            if not isinstance(r, CrowdError):
                s = r.stitch
                print(f"wrote {s.path}: frames {s.frames[0]}-{s.frames[1]}, {s.agents:,} "
                      f"agents, {len(r.chunks)} chunks")
    for r in failed:
        print(f"crowd farm: error: {r}", file=sys.stderr)
    if any(getattr(r, "exit_code", 2) == 3 for r in failed):
        return 3                # a shot's crowd script not trusted (and no ignore_scripts)
    return 2 if failed else 0


# ------------------------------------------------------------------------- stitch
def add_stitch(subparsers) -> None:
    p = subparsers.add_parser(
        "stitch",
        help="join chunk exports of one shot into one stage",
        description="Join the USD exports of consecutive chunks of one shot (crowd export "
                    "--frames A-B --snapshots DIR, one per chunk) into one stage that reads "
                    "back as the export of the whole range. The stitched stage reads the "
                    "chunks' characters and blends where they are (relative paths): keep "
                    "them beside it. Nothing is written unless it all succeeds "
                    "(docs/snapshots.md).",
        epilog="example: crowd stitch --out shot.usdc chunks/c1/shot.usdc "
               "chunks/c2/shot.usdc")
    p.add_argument("chunks", nargs="+", type=path_arg, metavar="CHUNK_USD",
                   help="the chunks' main layers, any order")
    p.add_argument("--out", required=True, type=path_arg, metavar="SHOT_USD",
                   help="main layer to write (.usdc, .usd or .usda); its folder is "
                        "created if missing")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(handler=_run_stitch)


def _run_stitch(args) -> int:
    import dataclasses
    import json

    from ..core.base.files import folders_made
    from ..core.base.files import writable_dir
    from ..usd.stitch import stitch
    folder = writable_dir(os.path.dirname(os.path.abspath(args.out)))
    with folders_made(folder):                  # as crowd export: gone again on failure
        result = stitch(args.chunks, args.out, progress=progress_printer("crowd stitch"))
    if args.json:
        print(json.dumps({**dataclasses.asdict(result), "bytes": result.bytes}))
        return 0
    print(f"wrote {result.path} and {len(result.files) - 1} layers in {result.layers_dir} "
          f"({result.bytes:,} B): {len(result.chunks)} chunks, frames {result.frames[0]}-"
          f"{result.frames[1]}, {result.agents:,} agents ({result.shared_agents:,} shared, "
          f"{result.clip_agents:,} on value clips, {result.moving_agents:,} moving), "
          f"{result.seconds:.1f} s")
    return 0


# ----------------------------------------------------------------------- snapshot
def add_snapshot(subparsers) -> None:
    p = subparsers.add_parser(
        "snapshot",
        help="write exact snapshots of a crowd shot, for chunked exports",
        description="Simulate a crowd over a frame range once and write an exact "
                    "snapshot (docs/snapshots.md) at the frame before each chunk of "
                    "--every frames and at the last frame, into a folder. "
                    "crowd export --frames A-B --snapshots DIR then starts from the one "
                    "before A instead of simulating from the start frame. A snapshot "
                    "already in the folder before the first frame is started from.",
        epilog="example: crowd snapshot --config crowd.json --frames 1-3000 --every 500 "
               "--out snaps")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--config", type=path_arg, metavar="CROWD_JSON",
                     help="crowd configuration manifest written by config_io.save_config")
    src.add_argument("--blend", type=path_arg, metavar="SCENE_BLEND",
                     help="a .blend whose scene has Crowd settings (needs the bpy module)")
    p.add_argument("--scene", default=None, metavar="NAME",
                   help="scene of the .blend (default: the active scene)")
    p.add_argument("--out", required=True, type=path_arg, metavar="DIR",
                   help="snapshot folder (created if missing)")
    p.add_argument("--frames", type=frame_range, metavar="FIRST-LAST",
                   help="the shot's frames (default, from a .blend: the scene's frame "
                        "range; with --config it must be given)")
    p.add_argument("--every", type=int_at_least(1), required=True, metavar="N",
                   help="chunk length in frames: a snapshot before each chunk")
    p.add_argument("--substeps", type=int_at_least(1, MAX_SUBSTEPS), default=1, metavar="N",
                   help="samples per frame the exports from these snapshots will write "
                        "(a snapshot keeps them; default 1)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_trust_argument(p)
    p.set_defaults(handler=_run_snapshot)


def _run_snapshot(args) -> int:
    import json
    import time

    from ..farm.chunks import write_shot_snapshots
    from ..shot_source import ShotSource
    t = time.perf_counter()
    progress = progress_printer("crowd snapshot")
    source = ShotSource(config=args.config, blend=args.blend, scene=args.scene,
                        trust_scripts=args.trust_scripts, substeps=args.substeps,
                        ignore_scripts=args.ignore_scripts, strict=args.strict)
    files = write_shot_snapshots(
        source, args.out, args.frames, args.every,
        progress=lambda d, n: progress("simulate", d, n),
        on_bake=lambda done, total, message: print(f"crowd snapshot: {message}",
                                                   file=sys.stderr, flush=True))
    size = sum(os.path.getsize(f) for f in files)
    seconds = time.perf_counter() - t
    if args.json:
        print(json.dumps({"files": files, "bytes": size, "seconds": round(seconds, 2)}))
    else:
        print(f"wrote {len(files)} snapshots ({size:,} B) in {args.out}, {seconds:.1f} s")
    return 0
