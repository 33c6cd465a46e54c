"""Memory of repeated exports in one long-lived process (a Blender session exports a
shot many times): the resident memory after 1, 10 and 25 USD exports of a small crowd
must stay on a flat line once the first exports have warmed the caches.

Each export is what ``crowd export --config crowd.json --out shot.usdc --frames 1-40``
does, run in this process (``crowd_addon.cli.main``): load the configuration, build
the crowd, record the shot, write the stage. With ``--blend`` each export is instead
``export_scene`` of the open scene of a small stadium .blend (the bpy module: the
sample stadium with 120 seats, its crowd, show and camera, built once at the start),
as the *Export Crowd USD* operator does in a Blender session. With ``--workers N``
each is ``crowd export --workers N``: chunks on a local Dask cluster it starts and
closes.

Prints the resident memory (``/proc/self/statm``) after 1, 10 and 25 exports, and
ends with one JSON line ``{"rss_mb_1": .., "rss_mb_10": .., "rss_mb_25": ..}``.

    .venv/bin/python benchmarks/export_memory.py [--exports 25] [--blend | --workers N]
        [--trace]

``--trace`` also prints the ten sources of Python allocations that grew most between
the 10th and the last export (``tracemalloc``), what to look at when the line rises.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import io
import json
import os
import shutil
import sys
import tempfile

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

FRAMES = "1-40"
MARKS = (1, 10, 25)


def rss_mb() -> float:
    """Resident memory of this process now, in MB (2**20 bytes)."""
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def small_config():
    """A small crowd with a show: a clip, a 2-way blend and a state machine stream, a
    unique, a held sweep and a cue for the unique, so the export writes stream layers,
    blend banks and value clips."""
    from crowd_addon.core import Blend2, ClipPlayer, CrowdConfig, StateMachine, StateTransition
    from crowd_addon.core.authoring.show import Action, Cue, Show, Sweep
    from crowd_addon.core.authoring.synthetic import humanoid, humanoid_mesh, periodic_clip
    sk = humanoid("fan", bones=24)
    cfg = CrowdConfig(max_offset=8, transition_slots=4)
    cfg.add_skeleton(sk)
    cfg.add_mesh(humanoid_mesh(sk), lods=())
    for i in range(3):
        cfg.add_clip(periodic_clip(sk, f"c{i}", frames=13 + 6 * i, seed=i,
                                   events=[("clap", 4.0)] if i == 0 else ()))
    cfg.add_stream("idle", "fan", ClipPlayer("c0"))
    cfg.add_stream("cheer", "fan", Blend2(ClipPlayer("c1"), ClipPlayer("c2"), weight=0.3))
    cfg.add_stream("wave", "fan", StateMachine(
        {"calm": ClipPlayer("c0"), "wild": ClipPlayer("c2")},
        [StateTransition("calm", "wild", 3, trigger="go")]))
    cfg.add_unique("solo", "fan", ClipPlayer("c2"))
    n = 48
    k = np.arange(n)
    cfg.add_agents(n, streams=k % 3, offsets=k % 8,
                   positions=np.stack([k % 8 * 0.8, k // 8 * 0.9, k // 8 * 0.4], 1))
    cfg.show = Show((Cue("wave", 4, Action("stream", "cheer", 3, hold=5),
                         sweep=Sweep((0, 0, 0), "angle", 0.8)),
                     Cue("solo", 9, Action("unique", "solo", 2, hold=6),
                         agents=np.arange(3)),
                     Cue("go", 12, Action("trigger", "wave", name="go"))))
    return cfg


def config_exporter(folder, workers=None):
    """``export()``: one ``crowd export --config`` in this process (``--workers N``: in
    chunks on a local Dask cluster of N workers started and closed by each export)."""
    from crowd_addon.cli import main
    from crowd_addon.core.authoring.config_io import save_config
    config = os.path.join(folder, "crowd.json")
    save_config(small_config(), config)
    out = os.path.join(folder, "out", "shot.usdc")

    def export():
        with contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()) as err:
            code = main(["export", "--config", config, "--out", out, "--frames", FRAMES]
                        + (["--workers", str(workers)] if workers else []))
        if code != 0:
            raise SystemExit(f"export failed ({code}): {err.getvalue()}")
    return export


def blend_exporter(folder):
    """``export()``: one export of the open scene of a small stadium .blend in this
    process, as the *Export Crowd USD* operator in a Blender session (the scene is
    baked and exported each time, the .blend stays open)."""
    import bpy  # the bpy module (Blender as a Python module)
    sys.path.insert(0, os.path.join(ROOT, "sample_scenes"))
    from build_stadium import build_stadium

    from crowd_addon import register
    from crowd_addon.blender.scene_export import export_scene
    from crowd_addon.blender.stadium import add_stand_camera, setup_show
    from crowd_addon.blender.stadium_cast import setup_crowd
    stadium = os.path.join(folder, "stadium.blend")
    with contextlib.redirect_stdout(io.StringIO()):
        build_stadium(stadium, seats=120, log=None)
        bpy.ops.wm.open_mainfile(filepath=stadium)
    register()
    scene = bpy.context.scene
    setup_crowd(scene, hits=2, slots=16)
    setup_show(scene, 40)
    add_stand_camera(scene, (320, 180))
    out = os.path.join(folder, "shot.usdc")

    def export():
        export_scene(scene, out, (scene.frame_start, scene.frame_end))
    return export


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--exports", type=int, default=MARKS[-1])
    p.add_argument("--blend", action="store_true",
                   help="export the open scene of a small .blend (needs the bpy module)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="each export in chunks on a local Dask cluster of N workers "
                        "(crowd export --workers N; needs dask and distributed)")
    p.add_argument("--trace", action="store_true",
                   help="print the Python allocations that grew most after the 10th")
    args = p.parse_args(argv)
    folder = tempfile.mkdtemp(prefix="crowd_export_memory_")
    try:
        export = blend_exporter(folder) if args.blend else \
            config_exporter(folder, args.workers)
        marks = sorted({m for m in MARKS if m <= args.exports} | {args.exports})
        if args.trace:
            import tracemalloc
            tracemalloc.start(12)
        figures, before = {}, None
        for i in range(1, args.exports + 1):
            export()
            gc.collect()
            if i in marks:
                figures[f"rss_mb_{i}"] = round(rss_mb(), 1)
                print(f"after {i:3d} exports: {figures[f'rss_mb_{i}']:7.1f} MB resident",
                      flush=True)
                if args.trace and i == 10:
                    before = tracemalloc.take_snapshot()
        if before is not None:
            grown = tracemalloc.take_snapshot().compare_to(before, "traceback")
            print("grew most since the 10th export (tracemalloc):")
            for stat in grown[:10]:
                print(f"  {stat.size_diff / 1024:+9.1f} KiB {stat.count_diff:+6d} blocks")
                for line in stat.traceback.format()[-6:]:
                    print(f"      {line}")
        print(json.dumps(figures))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
