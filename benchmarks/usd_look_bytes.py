"""What looks cost in a USD export (issue 34, item 5): the same shot written with and
without a look cue, bytes and time.

The paper's humanoid (82 bones) on ``--streams`` streams (M = 60) in a stadium grid,
the benchmark's steady shot (benchmarks/usd_export.py: a small share of the crowd
reacts three times); with looks, ``--share`` of the agents (every k-th seat) look at a
ball crossing the pitch from shot frame ``--at`` for ``--hold`` frames (8-frame blends
in and out). Each looking frame is an aim frame in the blend banks (the agent's own
pose), so the extra bytes are about ``share x agents x (hold + 8)`` poses.

    .venv/bin/python benchmarks/usd_look_bytes.py [--agents 2000] [--frames 120]
        [--streams 32] [--share 0.1] [--at 30] [--hold 40]

Ends with one JSON line (``look_bytes_ratio``: bytes with looks over without).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from usd_export import FIRST, build, reactions  # noqa: E402

from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.runtime.look_at import LookRig, LookTarget  # noqa: E402
from crowd_addon.core.shots.recorder import record  # noqa: E402
from crowd_addon.usd import export_crowd  # noqa: E402


def export(args, looks: bool, directory: str) -> dict:
    cfg = build(args.agents, args.streams)
    react = reactions(0.005)
    before_step = react
    if looks:
        t = np.arange(args.frames + 20)
        cfg.look_rigs = {"fan": LookRig(("neck", "head"), (0.4, 0.6),
                                        yaw_limit=math.radians(80))}
        cfg.look_targets = {"ball": LookTarget("ball", FIRST, np.c_[
            -20 + 0.6 * t, np.full(t.size, -15.0), np.full(t.size, 1.0)], smoothing=3)}
        step = max(1, round(1 / args.share))
        who = np.arange(0, args.agents, step)

        def before_step(crowd, frame):
            react(crowd, frame)
            if frame == FIRST + args.at:
                crowd.look_at(who, "ball", blend=8, hold=args.hold)
    t0 = time.perf_counter()
    rec = record(Crowd(cfg, skinning="gpu"), FIRST, FIRST + args.frames - 1,
                 before_step=before_step)
    r = export_crowd(rec, os.path.join(directory, "shot.usdc"), repetition=None)
    return {"bytes": r.bytes, "seconds": time.perf_counter() - t0,
            "clip_agents": r.clip_agents, "bank_frames": r.blend_frames,
            "looking_agents": int(rec.looking.sum())}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=2000)
    p.add_argument("--frames", type=int, default=120)
    p.add_argument("--streams", type=int, default=32)
    p.add_argument("--share", type=float, default=0.1)
    p.add_argument("--at", type=int, default=30)
    p.add_argument("--hold", type=int, default=40)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as d:
        os.mkdir(os.path.join(d, "plain"))
        os.mkdir(os.path.join(d, "looks"))
        plain = export(args, False, os.path.join(d, "plain"))
        looked = export(args, True, os.path.join(d, "looks"))
    aim = looked["bank_frames"] - plain["bank_frames"]
    out = {"agents": args.agents, "frames": args.frames, "streams": args.streams,
           "share": args.share, "hold": args.hold, "plain": plain, "looks": looked,
           "look_bytes_ratio": looked["bytes"] / plain["bytes"], "aim_frames": aim,
           "bytes_per_aim_frame": (looked["bytes"] - plain["bytes"]) / max(aim, 1)}
    print(f"without looks {plain['bytes'] / 1e6:.1f} MB in {plain['seconds']:.1f} s; "
          f"with {looked['looking_agents']} agents looking {looked['bytes'] / 1e6:.1f} MB in "
          f"{looked['seconds']:.1f} s: look_bytes_ratio {out['look_bytes_ratio']:.2f} "
          f"(target <= 2), {aim} aim frames, {out['bytes_per_aim_frame']:.0f} B each")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
