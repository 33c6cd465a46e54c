"""``crowd budget`` (the paper's GPU memory model and a proposed stream count and max
offset, docs/performance_budget.md) and ``crowd plan`` (the M, copies and offsets that
repeat least within a memory budget, docs/variety.md): their subparsers and handlers, on
:mod:`crowd_addon.core.planning` (``plan --blend`` reads the .blend through
:mod:`crowd_addon.shot_source`, which imports :mod:`crowd_addon.blender` only then).

Units: sizes in bytes; ``--budget-mb`` is in MB of 10**6 bytes, or MiB (2**20 bytes)
with ``--mib``.
"""

from __future__ import annotations

import sys

from ..cli_args import (add_repetition_arguments, add_trust_argument, int_at_least, path_arg,
                        positive_float, progress_printer)

__all__ = ["add_budget", "add_plan"]


MB = 10**6
MIB = 2**20


# ------------------------------------------------------------------------- budget

def add_budget(subparsers) -> None:
    from ..core.planning import budget as b  # only for the defaults shown in --help

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

    from ..core.planning import budget as b
    from ..core.planning.budget_report import report, report_dict

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

def add_plan(subparsers) -> None:
    from ..core.planning import budget as b
    from ..core.planning.variety_plan import MAX_STREAMS
    from ..plan_report import PLOT_FORMATS

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
    p.add_argument("--plot", type=path_arg, default="plan.png", metavar="FILE",
                   help="where to write the plot, in the format its extension names "
                        f"({', '.join('.' + f for f in PLOT_FORMATS)}); a name without "
                        "one gets .png (default: %(default)s)")
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

    from ..core.variety.repetition import RepetitionSettings
    from ..core.planning.variety_plan import plan_input, plan_variety
    from ..core.base.camera import frame_positions
    from ..core.anim.sub_keys import SUB_KEYS, sub_key_bytes
    from ..plan_report import plot, plot_target, summary_lines, table

    target = plot_target(args.plot) if args.plot else None     # refused before the work
    settings = RepetitionSettings(k=args.neighbours, appearance=not args.motion_only)
    printer = progress_printer("crowd plan")
    from ..shot_source import ShotSource
    source = ShotSource(config=args.config, blend=args.blend, scene=args.scene,
                        trust_scripts=args.trust_scripts, ignore_scripts=args.ignore_scripts,
                        strict=args.strict)
    with source.quietly():      # no crowd is built here, so no crowd script runs
        shot = source.open(on_bake=lambda done, total, message: print(
            f"crowd plan: {message}", file=sys.stderr, flush=True),
            frames_needed=False, crowd_needed=False)
        config = shot.config
        camera, settings = shot.metric_view(settings)
    size = {k: v for k, v in (("width", args.width), ("height", args.height)) if v}
    settings = dataclasses.replace(settings, **size)
    if camera is None:
        camera = frame_positions(config.agent_position, settings.width / settings.height)
    result = plan_variety(plan_input(config), camera.view_projection, args.budget_mb * 1e6,
                          settings, args.max_streams,
                          progress=lambda done, total: printer("candidates", done, total))
    written = plot(result, target) if target else None
    text = sys.stderr if args.json else sys.stdout     # --json: stdout is the JSON alone
    print(table(result), file=text)
    print("\n".join(summary_lines(result)), file=text)
    sub_bytes = sub_key_bytes(config)
    if sub_bytes:
        print(f"  speed streams: their clips resampled at 1/{SUB_KEYS} frame, "
              f"{sub_bytes / 1e6:,.1f} MB of CPU memory (not in the GPU budget)", file=text)
    if written:
        print(f"  plot: {written}", file=text)
    if args.json:
        print(json.dumps({**result.as_dict(), "plot": written, "sub_key_bytes": sub_bytes}))
    return 0
