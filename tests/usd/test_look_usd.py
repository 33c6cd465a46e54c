"""Looks in the USD export (issue 34, item 5): UsdSkel turns each looking agent's head
as core does, and the agents that look keep sharing what they play outside their looks.

The shot is conftest's (transitions, a queue, a cut, a unique, moves) with a look rig on
both characters and a ball moving across the crowd; agents start looking before and
during the shot, some through a transition, some look away, one starts on the last
frame. The oracle is core: ``Crowd.agent_rows`` of the same crowd run again, its head
forward (the chain's last bone's rotation of the rig's forward) in the agent's model
space. pxr's ``ComputeJointSkelTransforms`` gives the exported head, at every frame.
"""

import math

import numpy as np
import pytest
from pxr import Usd, UsdSkel

from crowd_addon.core import Crowd
from crowd_addon.core.look_at import LookChain, LookRig, LookTarget, head_direction
from crowd_addon.core.recorder import record

from .conftest import FIRST, LAST, make_config, simulate

#: agents that look: 1, 2 through transitions, 3 to the unique, 39 on the unique from the
#: start, 7 moved, 41 a kid, 20 static then looking away, 12 starting on the last frame
LOOKERS = [1, 2, 3, 5, 7, 12, 20, 39, 41, 43]
QUIET = [0, 4, 6, 11]                   # no look: shared and clip agents as before
AGENTS = LOOKERS + QUIET


def look_config():
    cfg = make_config()
    frames = np.arange(40)
    path = np.c_[-12 + 0.8 * frames, np.full(40, -14.0), 1.0 + 0.05 * frames]
    cfg.look_rigs = {"fan": LookRig(("neck", "head"), (0.4, 0.6)),
                     "kid": LookRig(("spine2", "neck", "head"), yaw_limit=math.radians(80))}
    cfg.look_targets = {"ball": LookTarget("ball", 0, path, smoothing=2.0)}
    return cfg


def simulate_looks(crowd, frame):
    simulate(crowd, frame)
    if frame == 1:
        crowd.look_at([1, 2, 20, 39, 41], "ball", blend=0)       # looking at FIRST
    if frame == 3:
        crowd.look_at([3, 5, 7, 43], "ball", blend=3)             # 3 blends to the unique
    if frame == 8:
        crowd.look_away([20, 5], blend=2)
    if frame == 11:
        crowd.look_at([20], "ball", blend=1, hold=2)              # again, briefly
    if frame == LAST:
        crowd.look_at([12], "ball", blend=0)                      # on LAST only


def chains(cfg):
    return [LookChain(cfg.look_rigs[n], sk) if n in cfg.look_rigs else None
            for n, sk in cfg.skeletons.items()]


def core_heads():
    """{frame: (N, 3) head forward in each agent's model space} and the weights."""
    crowd = Crowd(look_config())
    ch = chains(crowd.config)
    out, weights = {}, {}
    while crowd.frame < LAST:
        simulate_looks(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame >= FIRST:
            rows = crowd.agent_rows().astype(np.float64)
            f = np.zeros((rows.shape[0], 3))
            for k, c in enumerate(ch):
                m = crowd.agent_skeleton == k
                f[m] = head_direction(rows[m], c)[1]
            out[crowd.frame] = f
            weights[crowd.frame] = crowd.looks.weights(crowd.frame, np.arange(rows.shape[0]))
    return out, weights


@pytest.fixture(scope="module")
def truth():
    return core_heads()


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    from crowd_addon.usd import export_crowd
    d = tmp_path_factory.mktemp("looks")
    looked = record(Crowd(look_config(), skinning="gpu"), FIRST, LAST, on_frame=simulate_looks)
    plain = record(Crowd(make_config(), skinning="gpu"), FIRST, LAST, on_frame=simulate)
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
    print(f"bytes: {plain.bytes} without looks, {looked.bytes} with "
          f"({looked.bytes / plain.bytes:.2f}x), aim frames "
          f"{looked.blend_frames - plain.blend_frames}")
    assert looked.bytes <= 2 * plain.bytes
