"""Seeking in a long shot: from the nearest snapshot against from the start (issue 18).

The paper's configuration (65,000 agents, 256 streams, M = 60, 800 slots, 82 bones)
running the cue-heavy show of ``core_frame.py`` (a Mexican wave lapping the stadium
and a cue every 10 frames). The crowd is stepped to ``--frames`` (default 10,000),
keeping a snapshot every ``--every`` frames (K, default 30) over the last
``--window`` frames (a full shot at K = 30 would need ``frames / K`` snapshots: the
figure is printed, not allocated). Then it jumps to random frames of that window and
to the last frame, and measures each jump from the nearest snapshot, and once the
same last frame reached from the start (reset and step) as the baseline. Every jump
is checked against the straight run's poses. Prints the figures and ends with one
JSON line (``seek_s_from_snapshot``: the slowest jump, ``seek_s_median``,
``seek_s_from_start``, ``snapshot_bytes``, ``snapshot_ms``, ``restore_ms``).

    .venv/bin/python benchmarks/scrub.py [--frames 10000] [--every 30] [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))

from core_frame import show_config  # noqa: E402

from crowd_addon.core import Crowd  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=65_000)
    ap.add_argument("--frames", type=int, default=10_000, help="the frame to reach")
    ap.add_argument("--every", type=int, default=30, help="K: frames between snapshots")
    ap.add_argument("--window", type=int, default=300,
                    help="frames before the last where snapshots are kept")
    ap.add_argument("--jumps", type=int, default=20)
    ap.add_argument("--quick", action="store_true", help="1,000 frames (smoke run)")
    args = ap.parse_args(argv)
    frames = 1_000 if args.quick else args.frames
    cfg = show_config(args.agents, frames)
    crowd = Crowd(cfg, skinning="gpu")
    start = crowd.frame
    last = start + frames
    keep_from = last - args.window
    print(f"scrub: {args.agents:,} agents, paper configuration with the cue-heavy show, "
          f"frame {last:,}, a snapshot every {args.every} frames over frames "
          f"{keep_from:,}..{last:,}", flush=True)
    t0 = time.perf_counter()
    while crowd.frame < keep_from:
        crowd.step()
        if crowd.frame % 1000 == 0:
            print(f"  stepped to {crowd.frame:,} ({time.perf_counter() - t0:.0f} s)",
                  file=sys.stderr, flush=True)
    cache = crowd.keep_snapshots(every=args.every, max_bytes=1 << 40)
    truth = {}
    rng = np.random.default_rng(3)
    targets = sorted(set(rng.integers(keep_from + args.every, last, args.jumps).tolist())
                     | {last})
    t_snap = []
    while crowd.frame < last:
        before = len(cache)
        crowd.step()
        if len(cache) > before:
            t = time.perf_counter()
            crowd.snapshot()                 # the cost of one more, timed apart
            t_snap.append(time.perf_counter() - t)
        if crowd.frame in targets:
            truth[crowd.frame] = crowd.agent_poses()
    straight_s = time.perf_counter() - t0
    snap_bytes = cache.nbytes // len(cache)

    seeks = []
    order = rng.permutation(targets).tolist()
    for target in order:                     # each jump from where the last one landed
        t = time.perf_counter()
        crowd.advance_to(target)
        seeks.append(time.perf_counter() - t)
        np.testing.assert_array_equal(crowd.agent_poses(), truth[target])
    t = time.perf_counter()
    crowd._set_state(cache.nearest(last).state())
    restore_ms = (time.perf_counter() - t) * 1e3

    # the baseline: the last frame reached from the start, without snapshots
    crowd.keep_snapshots(every=None)
    t = time.perf_counter()
    crowd.reset()
    crowd.advance_to(last)
    from_start = time.perf_counter() - t
    np.testing.assert_array_equal(crowd.agent_poses(), truth[last])

    worst = max(seeks)
    print(f"  jumps to {len(order)} frames of the window from the nearest snapshot: median "
          f"{statistics.median(seeks):.3f} s, slowest {worst:.3f} s (target < 0.2 s "
          f"with K = {args.every}: {'met' if worst < 0.2 else 'NOT met'}); every jump "
          f"equals the straight run's poses")
    print(f"  frame {last:,} from the start: {from_start:.1f} s "
          f"({from_start / worst:,.0f}x the slowest jump)")
    print(f"  one snapshot: {snap_bytes / 2**20:.1f} MiB, taken in "
          f"{statistics.median(t_snap) * 1e3:.0f} ms, restored in {restore_ms:.0f} ms; a "
          f"whole {frames:,}-frame shot at K = {args.every} would keep "
          f"{frames // args.every:,} of them ({frames // args.every * snap_bytes / 2**30:.1f} "
          f"GiB: the memory cap doubles K until they fit)")
    print(json.dumps({
        "seek_s_from_snapshot": round(worst, 4),
        "seek_s_median": round(statistics.median(seeks), 4),
        "seek_s_from_start": round(from_start, 2),
        "snapshot_bytes": int(snap_bytes),
        "snapshot_ms": round(statistics.median(t_snap) * 1e3, 1),
        "restore_ms": round(restore_ms, 1),
        "every": args.every, "frames": frames, "agents": args.agents,
        "straight_run_s": round(straight_s, 1),
    }))


if __name__ == "__main__":
    main()
