"""Headless command line: ``crowd <command> ...`` or ``python -m crowd_addon <command> ...``.

Commands: ``budget`` (the paper's GPU memory model and a proposed stream count and
max offset, docs/performance_budget.md), ``export`` (a crowd shot over a frame range
as UsdSkel, docs/usd_export.md), ``snapshot`` (exact snapshots of a shot for chunked
exports), ``stitch`` (chunk exports joined into one stage) and ``farm`` (a shot list
exported in chunks on one Dask cluster; all three docs/snapshots.md), ``preview`` (a crowd rendered headless to PNG frames
and an MP4, docs/preview.md), ``demo`` (the stadium demo end to end,
docs/pipeline.md) and ``build-extension`` (the Blender extension zip with its bundled
wheels, ``crowd_addon/packaging.py``).

Each command is one ``_add_<name>`` function that builds its subparser and one
``_run_<name>`` function that does the work; heavy modules are imported inside the
latter so ``crowd --help`` stays fast. What needs Blender (``export --blend`` and
``preview --blend``: open a .blend, register the extension, take its frame range and
camera) is :mod:`crowd_addon.blender.cli_commands`, imported only for them; that
package never imports this module (inside Blender, ``blender -c crowd export`` is its
own command). Exit codes: 0 success, 2 bad input (usage
errors and :class:`~crowd_addon.core.base.errors.CrowdError`, reported on stderr as
``crowd <command>: error: <message>``), 3 a .blend's crowd script that is not trusted
here (:class:`~crowd_addon.core.base.errors.ScriptNotTrusted`, reported the same way;
``--ignore-scripts`` goes on without it).

Units: sizes in bytes; ``--budget-mb`` is in MB of 10**6 bytes, or MiB (2**20 bytes)
with ``--mib``.
"""

from __future__ import annotations

import argparse
import os
import sys

from .cli_args import (add_repetition_arguments, add_shot_arguments, add_trust_argument,
                       frame_number, frame_range, int_at_least, parse_command, path_arg,
                       positive_float, progress_printer, repetition_settings)
from .core.authoring.config import MAX_SUBSTEPS, USD_LAYOUTS
from .core.base.errors import CrowdError

__all__ = ["build_parser", "main"]

MB = 10**6
MIB = 2**20


# ------------------------------------------------------------------------- budget

def _add_budget(subparsers) -> None:
    from .core.planning import budget as b  # only for the defaults shown in --help

    p = subparsers.add_parser(
        "budget",
        help="paper's memory model and a stream/offset proposal",
        description="Evaluate Paduraru's memory model (section 5: NumClips_OLD, "
                    "NumClips_NEW) and propose a stream count S and max offset M whose "
                    "GPU pose texture fits the budget. Defaults are the paper's inputs. "
                    "Sizes are bytes; MB means 10**6 bytes unless --mib is given.",
        epilog="example: crowd budget --bones 82 --pose-bytes 800 --clip-frames 300 "
               "--budget-mb 520 --max-offset 60")
    p.add_argument("--agents", type=int_at_least(1), default=65000,
                   help="agents in the crowd (default: %(default)s)")
    p.add_argument("--bones", type=int_at_least(1), default=b.PAPER_BONES,
                   help="bones per skeleton, NBones (default: %(default)s)")
    p.add_argument("--bytes-per-bone", type=positive_float,
                   default=float(b.PAPER_BYTES_PER_BONE),
                   help="SizePerBone of the paper's model, bytes (default: %(default)g, "
                        "the paper's 0.8 KB pose / 82 bones)")
    p.add_argument("--pose-bytes", type=positive_float, default=None,
                   help="PoseSize in bytes; overrides bones x --bytes-per-bone in the "
                        "paper's model (the plan always uses the GPU row size)")
    p.add_argument("--clip-frames", type=positive_float, nargs="+",
                   default=[float(b.PAPER_MOTION_LENGTH)], metavar="FRAMES",
                   help="clip length(s) in frames; the model uses their mean as "
                        "MotionLength, M may not exceed the shortest (default: 300)")
    p.add_argument("--budget-mb", type=positive_float, default=float(b.PAPER_BUDGET_MB),
                   help="GPU pose budget, MemBudget, in MB = 10**6 B (default: %(default)g)")
    p.add_argument("--mib", action="store_true",
                   help="read --budget-mb as MiB (2**20 B) instead of MB")
    p.add_argument("--max-offset", type=int_at_least(1), default=None,
                   help="M in frames; default: chosen by the planner")
    p.add_argument("--streams", type=int_at_least(1), default=None,
                   help="fix the stream count S; default: chosen by the planner")
    p.add_argument("--fps", type=positive_float, default=30.0,
                   help="crowd frames per second (default: %(default)g)")
    p.add_argument("--unique-agents", type=int_at_least(0), default=0,
                   help="agents in the unique pool, one row each (default: %(default)s)")
    p.add_argument("--transition-slots", type=int_at_least(0), default=800,
                   help="transition slots NT, one row each (default: %(default)s)")
    p.add_argument("--agents-per-key", type=positive_float, default=4.0,
                   help="diversity target: most agents per (stream, offset) "
                        "(default: %(default)g)")
    p.add_argument("--offset-seconds", type=positive_float, default=2.0,
                   help="preferred M in seconds, capped by the shortest clip "
                        "(default: %(default)g)")
    p.add_argument("--gpu-bytes-per-bone", type=positive_float,
                   default=float(b.GPU_BYTES_PER_BONE),
                   help="bytes per bone of a GPU pose row (default: %(default)g, "
                        "three RGBA32F texels)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=_run_budget)


def _run_budget(args) -> int:
    import json

    from .core.planning import budget as b
    from .core.planning.budget_report import report, report_dict

    unit = MIB if args.mib else MB
    budget_bytes = args.budget_mb * unit
    motion_length = sum(args.clip_frames) / len(args.clip_frames)
    proposal = b.plan(
        args.agents, budget_bytes, args.bones, args.clip_frames,
        bytes_per_bone=args.gpu_bytes_per_bone, fps=args.fps,
        max_agents_per_key=args.agents_per_key, offset_seconds=args.offset_seconds,
        max_offset=args.max_offset, streams=args.streams,
        unique_agents=args.unique_agents, transition_slots=args.transition_slots)
    model = b.memory_model(
        budget_bytes, motion_length, proposal.max_offset, pose_bytes=args.pose_bytes,
        bones=args.bones, bytes_per_bone=args.bytes_per_bone)

    if args.json:
        source = "--max-offset" if args.max_offset else "planner"
        print(json.dumps(report_dict(model, proposal, budget_mb=args.budget_mb,
                                     unit_bytes=unit, max_offset_source=source)))
        return 0
    pose = ("--pose-bytes" if args.pose_bytes is not None
            else f"{args.bones} bones x {args.bytes_per_bone:g} B")
    print(report(model, proposal, budget_mb=args.budget_mb,
                 unit_name="MiB" if args.mib else "MB", pose_source=pose,
                 max_offset_source="--max-offset" if args.max_offset else "from the plan",
                 clip_count=len(args.clip_frames), bones=args.bones,
                 gpu_bytes_per_bone=args.gpu_bytes_per_bone, fps=args.fps))
    return 0


# --------------------------------------------------------------------------- plan

def _add_plan(subparsers) -> None:
    from .core.planning import budget as b
    from .core.planning.variety_plan import MAX_STREAMS

    p = subparsers.add_parser(
        "plan",
        help="the M, copies and offsets that repeat least within a memory budget",
        description="Measure the repetition metric (docs/variety.md) of a crowd's agents "
                    "through a camera for every choice of M, copies of each speed stream "
                    "and offset distribution, and propose the one that repeats least "
                    "within the GPU pose budget and a stream count (the per-frame CPU "
                    "cost). Agents keep their templates, speeds, bodies and colours. "
                    "Prints every candidate and the proposal, and plots the metric "
                    "against M with the chosen point marked.",
        epilog="example: crowd plan --blend stadium.blend --budget-mb 520 --plot plan.png")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--config", type=path_arg, metavar="CROWD_JSON",
                     help="crowd configuration (seen from a camera framing its agents)")
    src.add_argument("--blend", type=path_arg, metavar="SCENE_BLEND",
                     help="a .blend with Crowd settings, baked as the panel bakes it, seen "
                          "through its scene camera (needs the bpy module)")
    p.add_argument("--scene", default=None, metavar="NAME",
                   help="scene of the .blend (default: the active scene)")
    p.add_argument("--budget-mb", type=positive_float, default=float(b.PAPER_BUDGET_MB),
                   help="GPU pose budget in MB = 10**6 B (default: the paper's %(default)g)")
    p.add_argument("--max-streams", type=int_at_least(1), default=MAX_STREAMS, metavar="S",
                   help="most streams a plan may use, the per-frame CPU cost (default: the "
                        "paper's %(default)s)")
    p.add_argument("--width", type=int_at_least(1), default=None,
                   help="screen width in pixels (default: the scene's render size, or 1280)")
    p.add_argument("--height", type=int_at_least(1), default=None,
                   help="screen height in pixels (default: the scene's render size, or 720)")
    add_repetition_arguments(p, frames=False)
    p.add_argument("--motion-only", action="store_true",
                   help="compare motion alone: agents alike when in step, whatever their "
                        "bodies and colours (what M, copies and offsets change; a crowd "
                        "whose looks never repeat measures 0 otherwise)")
    p.add_argument("--plot", type=path_arg, default="plan.png", metavar="PNG",
                   help="where to write the plot (default: %(default)s)")
    p.add_argument("--no-plot", dest="plot", action="store_const", const=None,
                   help="write no plot")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object on stdout (repetition_default, "
                        "repetition_planned, the default, the plan and every "
                        "candidate); the table goes to stderr")
    add_trust_argument(p)
    p.set_defaults(handler=_run_plan)


def _run_plan(args) -> int:
    import dataclasses
    import json

    from .core.variety.repetition import RepetitionSettings
    from .core.planning.variety_plan import plan_input, plan_variety
    from .core.base.camera import frame_positions
    from .plan_report import plot, summary_lines, table

    settings = RepetitionSettings(k=args.neighbours, appearance=not args.motion_only)
    printer = progress_printer("crowd plan")
    camera = None
    if args.blend:
        from .blender.cli_commands import plan_blend
        config, camera, settings = plan_blend(
            blend=args.blend, scene=args.scene, settings=settings,
            trust_scripts=args.trust_scripts, ignore_scripts=args.ignore_scripts,
            strict=args.strict,
            on_bake=lambda done, total, message: print(f"crowd plan: {message}",
                                                       file=sys.stderr, flush=True))
    else:
        from .core.authoring.config_io import load_config
        if args.scene is not None:
            raise CrowdError("--scene needs --blend (a configuration has no scenes)")
        config = load_config(args.config)
    size = {k: v for k, v in (("width", args.width), ("height", args.height)) if v}
    settings = dataclasses.replace(settings, **size)
    if camera is None:
        camera = frame_positions(config.agent_position, settings.width / settings.height)
    result = plan_variety(plan_input(config), camera.view_projection, args.budget_mb * 1e6,
                          settings, args.max_streams,
                          progress=lambda done, total: printer("candidates", done, total))
    written = plot(result, args.plot) if args.plot else None
    text = sys.stderr if args.json else sys.stdout     # --json: stdout is the JSON alone
    print(table(result), file=text)
    print("\n".join(summary_lines(result)), file=text)
    if written:
        print(f"  plot: {written}", file=text)
    if args.json:
        print(json.dumps({**result.as_dict(), "plot": written}))
    return 0


# ------------------------------------------------------------------------- export

def _add_export(subparsers) -> None:
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

    from .core.variety.repetition import describe
    from .farm import ShotSource, export_chunk
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
        repetition=repetition_settings(args))
    if args.json:
        print(json.dumps({**dataclasses.asdict(result), "bytes": result.bytes}))
        return 0
    s = result.seconds
    print("\n".join([
        f"wrote {result.path} and {len(result.files) - 1} layers in {result.layers_dir} "
        f"({result.bytes:,} B)",
        f"  frames {result.frames[0]}-{result.frames[1]} at {config.fps:g} fps"
        f"{f' ({result.substeps} samples a frame)' if result.substeps > 1 else ''}, "
        f"{result.agents:,} agents: {result.shared_agents:,} on "
        f"{result.offset_animations:,} shared offset animations, "
        f"{result.clip_agents:,} changing animation on value clips ({result.blend_frames:,} "
        f"blend frames), {result.moving_agents:,} moving",
        f"  {result.stream_animations:,} stream animations, {result.characters} "
        f"character layer{'s' if result.characters != 1 else ''}",
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

    from .farm import chunk_folder, farm_export, summary
    if args.snapshots is not None:
        raise CrowdError("--workers keeps its snapshots beside its chunks "
                         "(<out stem>.chunks/snapshots); leave out --snapshots")
    frames = args.frames
    if source.config is not None:
        if frames is None:
            raise CrowdError("--workers and --scheduler need --frames FIRST-LAST with "
                             "--config (a .blend gives its scene's frame range)")
    else:       # opened here once: the scene's frames, its script checked before any task
        from .blender.cli_commands import blend_shot
        frames = blend_shot(frames, blend=source.blend, scene=source.scene,
                            trust_scripts=source.trust_scripts,
                            ignore_scripts=source.ignore_scripts)
    result = farm_export(source, args.out, frames, workers=args.workers or 2,
                         scheduler=args.scheduler, chunk_frames=args.chunk_frames,
                         progress=progress)
    if args.json:
        print(json.dumps(summary(result)))
        return 0
    s, sec = result.stitch, result.seconds
    print(f"wrote {s.path} ({s.layers_dir}) stitched from {len(result.chunks)} chunks in "
          f"{chunk_folder(args.out)}: frames {s.frames[0]}-{s.frames[1]}, {s.agents:,} "
          f"agents ({s.clip_agents:,} on value clips)\n"
          f"  {sec['total']:.1f} s (snapshot pass {sec['snapshots']:.1f} s, slowest chunk "
          f"{sec['chunks']:.1f} s, stitch {sec['stitch']:.1f} s)")
    return 0


# --------------------------------------------------------------------------- farm
def _add_farm(subparsers) -> None:
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

    from .farm import farm_export_shots, load_shot_list, summary
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
def _add_stitch(subparsers) -> None:
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

    from .core.base.files import folders_made
    from .gpu.preview_render import writable_dir
    from .usd.stitch import stitch
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
def _add_snapshot(subparsers) -> None:
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

    from .farm import ShotSource, write_shot_snapshots
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


# ------------------------------------------------------------------------ preview

def _add_preview(subparsers) -> None:
    from .gpu.preview_render import BACKENDS  # no GL imported: just the names

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

    from .core.variety.repetition import describe
    from .gpu.preview_render import render_preview
    shown = [-1]

    def progress(done, total):
        if done * 10 // total > shown[0] or done == total:
            shown[0] = done * 10 // total
            print(f"crowd preview: frame {done}/{total}", file=sys.stderr, flush=True)

    size = (args.width, args.height)
    if args.blend:                  # the scene's Crowd settings, baked as the panel does
        from .blender.cli_commands import preview_blend
        config, r, camera = preview_blend(
            args.out, args.frames, blend=args.blend, scene=args.scene, start=args.start,
            camera=args.camera, size=size, mp4=args.mp4, backend=args.backend,
            samples=args.samples, shadows=args.shadows, trust_scripts=args.trust_scripts,
            ignore_scripts=args.ignore_scripts, strict=args.strict,
            progress=progress, repetition=repetition_settings(args), lod=args.lod == "on",
            on_bake=lambda done, total, message: print(
                f"crowd preview: {message}", file=sys.stderr, flush=True))
    else:
        from .core.authoring.config_io import load_config
        for option in ("scene", "camera"):
            if getattr(args, option) is not None:
                raise CrowdError(f"--{option} needs --blend (a configuration has no "
                                 f"{option}s)")
        if args.frames is None:
            raise CrowdError("--frames N is required with --config (a .blend gives its "
                             "scene's frame range)")
        config, camera = load_config(args.config), None
        size = (args.width or 960, args.height or 540)
        if args.backend == "blender":       # bpy runs in background mode: wake its GPU
            from .blender.headless_gpu import init_headless_gpu
            init_headless_gpu()
        r = render_preview(config, args.out, args.frames, start=args.start, size=size,
                           mp4=args.mp4, backend=args.backend, progress=progress,
                           samples=args.samples, repetition=repetition_settings(args),
                           lod=args.lod == "on")
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


# --------------------------------------------------------------------------- demo

def _add_demo(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        help="the stadium demo: build, bake, simulate, render preview frames, export USD",
        description="Build the sample stadium (sample_scenes/build_stadium.py) with one "
                    "agent per seat, author its crowd and its show as scene data (a goal "
                    "with cheers through transition slots, a Mexican wave, hits through "
                    "unique animations; the beats are fractions of --frames) and bake its "
                    "actions with the extension's code, save stadium.blend, run the "
                    "crowd (claps are counted from its events), render preview frames "
                    "headless (PNG, and MP4 with imageio-ffmpeg) and export stadium.usdc. "
                    "Needs the bpy module. See docs/pipeline.md.",
        epilog="example: crowd demo --out demo_out --agents 65000")
    p.add_argument("--out", required=True, type=path_arg, metavar="DIR",
                   help="output folder")
    p.add_argument("--agents", type=int_at_least(10), default=2000, metavar="N",
                   help="seats, one agent each (default: %(default)s; the paper: 65000)")
    p.add_argument("--frames", type=int_at_least(1), default=240, metavar="N",
                   help="frames to simulate, render and export; the show's beats scale "
                        "with it (default: %(default)s)")
    p.add_argument("--width", type=int_at_least(2), default=960)
    p.add_argument("--height", type=int_at_least(2), default=540)
    p.add_argument("--no-mp4", dest="mp4", action="store_false", help="PNG frames only")
    p.add_argument("--no-usd", dest="usd", action="store_false", help="skip the USD export")
    p.add_argument("--layout", choices=USD_LAYOUTS, default=USD_LAYOUTS[0],
                   help="stadium.usdc's layout, as crowd export's: instanced (default), or "
                        "blender, the stage Blender's own USD importer plays (File > Import "
                        "> Crowd (.usd) sets its frame rate; docs/usd_export.md)")
    p.set_defaults(handler=_run_demo)


def _run_demo(args) -> int:
    from .core.variety.repetition import describe
    from .demo.run import run_demo

    import importlib.util
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        args.mp4 = False                    # PNG frames only; say so in the summary
    s = run_demo(args.out, args.agents, args.frames, (args.width, args.height),
                 mp4=args.mp4, usd=args.usd, layout=args.layout)
    t = s["seconds"]
    print("\n".join([
        f"stadium demo in {args.out} ({t['total']:.1f} s: "
        + ", ".join(f"{k} {t[k]:.1f}" for k in ("build_scene", "bake", "record", "simulate",
                                                 "upload", "draw", "encode", "usd") if k in t)
        + (f"; the USD export took {t['usd_beside']:.1f} s beside the frames"
           if "usd_beside" in t else "") + ")",
        f"  {s['agents']:,} agents, {s['streams']} streams, {s['uniques']} uniques, "
        f"{s['characters']} character types, {s['frames']} frames",
        f"  core step {s['ms_per_step']:.2f} ms/frame, {s['upload_bytes_per_frame']:,} B "
        f"uploaded/frame, rendered on {s['renderer']}",
        f"  mass reactions: {s['switched_with_streams']:,} agents followed "
        f"{s['streams_switched']} switched streams (no slot)",
        f"  transitions: {s['transitions_requested']:,} requested, "
        f"{s['transitions_served']:,} served, {s['queued']:,} queued, {s['cut']} cut",
        f"  events fired {s['events_fired']:,} (clap: {s['clap_agent_events']:,} agent "
        f"claps on {s['clap_calls']} frames), cheering {s['cheering']:,}, wave "
        f"{s['wave_agents']:,}, hit {s['hits']}",
        f"  {describe(s['repetition'])} through the demo's camera",
        "  cues: " + ", ".join(f"{c['name']} @{c['frame']}" + (" (muted)" if c["name"] in
                                                              s["muted_cues"] else "")
                               for c in s["cues"]),
        f"  {s['pngs']} PNG frames" + (f", {s['mp4']}" if s['mp4'] else "")
        + f", contact sheet {s['contact_sheet']}"
        + (f", {s['usd']} ({s['usd_layout']} layout, {s['usd_bytes']:,} B)" if "usd" in s
           else "")]))
    return 0


# --------------------------------------------------------------- build-extension

def _add_build_extension(subparsers) -> None:
    p = subparsers.add_parser(
        "build-extension",
        help="build the Blender extension zip with its bundled wheels",
        description="Download the moderngl/glcontext wheels for every platform and "
                    "Python Blender ships (cached in build/wheels) and build the "
                    "extension zip with Blender's own extension tool (from the bpy "
                    "module). Install it with Blender > Preferences > Get Extensions > "
                    "Install from Disk, or blender --command extension install-file --repo "
                    "user_default --enable ZIP (docs/user_guide_blender.md, Install).")
    p.add_argument("--out", default="dist", type=path_arg, metavar="DIR",
                   help="folder for the zip (default: %(default)s)")
    p.add_argument("--split-platforms", action="store_true",
                   help="one zip per platform instead of one for all")
    p.add_argument("--wheels", type=path_arg, metavar="DIR", default=None,
                   help="take the wheels from this folder only, without network (every "
                        "platform and Python must be there; default: download into "
                        "build/wheels when missing)")
    p.set_defaults(handler=_run_build_extension)


def _run_build_extension(args) -> int:
    from .packaging import build_extension

    for z in build_extension(args.out, wheel_cache=args.wheels, offline=args.wheels is not None,
                             split_platforms=args.split_platforms,
                             progress=lambda m: print(f"crowd build-extension: {m}",
                                                      file=sys.stderr, flush=True)):
        print(z)
    return 0


# --------------------------------------------------------------------------- main

#: One ``_add_<command>`` per subcommand.
_COMMANDS = (_add_budget, _add_plan, _add_export, _add_snapshot, _add_stitch, _add_farm, _add_preview,
             _add_demo, _add_build_extension)


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
    code = main(argv)
    if "bpy" in sys.modules:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


if __name__ == "__main__":          # python -m crowd_addon.cli (as python -m crowd_addon)
    raise SystemExit(console())
