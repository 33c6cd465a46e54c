"""Looks in the USD export (issue 34, item 5): UsdSkel turns each looking agent's head
as core does, and the agents that look keep sharing what they play outside their looks.

The shot is conftest's (transitions, a queue, a cut, a unique, moves) with a look rig on
both characters and a ball moving across the crowd; agents start looking before and
during the shot, some through a transition, some look away, one starts on the last
frame. The oracle is core: ``Crowd.agent_rows`` of the same crowd run again, its head
forward (the chain's last bone's rotation of the rig's forward) in the agent's model
space. pxr's ``ComputeJointSkelTransforms`` gives the exported head, at every frame.
"""

import numpy as np
import pytest
from pxr import Usd, UsdSkel

from crowd_addon.core import Crowd
from crowd_addon.core.runtime.look_at import head_direction
from crowd_addon.core.shots.recorder import record

from .conftest import FIRST, LAST, make_config, simulate
from .look_shot import AGENTS, LOOKERS, QUIET, chains, core_heads, look_config, simulate_looks

@pytest.fixture(scope="module")
def truth():
    return core_heads()


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    from crowd_addon.usd import export_crowd
    d = tmp_path_factory.mktemp("looks")
    looked = record(Crowd(look_config(), skinning="gpu"), FIRST, LAST, before_step=simulate_looks)
    plain = record(Crowd(make_config(), skinning="gpu"), FIRST, LAST, before_step=simulate)
    (d / "looks").mkdir()
    (d / "plain").mkdir()
    return (export_crowd(looked, d / "looks" / "shot.usdc", repetition=None),
            export_crowd(plain, d / "plain" / "shot.usdc", repetition=None), looked)


def angle(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


def usd_heads(path, agents, frames, cfg):
    """{agent: (T, 3)} head forward from pxr UsdSkel's skeleton-space joint transforms."""
    stage = Usd.Stage.Open(str(path))
    cache, pred = UsdSkel.Cache(), Usd.TraverseInstanceProxies()
    skeletons = list(cfg.skeletons.values())
    ch = chains(cfg)
    names = {a: f"agent_{a:02d}" for a in agents}
    out = {}
    crowd_skel = Crowd(cfg).agent_skeleton
    for a in agents:
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/Crowd/Agents/{names[a]}"))
        assert cache.Populate(root, pred)
        (binding,) = cache.ComputeSkelBindings(root, pred)
        query = cache.GetSkelQuery(binding.GetSkeleton())
        k = int(crowd_skel[a])
        sk, c = skeletons[k], ch[k]
        f = []
        for t in frames:
            model = np.array([np.array(m).T for m in query.ComputeJointSkelTransforms(t)])
            rows = (model @ sk.inverse_bind)[None, :, :3, :]
            f.append(head_direction(rows, c)[1][0])
        out[a] = np.array(f)
    return out


def test_usdskel_heads_within_3_degrees_of_core_at_every_frame(truth, exports):
    heads, weights = truth
    looked, _, rec = exports
    frames = list(range(FIRST, LAST + 1))
    got = usd_heads(looked.path, AGENTS, frames, rec.config)
    worst = 0.0
    for a in AGENTS:
        want = np.array([heads[f][a] for f in frames])
        err = angle(got[a], want)
        worst = max(worst, err.max())
        assert err.max() < 3.0, (a, err.round(2))
    print(f"worst head direction error {worst:.4f} degrees")
    # control: the same shot exported without looks misses core's heads by far more
    _, plain, _ = exports
    bare = usd_heads(plain.path, LOOKERS, frames, rec.config)
    off = max(angle(bare[a], np.array([heads[f][a] for f in frames])).max() for a in LOOKERS)
    assert off > 20.0, off
    # the looks turned the heads: without them the head is elsewhere for the lookers
    w = np.array([[weights[f][a] for a in LOOKERS] for f in frames])
    assert (w > 0.99).sum() > 50 and (w == 0).sum() > 10


def test_looking_agents_are_on_clips_and_the_rest_unchanged(exports):
    looked, plain, rec = exports
    assert rec.looking[LOOKERS].all() and not rec.looking[QUIET].any()
    # every looker on clips (its looking frames in the banks), quiet ones as before
    assert looked.clip_agents == plain.clip_agents + len(
        set(LOOKERS) - {1, 2, 3, 12, 39})
    assert looked.blend_frames > plain.blend_frames
    # a blend while looking is aim frames (the blend with the look), not both
    assert 0 < looked.blend_frames - looked.aim_frames < plain.blend_frames
    assert (looked.look_agents, plain.look_agents, plain.aim_frames) == (len(LOOKERS), 0, 0)
    print(f"bytes: {plain.bytes} without looks, {looked.bytes} with "
          f"({looked.bytes / plain.bytes:.2f}x), aim frames "
          f"{looked.aim_frames}")
    assert looked.bytes <= 2 * plain.bytes
