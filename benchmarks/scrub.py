"""Seeking in a long shot from snapshots, and exporting it in chunks (issue 18).

The paper's configuration (65,000 agents, 256 streams, M = 60, 800 slots, 82 bones)
running the cue-heavy show of ``core_frame.py`` (a Mexican wave lapping the stadium
and a cue every 10 frames). The crowd is stepped to ``--frames`` (default 10,000),
keeping a snapshot every ``--every`` frames (K, default 30) over the last
``--window`` frames (a full shot at K = 30 would need ``frames / K`` snapshots: the
figure is printed, not allocated). Then it jumps to random frames of that window and
to the last frame, and measures each jump from the nearest snapshot, and once the
same last frame reached from the start (reset and step) as the baseline. Every jump
is checked against the straight run's poses. Then it exports ``--export-frames`` of
the show in one process and in chunks on a local Dask cluster of 1 and 2 workers
(snapshot pass, chunks, stitch; each stitched stage checked against the single
export). Prints the figures and ends with one JSON line (``seek_s_from_snapshot``:
the slowest jump, ``seek_s_median``, ``seek_s_from_start``, ``snapshot_bytes``,
``snapshot_ms``, ``restore_ms``, ``export_fps_single``, ``export_fps_1_worker``,
``export_fps_2_workers``; ``chunk_cpu_overhead``: the CPU of all processes of a
4-chunk export on 2 workers, stitch included, over the single export's CPU, and
``stitch_share``: the stitch task's CPU over that).

    .venv/bin/python benchmarks/scrub.py [--frames 10000] [--every 30] [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))

from core_frame import show_config  # noqa: E402

from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.shots.crowd_state import set_state  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=65_000)
    ap.add_argument("--frames", type=int, default=10_000, help="the frame to reach")
    ap.add_argument("--every", type=int, default=30, help="K: frames between snapshots")
    ap.add_argument("--window", type=int, default=300,
                    help="frames before the last where snapshots are kept")
    ap.add_argument("--jumps", type=int, default=20)
    ap.add_argument("--export-frames", type=int, default=120,
                    help="frames of the export throughput figures")
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
    restores = []
    for _ in range(5):
        t = time.perf_counter()
        set_state(crowd, cache.nearest(last).state())
        restores.append(time.perf_counter() - t)
    restore_ms = statistics.median(restores) * 1e3

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
    quarter = 62_688_894 // 4                 # a quarter of the arrays whole (issue 33)
    print(f"  one snapshot: {snap_bytes:,} B (target <= {quarter:,}, a quarter of the "
          f"62,688,894 B the arrays took whole: {'met' if snap_bytes <= quarter else 'NOT met'})")
    print(f"  one snapshot: {snap_bytes / 2**20:.1f} MiB, taken in "
          f"{statistics.median(t_snap) * 1e3:.0f} ms, restored in {restore_ms:.0f} ms; a "
          f"whole {frames:,}-frame shot at K = {args.every} would keep "
          f"{frames // args.every:,} of them ({frames // args.every * snap_bytes / 2**30:.1f} "
          f"GiB: the memory cap doubles K until they fit)")
    exp = export_throughput(args.agents, 20 if args.quick else args.export_frames)
    print(f"  export of {exp['frames']} frames of the same show ({exp['clip_agents']:,} agents "
          f"on value clips, {exp['bytes'] / 2**20:,.0f} MiB): single process "
          f"{exp['fps_single']:.2f} frames/s ({exp['s_single']:.1f} s); in chunks on a local "
          f"Dask cluster, stitched: 1 worker {exp['fps_1']:.2f} frames/s "
          f"({exp['s_1']:.1f} s), 2 workers {exp['fps_2']:.2f} frames/s ({exp['s_2']:.1f} s: "
          f"snapshots {exp['steps_2']['snapshots']:.1f}, chunks {exp['steps_2']['chunks']:.1f}, "
          f"stitch {exp['steps_2']['stitch']:.1f}); this machine has {os.cpu_count()} cores")
    t4 = exp["cpu_tasks_4"]
    print(f"  in {exp['chunks_4']} chunks on 2 workers: {exp['cpu_4_chunks']:.1f} s of CPU in "
          f"all processes against {exp['cpu_single']:.1f} s for the single export: "
          f"chunk_cpu_overhead {exp['chunk_cpu_overhead']:.2f} (target <= 1.3); tasks: "
          f"snapshots {t4['snapshots']:.1f} s, chunks {t4['chunks']:.1f} s, stitch "
          f"{t4['stitch']:.1f} s: stitch_share {exp['stitch_share']:.2f} (target <= 0.1)")
    print(json.dumps({
        "seek_s_from_snapshot": round(worst, 4),
        "seek_s_median": round(statistics.median(seeks), 4),
        "seek_s_from_start": round(from_start, 2),
        "snapshot_bytes": int(snap_bytes),
        "snapshot_ms": round(statistics.median(t_snap) * 1e3, 1),
        "restore_ms": round(restore_ms, 1),
        "every": args.every, "frames": frames, "agents": args.agents,
        "straight_run_s": round(straight_s, 1),
        "export_fps_single": round(exp["fps_single"], 3),
        "export_fps_1_worker": round(exp["fps_1"], 3),
        "export_fps_2_workers": round(exp["fps_2"], 3),
        "export_frames": exp["frames"],
        "chunk_cpu_overhead": round(exp["chunk_cpu_overhead"], 3),
        "stitch_share": round(exp["stitch_share"], 3),
    }))


def export_throughput(agents: int, frames: int) -> dict:
    """Frames per second of exporting ``frames`` frames of the show: one process
    (``crowd export``), then chunked on a local Dask cluster of 1 and of 2 workers,
    snapshots and stitch included (``crowd export --workers N``). Each stitched stage
    is checked against the single export's poses at a few frames."""
    import tempfile

    from crowd_addon.core.authoring.config_io import save_config
    from crowd_addon.core.authoring.synthetic import humanoid_mesh
    from crowd_addon.farm.chunks import export_chunk
    from crowd_addon.shot_source import ShotSource
    from crowd_addon.farm.cluster import farm_export
    cfg = show_config(agents, frames)
    cfg.add_mesh(humanoid_mesh(cfg.skeletons["fan"]), lods=())
    out = {"frames": frames}
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "crowd.json")
        save_config(cfg, path)
        source, span = ShotSource(config=path), (cfg.start_frame + 1, cfg.start_frame + frames)
        t, cpu = time.perf_counter(), time.process_time()
        _, single = export_chunk(source, span, os.path.join(tmp, "single", "shot.usdc"))
        out["s_single"] = time.perf_counter() - t
        out["cpu_single"] = time.process_time() - cpu
        out["bytes"], out["clip_agents"] = single.bytes, single.clip_agents
        for w in (1, 2):
            t = time.perf_counter()
            result = farm_export(source, os.path.join(tmp, f"w{w}", "shot.usdc"), span,
                                 workers=w)
            out[f"s_{w}"] = time.perf_counter() - t
            out[f"steps_{w}"] = result.seconds
            _same_poses(single.path, result.stitch.path, span)
        # four chunks on two workers: the CPU of every process (this one, and the
        # cluster's once it closed and its processes were waited for) over the single
        # export's, and the stitch's share of it
        cpu = time.process_time()
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        result = farm_export(source, os.path.join(tmp, "c4", "shot.usdc"), span, workers=2,
                             chunk_frames=-(-frames // 4))
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        total = time.process_time() - cpu + (after.ru_utime + after.ru_stime) \
            - (children.ru_utime + children.ru_stime)
        _same_poses(single.path, result.stitch.path, span)
        out["chunks_4"] = len(result.chunks)
        out["cpu_4_chunks"] = total
        out["cpu_tasks_4"] = result.cpu
        out["chunk_cpu_overhead"] = total / out["cpu_single"]
        out["stitch_share"] = result.cpu["stitch"] / total
    for k in ("single", "1", "2"):
        out[f"fps_{k}"] = frames / out[f"s_{k}"]
    return out


def _same_poses(a, b, span):
    """The stitched stage's joint transforms equal the single export's (1e-6) for 50
    agents at the first, middle and last frame."""
    from pxr import Usd, UsdSkel
    times = (span[0], (span[0] + span[1]) // 2, span[1])
    stages = [Usd.Stage.Open(p) for p in (a, b)]
    caches = [UsdSkel.Cache() for _ in stages]
    pred = Usd.TraverseInstanceProxies()
    for name in [p.GetName() for p in stages[0].GetPrimAtPath("/Crowd/Agents").GetChildren()][
            ::1300][:50]:
        got = []
        for stage, cache in zip(stages, caches):
            root = UsdSkel.Root(stage.GetPrimAtPath(f"/Crowd/Agents/{name}"))
            cache.Populate(root, pred)
            (binding,) = cache.ComputeSkelBindings(root, pred)
            query = cache.GetSkelQuery(binding.GetSkeleton())
            got.append(np.array([np.array(query.ComputeJointLocalTransforms(t))
                                 for t in times]))
        if np.abs(got[0] - got[1]).max() > 1e-6:
            raise AssertionError(f"stitched {name} differs from the single export")


if __name__ == "__main__":
    main()
