"""``crowd demo``: the stadium demo end to end (docs/pipeline.md), its subparser and
handler, on :mod:`crowd_addon.demo.run`.
"""

from __future__ import annotations

from ..cli_args import int_at_least, path_arg
from ..core.authoring.config import USD_LAYOUTS

__all__ = ["add_demo"]


def add_demo(subparsers) -> None:
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
    from ..core.variety.repetition import describe
    from ..demo.run import run_demo

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
