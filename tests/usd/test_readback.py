"""Read the exported shot back with pxr.UsdSkel and compare with core at the same frames.

UsdSkel evaluates the file on its own (composition of the offset references, instance
proxies, skel:animationSource inherited from the instance root, its own skinning); the
truth is core's evaluation of the same crowd driven by the same simulation (conftest).
"""

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdSkel

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.base.skinning import model_matrices, skin_vertices, skinning_matrices

from .conftest import DYNAMIC, FIRST, LAST, MOVING, make_config

RTOL = 1e-5
FRAMES = list(range(FIRST, LAST + 1))      # every time sample, both sides of every switch
STATIC = [0, 5, 10, 13, 21, 40, 45, 9]           # several streams and offsets, a kid
AGENTS = STATIC + sorted(DYNAMIC) + sorted(MOVING)


@pytest.fixture(scope="module")
def stage(shot):
    return Usd.Stage.Open(str(shot[1]))


@pytest.fixture(scope="module")
def bindings(stage):
    """agent id -> (SkelQuery, Skeleton instance proxy prim, [SkinningQuery]).

    Agents are instances, so the SkelQuery holds the prototype's Skeleton (shared)
    with the agent's own animation; the agent's transform is on the instance proxy
    Skeleton the binding names, whose local-to-world the tests apply."""
    cache = UsdSkel.Cache()
    pred = Usd.TraverseInstanceProxies()
    out = {}
    for a in AGENTS:
        prim = stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}")
        assert prim.IsInstance()
        root = UsdSkel.Root(prim)
        assert cache.Populate(root, pred)
        (binding,) = cache.ComputeSkelBindings(root, pred)
        skel = binding.GetSkeleton()
        assert skel.GetPrim().IsInstanceProxy()
        out[a] = (cache.GetSkelQuery(skel), skel.GetPrim(), binding.GetSkinningTargets())
    return out


def agent_matrix(position, heading, scale=1.0):
    c, s = np.cos(heading), np.sin(heading)
    m = np.eye(4)
    m[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) * scale
    m[:3, 3] = position
    return m


def to_world(xf_cache, prim):
    """(4, 4) column-vector local-to-world matrix of ``prim``."""
    return np.array(xf_cache.GetLocalToWorldTransform(prim)).T


def rel_err(actual, expected):
    return float(np.abs(actual - expected).max() / np.abs(expected).max())


def skeleton_of(agent):
    cfg = make_config()
    s, u = cfg.agent_stream[agent], cfg.agent_unique[agent]
    name = cfg.streams[s].skeleton if s >= 0 else cfg.uniques[u].skeleton
    return cfg.skeletons[name], cfg.meshes[name][0]


@pytest.mark.parametrize("frame", FRAMES)
def test_joint_transforms_match_core(bindings, oracle, frame):
    xf_cache = UsdGeom.XformCache(frame)
    for a in AGENTS:
        query, skel_prim, _ = bindings[a]
        skeleton, _ = skeleton_of(a)
        pose = oracle["poses"][frame][a:a + 1]
        local = np.array(query.ComputeJointLocalTransforms(frame)).transpose(0, 2, 1)
        expected_local = sqt.pose_to_matrices(pose[0, :skeleton.bone_count])
        assert rel_err(local, expected_local) < RTOL, (a, frame)
        # the prototype's world transforms are the instance's skeleton-space ones
        in_skel = np.array(query.ComputeJointWorldTransforms(xf_cache)).transpose(0, 2, 1)
        world = to_world(xf_cache, skel_prim) @ in_skel
        agent = agent_matrix(oracle["position"][frame][a], oracle["heading"][frame][a],
                             oracle["scale"][a])
        expected = agent @ model_matrices(pose, skeleton)[0]
        assert world.shape == expected.shape
        assert rel_err(world, expected) < RTOL, (a, frame)


@pytest.mark.parametrize("frame", FRAMES)
def test_skinned_points_match_core(bindings, oracle, frame):
    xf_cache = UsdGeom.XformCache(frame)
    for a in AGENTS:
        query, skel_prim, targets = bindings[a]
        skeleton, mesh = skeleton_of(a)
        (target,) = targets
        points = UsdGeom.Mesh(target.GetPrim()).GetPointsAttr().Get(frame)
        ok = target.ComputeSkinnedPoints(query.ComputeSkinningTransforms(frame), points,
                                         frame)
        assert ok
        skel_to_world = to_world(xf_cache, skel_prim)
        usd = np.asarray(points, np.float64) @ skel_to_world[:3, :3].T + skel_to_world[:3, 3]
        pose = oracle["poses"][frame][a:a + 1]
        core = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                             skinning_matrices(pose, skeleton))[0]
        agent = agent_matrix(oracle["position"][frame][a], oracle["heading"][frame][a],
                             oracle["scale"][a])
        core = core @ agent[:3, :3].T + agent[:3, 3]
        assert rel_err(usd, core) < RTOL, (a, frame)


def test_blends_split_over_several_banks_read_back_the_same(tmp_path, oracle, monkeypatch):
    """Banks hold at most ``BANK_FRAMES`` frames; with 3 the shot's blends fill several
    layers, and every agent that changes still reads core's pose at every frame."""
    from crowd_addon.usd import clips, export_crowd

    from .conftest import recording

    monkeypatch.setattr(clips, "BANK_FRAMES", 3)
    result = export_crowd(recording(), tmp_path / "banks.usda")
    banks = sorted(f for f in result.files if "/blends/" in f)
    assert len(banks) >= 3, banks
    stage = Usd.Stage.Open(str(result.path))
    cache, pred = UsdSkel.Cache(), Usd.TraverseInstanceProxies()
    for a in sorted(DYNAMIC):
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}"))
        cache.Populate(root, pred)
        (binding,) = cache.ComputeSkelBindings(root, pred)
        query = cache.GetSkelQuery(binding.GetSkeleton())
        skeleton, _ = skeleton_of(a)
        for frame in FRAMES:
            local = np.array(query.ComputeJointLocalTransforms(frame)).transpose(0, 2, 1)
            expected = sqt.pose_to_matrices(oracle["poses"][frame][a, :skeleton.bone_count])
            assert rel_err(local, expected) < RTOL, (a, frame)
