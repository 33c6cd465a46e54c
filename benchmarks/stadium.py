"""The sample stadium's show at the demo's and the paper's scale, read from recordings.

For each size (``--agents``, default 2,000 and 65,000): build the sample stadium with
that many seats, author its crowd and show (``crowd_addon.blender.stadium``, the
demo's own code), run the crowd with its show into a recording, and run it again
without the show (the *quiet run*: the same agents, streams and offsets) into another.

- ``goal_reacted_share_2s_<size>``: of the agents the goal cues select (home fans
  celebrate, away fans despair), the share whose arm bones (upper arm, forearm, hand,
  both sides) leave their quiet-run pose (the same agent at the same frame) by more
  than 0.1 rad (the angle between the two local rotations) within 60 frames of the
  cue (two seconds at 30 fps). A goal that sends its fans through 800 transition
  slots reaches a few per cent of 65,000 in that time; streams that take the goal
  (docs/show.md, "Mass reactions") reach all of them at their own offsets.
- ``wave_queue_frames_<size>``: the longest a wave agent waits in the slot queue
  while the goal plays (from the goal's frame to the end of its hold plus M).
- ``goal_slots_<size>``: agents the goal cues sent through slots.
- with ``--compare``, ``goal_reacted_share_2s_<size>_by_slots``: the same share when
  the goal cues have no switch trigger and send every fan through the slots (the
  show as it was before mass reactions).
- ``demo_65k_seconds`` and ``demo_65k_split``: the whole ``crowd demo --agents
  65000`` (240 frames), its seconds per stage from its ``summary.json`` (with
  ``--demo``; it takes minutes).

    .venv/bin/python benchmarks/stadium.py [--agents 2000,65000] [--frames 240] [--compare]
                                           [--demo]

Prints a table and ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

ARM_BONES = tuple(f"{b}.{s}" for s in "LR" for b in ("upper_arm", "forearm", "hand"))
REACT_WITHIN = 60          # frames after the cue (2 s at 30 fps)
THRESHOLD = 0.1            # radians


def _label(n: int) -> str:
    return f"{n // 1000}k" if n % 1000 == 0 else str(n)


def _build(path: Path, seats: int):
    run = subprocess.run([sys.executable, str(ROOT / "sample_scenes" / "build_stadium.py"),
                          "--out", str(path), "--seats", str(seats), "--quiet"],
                         capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"building the stadium failed:\n{run.stderr[-2000:]}")


def _record(cfg, first, last, watch=None):
    """Record ``cfg``'s crowd over ``first .. last``; ``watch(crowd)`` after each step."""
    from crowd_addon.core.shots.crowd import Crowd
    from crowd_addon.core.shots.recorder import Recorder

    crowd = Crowd(cfg, skinning="gpu")
    rec = Recorder(crowd, first, last)
    while not rec.finished:
        rec.step()
        if watch is not None:
            watch(crowd)
    return crowd, rec.finish()


def _angles(a, b):
    """Angle (radians) between the quaternions of SQT poses ``a`` and ``b`` (..., 10)."""
    dot = np.abs(np.einsum("...i,...i->...", a[..., 3:7].astype(np.float64),
                           b[..., 3:7].astype(np.float64)))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


def _by_slots(cfg):
    """``cfg`` with the goal cues' switch triggers taken out: every fan by slot."""
    from crowd_addon.blender.stadium import CUES
    from crowd_addon.core.authoring.show import Show

    goals = (CUES["goal_home"], CUES["goal_away"])
    cues = tuple(replace(c, action=replace(c.action, trigger="", release=""))
                 if c.name in goals else c for c in cfg.show.cues)
    return replace(cfg, show=Show(cues, cfg.show.reactions, cfg.show.tracks))


def stadium_config(agents: int, frames: int, work: Path):
    import bpy

    from crowd_addon.blender.stadium import author_stadium

    blend = work / f"stadium_{agents}.blend"
    t = time.perf_counter()
    _build(blend, agents)
    stadium = author_stadium(blend, frames, progress=None)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return stadium.config, time.perf_counter() - t


def measure(cfg, frames: int, build_s: float = 0.0) -> dict:
    from crowd_addon.blender.stadium import CUES
    from crowd_addon.core.authoring.show import Show

    show = cfg.show
    goals = [show.cue(CUES["goal_home"]), show.cue(CUES["goal_away"])]
    at = goals[0].frame
    first = cfg.start_frame
    m = cfg.max_offset
    hold = goals[0].action.hold
    last = min(first + frames - 1, at + hold + m)
    wave = show.cue(CUES["wave"])

    waiting = {}                   # wave agent -> frames waited so far
    longest = [0]
    wave_ids = np.zeros(cfg.agent_count, bool)

    def watch(crowd):
        if not wave_ids.any():
            ids = np.arange(cfg.agent_count) if wave.agents is None else wave.agents
            wave_ids[ids] = True
        q = crowd.slots.queued_agents()
        q = q[wave_ids[q]]
        now = {int(a): waiting.get(int(a), 0) + 1 for a in q.tolist()}
        waiting.clear()
        waiting.update(now)
        if at <= crowd.frame <= at + hold + m and now:
            longest[0] = max(longest[0], max(now.values()))

    t = time.perf_counter()
    crowd, loud = _record(cfg, first, last, watch)
    quiet_cfg = replace(cfg, show=Show())
    _, quiet = _record(quiet_cfg, first, min(last, at + REACT_WITHIN))
    run_s = time.perf_counter() - t

    skeletons = list(cfg.skeletons)
    target = [d.name for d in cfg.streams].index(goals[0].action.target)
    fan = int(loud.stream_skeleton[target])
    bones = [cfg.skeletons[skeletons[fan]].bone_index(b) for b in ARM_BONES]
    selected = np.unique(np.concatenate([
        np.arange(cfg.agent_count) if g.agents is None else g.agents for g in goals]))
    selected = selected[loud.agent_skeleton[selected] == fan]
    moved = np.zeros(selected.size, bool)
    for f in range(at, min(at + REACT_WITHIN, quiet.last) + 1):
        a = loud.agent_poses([f], selected)[0][:, bones]
        b = quiet.agent_poses([f], selected)[0][:, bones]
        moved |= (_angles(a, b) > THRESHOLD).any(1)
    stats = crowd.show.stats
    return {"agents": cfg.agent_count, "goal_selected": int(selected.size),
            "goal_reacted": int(moved.sum()),
            "goal_reacted_share": float(moved.mean()) if selected.size else 0.0,
            "goal_switched": int(sum(stats[g.name]["switched"] for g in goals)),
            "goal_slots": int(sum(stats[g.name]["agents"] - stats[g.name]["switched"]
                                  for g in goals)),
            "wave_agents": int(stats[wave.name]["agents"]),
            "wave_queue_frames": int(longest[0]),
            "build_seconds": round(build_s, 1), "run_seconds": round(run_s, 1)}


def run_demo(agents: int, frames: int, work: Path) -> dict:
    out = work / f"demo_{agents}"
    t = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "demo", "--agents", str(agents),
                          "--frames", str(frames), "--out", str(out)],
                         capture_output=True, text=True, cwd=ROOT)
    seconds = time.perf_counter() - t
    if run.returncode != 0:
        raise SystemExit(f"crowd demo failed:\n{run.stderr[-2000:]}")
    split = json.loads((out / "summary.json").read_text())["seconds"]
    return {"seconds": round(seconds, 1), "split": split}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", default="2000,65000",
                    help="comma-separated stadium sizes (default 2000,65000)")
    ap.add_argument("--frames", type=int, default=240, help="the show's run (default 240)")
    ap.add_argument("--compare", action="store_true",
                    help="also measure the goal sent through the slots (no switch trigger)")
    ap.add_argument("--demo", action="store_true",
                    help="also time the whole `crowd demo --agents 65000`")
    args = ap.parse_args(argv)
    sizes = [int(a) for a in args.agents.split(",") if a.strip()]
    out = {}
    with tempfile.TemporaryDirectory(prefix="crowd_stadium_") as tmp:
        work = Path(tmp)
        print(f"{'agents':>8} {'selected':>9} {'reacted':>8} {'share':>7} {'switched':>9} "
              f"{'by slot':>8} {'wave wait':>9} {'build s':>8} {'run s':>7}")
        for n in sizes:
            cfg, build_s = stadium_config(n, args.frames, work)
            runs = [("", cfg)] + ([("_by_slots", _by_slots(cfg))] if args.compare else [])
            for suffix, c in runs:
                r = measure(c, args.frames, build_s)
                print(f"{r['agents']:>8,} {r['goal_selected']:>9,} {r['goal_reacted']:>8,} "
                      f"{r['goal_reacted_share']:>7.3f} {r['goal_switched']:>9,} "
                      f"{r['goal_slots']:>8,} {r['wave_queue_frames']:>9} "
                      f"{r['build_seconds']:>8} {r['run_seconds']:>7}"
                      + ("  (goal by slots)" if suffix else ""), flush=True)
                k = _label(n)
                out[f"goal_reacted_share_2s_{k}{suffix}"] = round(r["goal_reacted_share"], 4)
                if not suffix:
                    out[f"wave_queue_frames_{k}"] = r["wave_queue_frames"]
                    out[f"goal_slots_{k}"] = r["goal_slots"]
                else:
                    out[f"wave_queue_frames_{k}{suffix}"] = r["wave_queue_frames"]
        if args.demo:
            d = run_demo(65000, args.frames, work)
            print(f"crowd demo --agents 65000 --frames {args.frames}: {d['seconds']} s "
                  f"({', '.join(f'{k} {v}' for k, v in d['split'].items())})")
            out["demo_65k_seconds"] = d["seconds"]
            out["demo_65k_split"] = d["split"]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
