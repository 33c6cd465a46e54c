"""Bake speed: Blender actions -> core clips, against a ``scene.frame_set`` loop.

Two kinds of action, on the armatures they were made for:

- motion capture: the CMU BVH files of Debian's ``assimp-testmodels``
  (``/usr/share/assimp/models/BVH``), imported with Blender's BVH importer (every
  bone keyed on every frame, Euler, linear);
- hand-keyed: the core's 82-bone humanoid as a Blender armature (rolled bones) with
  quaternion Bezier keys every 5 frames over 120 frames, as an animator's cycles.

For each action: the bake (``bake_actions``, F-curve path), the baseline (the action
assigned, then for each of the same frames ``scene.frame_set`` and every
``pose.bones[name].matrix`` read), and the complete frame_set bake (the same clips
obtained by sampling, ``method="frame_set"``). Times are the best of ``--repeats``
runs (the machine is shared). The fast and sampled clips are compared as a check.
Prints a table and ends with one JSON line; the target ratio is 10x.

    .venv/bin/python benchmarks/bake.py [--repeats 5] [--quick]
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import bpy  # noqa: E402
from bpy_extras import anim_utils  # noqa: E402

from crowd_addon.blender.bake import bake_actions  # noqa: E402
from crowd_addon.core.base.skinning import model_matrices  # noqa: E402
from crowd_addon.core.authoring.synthetic import humanoid  # noqa: E402

BVH_DIR = "/usr/share/assimp/models/BVH"


def best(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def frame_set_loop(scene, obj, action, slot, frames):
    """The baseline: play the action and read every bone's pose matrix per frame."""
    ad = obj.animation_data
    ad.action, ad.action_slot = action, slot
    bones = obj.pose.bones
    for f in frames:
        scene.frame_set(int(f))
        [pb.matrix for pb in bones]


def bvh_armature(path):
    """A fresh scene holding only the armature Blender's BVH importer makes of ``path``."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=path)
    obj = bpy.context.object
    return "mocap", obj, [obj.animation_data.action]


def humanoid_armature(actions, seed=0):
    """A fresh scene holding the core humanoid as an armature with ``actions``
    hand-keyed Bezier actions."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    sk = humanoid("fan", 82)
    heads = sk.bind_model[:, :3, 3]
    data = bpy.data.armatures.new("Fan")
    obj = bpy.data.objects.new("Fan", data)
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    rng = np.random.default_rng(seed)
    for i, name in enumerate(sk.bone_names):
        eb = data.edit_bones.new(name)
        eb.head = heads[i]
        eb.tail = heads[i] + (0, 0, 0.08)
        eb.roll = float(rng.uniform(-3, 3))
        if sk.parents[i] >= 0:
            eb.parent = data.edit_bones[sk.bone_names[sk.parents[i]]]
    bpy.ops.object.mode_set(mode="OBJECT")
    frames = np.arange(1, 122, 5, dtype=np.float32)
    made = []
    for a in range(actions):
        action = bpy.data.actions.new(f"cycle{a}")
        slot = action.slots.new("OBJECT", "Fan")
        bag = anim_utils.action_ensure_channelbag_for_slot(action, slot)
        for name in sk.bone_names:
            q = rng.normal(0, 0.3, (len(frames), 4))
            q[:, 0] += 1
            q[-1] = q[0]
            for c in range(4):
                fc = bag.fcurves.new(f'pose.bones["{name}"].rotation_quaternion', index=c)
                fc.keyframe_points.add(len(frames))
                fc.keyframe_points.foreach_set("co", np.stack([frames, q[:, c]], 1).ravel())
                fc.update()
        for c in range(3):
            fc = bag.fcurves.new('pose.bones["root"].location', index=c)
            fc.keyframe_points.add(len(frames))
            fc.keyframe_points.foreach_set(
                "co", np.stack([frames, rng.normal(0, 0.05, len(frames))], 1).ravel())
            fc.update()
        made.append(action)
    ad = obj.animation_data_create()
    ad.action, ad.action_slot = made[0], made[0].slots[0]
    return "hand-keyed", obj, made


def max_model_error(a, b):
    """Largest difference of the two bakes' model matrices over all keys, relative to
    the skeleton's extent."""
    err = 0.0
    for ca, cb in zip(a.clips, b.clips):
        t = np.arange(ca.frame_count, dtype=np.float64)
        ma = model_matrices(ca.sample(t), a.skeleton)
        mb = model_matrices(cb.sample(t), b.skeleton)
        err = max(err, float(np.abs(ma - mb).max() / max(1.0, np.abs(mb[..., :3, 3]).max())))
    return err


def measure(kind, obj, actions, repeats):
    """Bake all ``actions`` of ``obj`` in one call (as the bake operator does) against
    the frame_set loop over the same frames, and the frame_set bake once."""
    scene = bpy.context.scene
    fps = scene.render.fps / scene.render.fps_base
    frames = [np.arange(a.frame_range[0], a.frame_range[1] + 1) for a in actions]
    bake_s, fast = best(lambda: bake_actions(obj, actions, fps), repeats)

    def loop():
        for action, f in zip(actions, frames):
            frame_set_loop(scene, obj, action, action.slots[0], f)
    loop_s, _ = best(loop, repeats)
    fs_s, slow = best(lambda: bake_actions(obj, actions, fps, method="frame_set"), 1)
    assert set(fast.methods.values()) == {"fcurves"}
    return dict(kind=kind, armature=obj.name, actions=len(actions),
                bones=len(obj.pose.bones), frames=int(sum(len(f) for f in frames)),
                bake_s=bake_s, frame_set_loop_s=loop_s, frame_set_bake_s=fs_s,
                ratio=loop_s / bake_s, max_rel_error=max_model_error(fast, slow))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="one BVH file, one hand-keyed action")
    args = ap.parse_args(argv)
    files = sorted(glob.glob(os.path.join(BVH_DIR, "*.bvh")))[: 1 if args.quick else None]
    builders = [lambda p=p: bvh_armature(p) for p in files]
    builders.append(lambda: humanoid_armature(1 if args.quick else 4))
    rows = []
    print(f"{'kind':11s} {'armature':12s} {'actions':>7s} {'bones':>5s} {'frames':>6s} "
          f"{'bake ms':>8s} {'loop ms':>8s} {'ratio':>6s} {'fs bake ms':>10s} {'error':>8s}")
    for build in builders:
        r = measure(*build(), args.repeats)
        rows.append(r)
        print(f"{r['kind']:11s} {r['armature']:12s} {r['actions']:7d} {r['bones']:5d} "
              f"{r['frames']:6d} {r['bake_s'] * 1e3:8.1f} {r['frame_set_loop_s'] * 1e3:8.1f} "
              f"{r['ratio']:6.1f} {r['frame_set_bake_s'] * 1e3:10.1f} "
              f"{r['max_rel_error']:8.1e}")
    bake = sum(r["bake_s"] for r in rows)
    loop = sum(r["frame_set_loop_s"] for r in rows)
    fs = sum(r["frame_set_bake_s"] for r in rows)
    print(f"total: bake {bake * 1e3:.1f} ms, frame_set loop {loop * 1e3:.1f} ms "
          f"({loop / bake:.1f}x), frame_set bake {fs * 1e3:.1f} ms ({fs / bake:.1f}x); "
          f"lowest ratio {min(r['ratio'] for r in rows):.1f}x (target 10x)")
    print(json.dumps(dict(
        benchmark="bake", blender=bpy.app.version_string, armatures=len(rows),
        actions=sum(r["actions"] for r in rows), frames=sum(r["frames"] for r in rows),
        bake_s=round(bake, 5), frame_set_loop_s=round(loop, 5), frame_set_bake_s=round(fs, 5),
        ratio=round(loop / bake, 2), min_ratio=round(min(r["ratio"] for r in rows), 2),
        ratio_vs_frame_set_bake=round(fs / bake, 2), target_ratio=10,
        max_rel_error=float(f"{max(r['max_rel_error'] for r in rows):.3g}"),
        per_armature=[{k: float(f"{v:.4g}") if isinstance(v, float) else v
                       for k, v in r.items()} for r in rows])))


if __name__ == "__main__":
    main()
