"""USD export cost at the paper's configuration, against per-agent baking.

256 streams (clips, 2-way blends, additive layers, state machines driven by
triggers), M = 60, 82 bones, 300 frames, synthetic clips and proxy mesh; a
simulation makes a small share of the crowd react three times in the shot (30-frame
blends to another stream), so those agents play value clips; and a transition-heavy
case (``transition_heavy``): every agent blends once, over 12 frames at a random frame,
to another stream.

Prints, for 2,000 and 65,000 agents (``--agents``): export time (the shot recorded
once, then written: simulate / author / write), peak memory, bytes, and bytes
relative to per-agent baked animation (each agent's own SkelAnimation over the
shot, at this exporter's bytes per animation-frame; target < 5 %), and the export's
process CPU (recording and writing) over the CPU of writing the same bytes as raw files
in the same process (``cpu_over_raw_write``, the 65,000-agent steady case at the top
level of the JSON and the transition-heavy case's under ``transition_heavy``; target
<= 8). Then the per-agent baseline: Blender's own ``bpy.ops.wm.usd_export`` of N
armatures sharing one skinned mesh, each playing its stream's baked action through
an NLA strip shifted by its offset (run in a child process; scaled per agent-frame),
and the ratios of time and bytes per agent. Ends with one JSON line.

    .venv/bin/python benchmarks/usd_export.py [--quick] [--agents N ...] [--frames F]
        [--heavy-agents N] [--blender-agents 24] [--blender-frames 60] [--react 0.005]
        [--keep DIR]

Each export runs in a child process of its own, so its peak memory (``peak_mb``) is
its own.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

from crowd_addon.core import CrowdConfig  # noqa: E402
from crowd_addon.core.authoring.synthetic import humanoid_mesh, paper_config  # noqa: E402

STREAMS, M, BONES, SLOTS, FRAMES = 256, 60, 82, 800, 300
FIRST = 1
REACT_AT = (60, 150, 240)            # shot-relative frames of the crowd's reactions
HEAVY_BLEND = 12                     # the transition-heavy case: 12-frame blends, and
HEAVY_SLOTS = 4096                   # slots for the ~2,600 agents blending at once


def build(agents: int, streams: int = STREAMS) -> CrowdConfig:
    """The paper's configuration with ``agents`` agents seated on a stadium grid."""
    cfg = paper_config(0, streams, M, SLOTS, BONES)
    cfg.add_mesh(humanoid_mesh(cfg.skeletons["fan"]), lods=())
    cols = int(np.ceil(np.sqrt(agents * 4)))
    k = np.arange(agents)
    pos = np.stack([(k % cols) * 0.8, (k // cols) * 0.9, (k // cols) * 0.4], 1)
    cfg.add_agents(agents, positions=pos, headings=np.full(agents, np.pi / 2))
    cfg.start_frame = FIRST
    return cfg


def reactions(share: float, seed: int = 7):
    """``before_step``: at each REACT_AT frame ``share`` of the agents blend to another
    stream over 30 frames; state machines get ``goal`` and later ``calm``."""
    rng = np.random.default_rng(seed)

    def before_step(crowd, frame):
        rel = frame - FIRST
        n, streams = crowd.view.agent_count, len(crowd.view.stream_names)
        if rel in REACT_AT and share > 0:
            who = rng.choice(n, max(1, int(n * share)), replace=False)
            crowd.transition_to_streamed(who, int(rng.integers(streams)), 30)
        if rel in (100, 200):
            for s in range(3, streams, 4):
                crowd.set_trigger(s, "goal" if rel == 100 else "calm")
    return before_step


def every_agent_once(agents: int, frames: int, seed: int = 11):
    """``before_step``: every agent blends once to another stream over
    :data:`HEAVY_BLEND` frames, at a random frame of the shot."""
    rng = np.random.default_rng(seed)
    when = rng.integers(0, frames, agents)
    order = np.argsort(when, kind="stable")
    starts = np.searchsorted(when[order], np.arange(frames + 1))

    def before_step(crowd, frame):
        rel = frame - FIRST
        if 0 <= rel < frames and starts[rel] < starts[rel + 1]:
            who = np.sort(order[starts[rel]:starts[rel + 1]])
            now = crowd.view.agents.ref[who]
            crowd.transition_to_streamed(who, (now + 1 + rng.integers(0, STREAMS - 1, who.size))
                                         % STREAMS, HEAVY_BLEND)
    return before_step


def run_case(case: str, agents: int, frames: int, react: float, directory: str) -> dict:
    """One export in a child process, so its peak memory is its own."""
    run = subprocess.run([sys.executable, __file__, "--export-worker", case, str(agents),
                          str(frames), str(react), directory],
                         capture_output=True, text=True, timeout=3000)
    if run.returncode != 0:
        raise RuntimeError(f"export {case} failed ({run.returncode}):\n"
                           f"{run.stdout[-2000:]}{run.stderr[-3000:]}")
    return json.loads(run.stdout.strip().splitlines()[-1])


def run_export(case: str, agents: int, frames: int, react: float, directory: str) -> dict:
    """Record the shot once (a crowd that skins nothing) and write it: ``steady`` (a
    share of the crowd reacts three times) or ``transition_heavy`` (every agent blends
    once, :func:`every_agent_once`, with slots enough that none waits)."""
    from crowd_addon.core import Crowd
    from crowd_addon.core.shots.recorder import record
    from crowd_addon.usd import export_crowd

    cfg = build(agents)
    if case == "transition_heavy":
        cfg.transition_slots = HEAVY_SLOTS
        before_step = every_agent_once(agents, frames)
    else:
        before_step = reactions(react)
    t, cpu = time.perf_counter(), time.process_time()
    shot = record(Crowd(cfg, skinning="gpu"), FIRST, FIRST + frames - 1, before_step=before_step)
    cpu_export = time.process_time()
    r = export_crowd(shot, os.path.join(directory, "shot.usdc"))
    seconds = time.perf_counter() - t
    cpu_export, cpu = time.process_time() - cpu_export, time.process_time() - cpu
    raw_cpu = raw_write_cpu(r.files, os.path.join(directory, "raw"))
    stream_bytes = sum(v for k, v in r.files.items() if "/streams/" in k)
    per_anim_frame = stream_bytes / (r.stream_animations * (frames + M - 1))
    per_agent_baked = per_anim_frame * frames * agents
    return {"case": case, "agents": agents, "frames": frames, "seconds": seconds,
            "simulate_s": r.seconds["simulate"], "author_s": r.seconds["author"],
            "write_s": r.seconds["write"], "bytes": r.bytes, "files": len(r.files),
            "shared_agents": r.shared_agents, "clip_agents": r.clip_agents, "blend_frames": r.blend_frames,
            "offset_animations": r.offset_animations,
            "stream_animations": r.stream_animations,
            "bytes_per_animation_frame": per_anim_frame,
            "per_agent_baked_bytes": per_agent_baked,
            "bytes_vs_per_agent_baked": r.bytes / per_agent_baked,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "cpu_s": cpu, "cpu_export_s": cpu_export, "raw_write_cpu_s": raw_cpu,
            "cpu_over_raw_write": cpu / raw_cpu}


def raw_write_cpu(files: dict, directory: str) -> float:
    """Process CPU seconds of writing ``files`` (name -> bytes) again as plain files of
    the same sizes under ``directory`` (the bytes from a buffer made beforehand), then
    removed: what the export's bytes cost to write with no USD at all."""
    os.makedirs(directory, exist_ok=True)
    block = np.random.default_rng(0).integers(0, 256, 1 << 24, np.uint8).tobytes()
    t = time.process_time()
    for i, size in enumerate(files.values()):
        with open(os.path.join(directory, f"{i}.bin"), "wb") as f:
            left = int(size)
            while left > 0:
                n = min(left, len(block))
                f.write(block[:n] if n < len(block) else block)
                left -= n
    cpu = time.process_time() - t
    shutil.rmtree(directory)
    return max(cpu, 1e-6)


# ---------------------------------------------------------------- Blender baseline
def blender_baseline(agents: int, frames: int, directory: str) -> dict:
    """Bake the streams the first ``agents`` agents play (core, this process), then
    time Blender's exporter on them in a child process (bpy's own pxr)."""
    from crowd_addon.core import Crowd
    from crowd_addon.core.shots.recorder import record

    cfg = build(agents, streams=agents)          # one stream each: no sharing to help it
    last = FIRST + frames - 1
    shot = record(Crowd(cfg, skinning="gpu"), FIRST, last)
    _, stream, offset = shot.playing(FIRST)
    sk = cfg.skeletons["fan"]
    mesh = cfg.meshes["fan"][0]
    npz = os.path.join(directory, "baseline.npz")
    np.savez(npz, stream_poses=shot.stream_poses, stream=stream, offset=offset,
             position=shot.position, heading=shot.heading, parents=sk.parents,
             bind_model=sk.bind_model, bind_pose=sk.bind_pose,
             names=np.array(sk.bone_names), positions=mesh.positions,
             triangles=mesh.triangles, bone_indices=mesh.bone_indices,
             bone_weights=mesh.bone_weights, frames=np.array([FIRST, last, M]))
    out = os.path.join(directory, "blender.usdc")
    run = subprocess.run([sys.executable, __file__, "--blender-worker", npz, out],
                         capture_output=True, text=True, timeout=3000)
    if run.returncode != 0:
        raise RuntimeError(f"Blender baseline failed ({run.returncode}):\n"
                           f"{run.stdout[-2000:]}{run.stderr[-3000:]}")
    res = json.loads(run.stdout.strip().splitlines()[-1])
    res.update(agents=agents, frames=frames,
               s_per_agent_frame=res["export_s"] / (agents * frames),
               bytes_per_agent_frame=res["bytes"] / (agents * frames))
    return res


def blender_worker(npz_path: str, out: str) -> None:
    """Child process: build the scene in bpy and run ``bpy.ops.wm.usd_export``."""
    import bpy
    from bpy_extras.anim_utils import action_ensure_channelbag_for_slot

    d = np.load(npz_path)
    first, last, m = (int(x) for x in d["frames"])
    names = [str(n) for n in d["names"]]
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = first, last
    t0 = time.perf_counter()
    arm_data = bpy.data.armatures.new("fan")
    setup = bpy.data.objects.new("setup", arm_data)
    scene.collection.objects.link(setup)
    bpy.context.view_layer.objects.active = setup
    bpy.ops.object.mode_set(mode="EDIT")
    heads = d["bind_model"][:, :3, 3]
    for i, n in enumerate(names):          # synthetic humanoid: bind rotations are identity
        b = arm_data.edit_bones.new(n)
        b.head, b.tail = heads[i], heads[i] + (0, 0.05, 0)
        if d["parents"][i] >= 0:
            b.parent = arm_data.edit_bones[names[d["parents"][i]]]
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.data.objects.remove(setup)
    me = bpy.data.meshes.new("body")
    me.from_pydata(d["positions"].tolist(), [], d["triangles"].tolist())
    body = bpy.data.objects.new("template", me)
    for n in names:
        body.vertex_groups.new(name=n)
    for v, (idx, w) in enumerate(zip(d["bone_indices"], d["bone_weights"])):
        for b, wb in zip(idx.tolist(), w.tolist()):
            if wb > 0:
                body.vertex_groups[b].add([v], wb, "ADD")
    actions = {}
    rest_t = d["bind_pose"][:, 7:10]
    for s in np.unique(d["stream"]).tolist():           # one baked action per stream
        act = bpy.data.actions.new(f"stream{s}")
        slot = act.slots.new(id_type="OBJECT", name="agent")
        act.layers.new("bake").strips.new(type="KEYFRAME")
        bag = action_ensure_channelbag_for_slot(act, slot)
        poses = d["stream_poses"][:, s]                  # (T + M - 1, B, 10)
        times = np.arange(poses.shape[0], dtype=np.float32)
        for i, n in enumerate(names):
            for path, cols, base in (("location", range(7, 10), rest_t[i]),
                                     ("rotation_quaternion", range(3, 7), None)):
                for j, c in enumerate(cols):
                    fc = bag.fcurves.new(f'pose.bones["{n}"].{path}', index=j)
                    vals = poses[:, i, c] - (base[j] if base is not None else 0)
                    fc.keyframe_points.add(times.size)
                    fc.keyframe_points.foreach_set(
                        "co", np.stack([times, vals], 1).astype(np.float32).ravel())
        actions[s] = act
    for a, (s, o) in enumerate(zip(d["stream"].tolist(), d["offset"].tolist())):
        arm = bpy.data.objects.new(f"agent{a}", arm_data)
        arm.location = d["position"][a]
        arm.rotation_euler[2] = float(d["heading"][a])
        scene.collection.objects.link(arm)
        body_a = bpy.data.objects.new(f"agent{a}_body", me)
        body_a.parent = arm
        body_a.modifiers.new("skin", "ARMATURE").object = arm
        scene.collection.objects.link(body_a)
        strip = arm.animation_data_create().nla_tracks.new().strips.new(
            f"s{s}", first - m + 1 + o, actions[s])
        assert strip.action_slot is not None          # the action's one slot
    setup_s = time.perf_counter() - t0
    t = time.perf_counter()
    bpy.ops.wm.usd_export(filepath=out, export_animation=True, export_armatures=True,
                          export_meshes=True, export_materials=False,
                          use_instancing=False, selected_objects_only=False)
    export_s = time.perf_counter() - t
    print(json.dumps({"setup_s": setup_s, "export_s": export_s,
                      "bytes": os.path.getsize(out)}))


# ---------------------------------------------------------------------------- main
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke run: 2k agents, 30 frames")
    ap.add_argument("--agents", type=int, nargs="+", default=[2000, 65000], metavar="N",
                    help="crowd sizes to export (default: 2000 65000)")
    ap.add_argument("--frames", type=int, default=FRAMES,
                    help=f"shot length (default {FRAMES})")
    ap.add_argument("--react", type=float, default=0.005,
                    help="share of agents reacting at each of 3 moments (default 0.5%%)")
    ap.add_argument("--blender-agents", type=int, default=24)
    ap.add_argument("--blender-frames", type=int, default=60)
    ap.add_argument("--keep", metavar="DIR", help="write the exports here and keep them")
    ap.add_argument("--heavy-agents", type=int, default=65000, metavar="N",
                    help="agents of the transition-heavy case (default 65000; 0 skips it)")
    ap.add_argument("--blender-worker", nargs=2, help=argparse.SUPPRESS)
    ap.add_argument("--export-worker", nargs=5, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.blender_worker:
        blender_worker(*args.blender_worker)
        return
    if args.export_worker:
        case, agents, frames, react, directory = args.export_worker
        print(json.dumps(run_export(case, int(agents), int(frames), float(react), directory)))
        return
    sizes = [("steady", 2000, 30)] if args.quick else \
        [("steady", n, args.frames) for n in args.agents]
    if args.heavy_agents:
        sizes.append(("transition_heavy", 2000 if args.quick else args.heavy_agents,
                      30 if args.quick else args.frames))
    base = args.keep or tempfile.mkdtemp(prefix="usd_bench_")
    exports = []
    try:
        for case, agents, frames in sizes:
            d = os.path.join(base, f"{case}_{agents}")
            os.makedirs(d, exist_ok=True)
            r = run_case(case, agents, frames, args.react, d)
            exports.append(r)
            print(f"{case:>16} {agents:>6,} agents x {frames} frames: {r['seconds']:6.1f} s "
                  f"(simulate {r['simulate_s']:.1f}, author {r['author_s']:.1f}, write "
                  f"{r['write_s']:.1f}), {r['bytes'] / 1e6:8.1f} MB, "
                  f"{r['clip_agents']:,} agents on clips ({r['blend_frames']:,} blend frames), "
                  f"{r['offset_animations']:,} offset animations, peak RSS "
                  f"{r['peak_rss_mb'] / 1e3:.2f} GB; CPU {r['cpu_s']:.1f} s ({r['cpu_export_s']:.1f} "
                  f"s exporting) against {r['raw_write_cpu_s']:.2f} s to write its bytes as "
                  f"raw files: {r['cpu_over_raw_write']:.1f}x (target <= 8); "
                  f"{100 * r['bytes_vs_per_agent_baked']:.2f} % of per-agent baked "
                  f"({r['per_agent_baked_bytes'] / 1e9:.1f} GB)", flush=True)
            if not args.keep:
                shutil.rmtree(d)
        bb = blender_baseline(args.blender_agents, args.blender_frames, base)
        print(f"Blender usd_export: {bb['agents']} armatures x {bb['frames']} frames in "
              f"{bb['export_s']:.1f} s (+{bb['setup_s']:.1f} s scene setup), "
              f"{bb['bytes'] / 1e6:.1f} MB: {1e3 * bb['s_per_agent_frame']:.3f} ms and "
              f"{bb['bytes_per_agent_frame']:,.0f} B per agent-frame", flush=True)
    finally:
        if not args.keep:
            shutil.rmtree(base, ignore_errors=True)
    for r in exports:
        af = r["agents"] * r["frames"]
        r["time_per_agent_vs_blender"] = (r["seconds"] / af) / bb["s_per_agent_frame"]
        r["bytes_per_agent_vs_blender"] = (r["bytes"] / af) / bb["bytes_per_agent_frame"]
        r["blender_estimate_s"] = bb["s_per_agent_frame"] * af
        print(f"{r['agents']:>6,} agents: per agent {r['time_per_agent_vs_blender']:.4f}x "
              f"Blender's time (it would take ~{r['blender_estimate_s'] / 3600:.1f} h) and "
              f"{r['bytes_per_agent_vs_blender']:.4f}x its bytes")
    big = [r for r in exports if r["agents"] == 65000 and r["case"] == "steady"]
    heavy = [r for r in exports if r["case"] == "transition_heavy"]
    figures = {"config": {"streams": STREAMS, "M": M, "bones": BONES, "frames": FRAMES,
                          "react_share": args.react, "heavy_blend": HEAVY_BLEND,
                          "heavy_slots": HEAVY_SLOTS},
               "exports": exports, "blender_baseline": bb,
               "cpu_over_raw_write": round(big[0]["cpu_over_raw_write"], 2) if big else None,
               "target_65k_under_60s": bool(big and big[0]["seconds"] < 60),
               "target_bytes_under_5pct": bool(big and big[0]["bytes_vs_per_agent_baked"]
                                               < 0.05)}
    if heavy:
        h = heavy[0]
        figures["transition_heavy"] = {
            "agents": h["agents"], "frames": h["frames"], "seconds": round(h["seconds"], 2),
            "bytes": h["bytes"], "bytes_vs_per_agent_baked": h["bytes_vs_per_agent_baked"],
            "peak_mb": round(h["peak_rss_mb"], 1), "clip_agents": h["clip_agents"],
            "blend_frames": h["blend_frames"],
            "cpu_over_raw_write": round(h["cpu_over_raw_write"], 2)}
        print(f"transition heavy: {h['agents']:,} agents each blending once over "
              f"{HEAVY_BLEND} frames: {h['seconds']:.1f} s (target <= 10 s), "
              f"{100 * h['bytes_vs_per_agent_baked']:.2f} % of per-agent baking (target "
              f"<= 6 %), peak {h['peak_rss_mb']:.0f} MB")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
