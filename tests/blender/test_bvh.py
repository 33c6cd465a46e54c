"""Real motion capture: CMU BVH (Debian's assimp-testmodels) imported with Blender's BVH
importer, baked, and every bone's model matrix compared with Blender's pose.

The importer keys every bone on every frame (Euler ZYX, linear), so the bake reads
key values only. Subframes are compared on a bake at 2x the scene fps (keys at half
frames), at frames ``F - O`` for a few agent offsets ``O`` as the crowd samples them.
Tolerance: 2e-7 of the skeleton's extent (the file is in centimetre-like units, so
float32 rounding on both sides scales with it).
"""

import os

import numpy as np
import pytest

from crowd_addon.blender.bake import bake_actions
from crowd_addon.core.anim.clip import ClipBank
from crowd_addon.core.base.skinning import model_matrices

BVH = "/usr/share/assimp/models/BVH/01_01.bvh"


@pytest.mark.skipif(not os.path.exists(BVH), reason="needs Debian's assimp-testmodels")
def test_cmu_bvh_matches_blender(scene, blend):
    bpy = blend.bpy
    bpy.ops.import_anim.bvh(filepath=BVH)
    obj = bpy.context.object
    action = obj.animation_data.action
    result = bake_actions(obj, [action], fps=scene.render.fps * 2)
    assert result.methods == {action.name: "fcurves"}
    clip = result.clips[0]
    start, end = action.frame_range
    assert clip.frame_count == 2 * (end - start) + 1
    names = result.skeleton.bone_names
    bank = ClipBank(result.clips)
    frames = np.array([1, 2, 600, 1377.5, 2751.5, 2752])
    offsets = np.array([0, 1, 30.5])
    want, times = [], []
    for f in frames:
        for o in offsets:
            if f - o >= start:
                want.append(blend.pose_at(scene, obj, names, f - o))
                times.append((f - o - start) * 2)
    want = np.array(want)
    got = model_matrices(bank.sample(np.zeros(len(times), np.int64), np.array(times)),
                         result.skeleton)
    extent = np.abs(want[..., :3, 3]).max()
    assert extent > 10
    assert np.abs(got - want).max() < 2e-7 * extent
