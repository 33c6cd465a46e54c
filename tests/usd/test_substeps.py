"""Sub-frame samples in the export (``Crowd(..., substeps=N)``, ``crowd export
--substeps N``): pxr UsdSkel reads every agent's joints and skinned points at every
exported time, whole frames and the samples between them (also those just before and
after each value clip switch), equal to core's at that time: the same crowd, run again
frame by frame, read through ``view.agent_poses(sub=k)``."""

from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdSkel

from crowd_addon.core import Crowd
from crowd_addon.core.base import pose as sqt
from crowd_addon.core.shots.recorder import record
from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices

from .conftest import FAN_AGENTS, FIRST, KID_AGENTS, LAST, core_samples, make_config, simulate
from .test_layout import usdchecker
from .test_readback import rel_err, skeleton_of

N = 3
AGENTS = range(FAN_AGENTS + KID_AGENTS)          # every agent


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The shot with N samples a frame, its blends split over several banks."""
    from crowd_addon.usd import clips, export_crowd

    path = tmp_path_factory.mktemp("substeps") / "shot.usda"
    banks = clips.BANK_FRAMES
    clips.BANK_FRAMES = 20                   # several banks, split by samples
    try:
        rec = record(Crowd(make_config(), skinning="gpu", substeps=N), FIRST, LAST,
                     before_step=simulate)
        result = export_crowd(rec, path)
    finally:
        clips.BANK_FRAMES = banks
    return result, Usd.Stage.Open(str(path)), rec


def test_every_sample_reads_back_as_core(exported):
    result, stage, rec = exported
    truth = {f + k / N: s[0] for (f, k), s in core_samples(N).items()}
    assert sorted(truth) == rec.times.tolist()
    assert sum("/blends/" in f for f in result.files) >= 2
    cache, pred = UsdSkel.Cache(), Usd.TraverseInstanceProxies()
    between = 0
    for a in AGENTS:
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}"))
        assert cache.Populate(root, pred)
        (binding,) = cache.ComputeSkelBindings(root, pred)
        query = cache.GetSkelQuery(binding.GetSkeleton())
        (target,) = binding.GetSkinningTargets()
        skeleton, mesh = skeleton_of(a)
        for t in rec.times.tolist():
            pose = truth[t][a:a + 1]
            local = np.array(query.ComputeJointLocalTransforms(t)).transpose(0, 2, 1)
            expected = sqt.pose_to_matrices(pose[0, :skeleton.bone_count])
            assert rel_err(local, expected) < 1e-5, (a, t)
            points = target.GetPrim().GetAttribute("points").Get(t)
            assert target.ComputeSkinnedPoints(query.ComputeSkinningTransforms(t), points, t)
            core = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                                 skinning_matrices(pose, skeleton))[0]
            assert rel_err(np.asarray(points, np.float64), core) < 1e-5, (a, t)
            if t % 1:
                frame = int(t)
                near = np.abs(truth[t][a] - truth[frame][a]).max()
                between += near > 1e-4      # a sample between frames that is not its frame
    assert between > len(AGENTS)


def test_samples_between_frames_are_in_the_layers(exported):
    result, stage, rec = exported
    assert stage.GetRootLayer().customLayerData["crowd"]["substeps"] == N
    stream = next(f for f in result.files if "/streams/" in f)
    layer = Sdf.Layer.FindOrOpen(str(Path(result.path).parent / stream))
    times = layer.ListTimeSamplesForPath("/Animation.rotations")
    frames = rec.stream_frames
    assert list(times) == pytest.approx(
        (frames[:, None] + np.arange(N) / N).reshape(-1).tolist())
    assert usdchecker(stage) == []
