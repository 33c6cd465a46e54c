"""Procedural skeletons and clips for tests, benchmarks and demos without Blender.

The humanoid has the paper's 82 bones by default (spine, neck/head, two arms with
five three-bone fingers, two legs, plus face/extra bones to reach the count); the
clips are smooth periodic motions with exactly matching ends so they loop.
"""

from __future__ import annotations

import numpy as np

from . import pose as sqt
from . import quaternion as quat
from .clip import Clip
from .skeleton import Skeleton

__all__ = ["humanoid", "periodic_clip"]


def humanoid(name="fan", bones=82) -> Skeleton:
    """A depth-first humanoid skeleton of ``bones`` bones (at least 24)."""
    names, parents, offsets = [], [], []

    def add(n, parent, off):
        names.append(n)
        parents.append(parent)
        offsets.append(off)
        return len(names) - 1

    root = add("root", -1, (0, 0, 0))
    hips = add("hips", root, (0, 0, 1.0))
    spine = hips
    for i in range(3):
        spine = add(f"spine{i}", spine, (0, 0, 0.15))
    neck = add("neck", spine, (0, 0, 0.15))
    add("head", neck, (0, 0, 0.1))
    for side, sx in (("L", 1), ("R", -1)):
        sh = add(f"shoulder.{side}", spine, (sx * 0.08, 0, 0.1))
        up = add(f"upperarm.{side}", sh, (sx * 0.12, 0, 0))
        fo = add(f"forearm.{side}", up, (sx * 0.28, 0, 0))
        ha = add(f"hand.{side}", fo, (sx * 0.25, 0, 0))
        for f in range(5):
            p = ha
            for j in range(3):
                p = add(f"finger{f}_{j}.{side}", p, (sx * 0.03, 0.02 * (f - 2), 0))
    for side, sx in (("L", 1), ("R", -1)):
        th = add(f"thigh.{side}", hips, (sx * 0.1, 0, -0.05))
        sh = add(f"shin.{side}", th, (0, 0, -0.45))
        ft = add(f"foot.{side}", sh, (0, 0, -0.42))
        add(f"toe.{side}", ft, (0, 0.12, -0.05))
    head = names.index("head")
    i = 0
    while len(names) < bones:
        add(f"face{i}", head, (0.01 * (i % 5), 0.05, 0.02 * (i // 5)))
        i += 1
    names, parents, offsets = names[:bones], parents[:bones], offsets[:bones]
    bind = sqt.identity_pose(len(names))
    bind[:, sqt.TRANS] = offsets
    return Skeleton(name, names, parents, bind)


def periodic_clip(skeleton: Skeleton, name: str, frames=61, amplitude=0.6, seed=0, fps=30.0,
                  loop=True, events=(), bones=None) -> Clip:
    """A smooth looping clip: each bone swings about a random axis, period ``frames-1``.

    ``bones`` limits the motion to the given bone names (others keep the bind pose),
    e.g. the arms for a wave layer.
    """
    rng = np.random.default_rng(seed)
    b = skeleton.bone_count
    t = np.arange(frames) / (frames - 1) * 2 * np.pi
    axis = quat.normalize(rng.normal(size=(b, 4)))[:, 1:]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, b)
    amp = np.full(b, amplitude)
    if bones is not None:
        keep = np.isin(np.array(skeleton.bone_names), list(bones))
        amp = np.where(keep, amp, 0.0)
    angle = amp[None] * np.sin(t[:, None] + phase[None])            # (F, B)
    q = np.concatenate([np.cos(angle / 2)[..., None],
                        np.sin(angle / 2)[..., None] * axis[None]], axis=-1)
    keys = np.broadcast_to(skeleton.bind_pose, (frames, b, sqt.WIDTH)).astype(np.float64)
    keys = keys.copy()
    keys[..., sqt.ROT] = quat.multiply(keys[..., sqt.ROT], q)
    if bones is None or skeleton.bone_names[1] in bones:
        keys[:, 1, sqt.TRANS] += 0.05 * np.sin(t)[:, None] * np.array([0, 0, 1.0])
    keys[-1] = keys[0]
    return Clip(name, keys, fps=fps, loop=loop, events=events,
                bone_names=skeleton.bone_names)
