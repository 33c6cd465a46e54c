"""Controller trees evaluated through TreeEvaluator, checked against direct clip math."""

import numpy as np
import pytest
from types import SimpleNamespace

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.base import quaternion as quat
from crowd_addon.core.anim.clip import Clip, ClipBank
from crowd_addon.core.anim.blends import (Blend2, BlendMask, BlendSpace2D, Layer,
                                          blend_space_weights)
from crowd_addon.core.anim.controllers import ClipPlayer
from crowd_addon.core.anim.state_machine import StateMachine, StateTransition
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.anim.graph import TreeEvaluator
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

ROT, TRANS = sqt.ROT, sqt.TRANS
SK = humanoid()                 # 82 bones: head, arms and legs
B = SK.bone_count
WALK = periodic_clip(SK, "walk", frames=41, seed=1)
RUN = periodic_clip(SK, "run", frames=25, seed=2, amplitude=0.9)
IDLE = periodic_clip(SK, "idle", frames=61, seed=3, amplitude=0.2)
CLIPS = [WALK, RUN, IDLE]


def make(roots, clips=CLIPS, bones=B):
    """roots: controllers (on SK) or (controller, skeleton) pairs."""
    roots = [r if isinstance(r, tuple) else (r, SK) for r in roots]
    return TreeEvaluator(roots, ClipBank(clips, bones), bones)


def run(ev, t):
    ev.prepare(np.full(len(ev.root_index), float(t)))
    ev.evaluate()
    return ev.root_poses().copy()


def assert_pose_close(p, ref, atol=2e-6):
    p = np.asarray(p, np.float64)
    ref = np.asarray(ref, np.float64)
    np.testing.assert_allclose(p[..., :3], ref[..., :3], atol=atol)
    np.testing.assert_allclose(p[..., TRANS], ref[..., TRANS], atol=atol)
    d = np.minimum(np.abs(p[..., ROT] - ref[..., ROT]).max(-1),
                   np.abs(p[..., ROT] + ref[..., ROT]).max(-1))
    assert d.max() <= atol, f"rotation distance {d.max()}"


def static_clip(name, translation, angle):
    """Two equal keys: bind pose, root at ``translation``, every bone turned ``angle`` about z."""
    keys = np.broadcast_to(SK.bind_pose, (2, B, 10)).astype(np.float64).copy()
    keys[:, 0, TRANS] = translation
    keys[..., ROT] = quat.multiply(keys[..., ROT], [np.cos(angle / 2), 0, 0, np.sin(angle / 2)])
    return Clip(name, keys, bone_names=SK.bone_names)


# ------------------------------------------------------------------ ClipPlayer

def test_clip_player_equals_clip_sample():
    specs = [("walk", 1.0, 0.0), ("walk", 0.5, 7.0), ("run", 2.3, -4.0), ("idle", -1.0, 3.0)]
    ev = make([ClipPlayer(c, speed=s, start=st) for c, s, st in specs])
    clip = {c.name: c for c in CLIPS}
    for t in (0.0, 1.0, 13.4, 97.25):
        out = run(ev, t)
        for r, (c, s, st) in enumerate(specs):
            assert_pose_close(out[r], clip[c].sample(st + s * t), atol=1e-6)


# ---------------------------------------------------------------------- Blend2

def test_blend2_endpoints_and_midpoint():
    ev = make([Blend2(ClipPlayer("walk"), ClipPlayer("run"), w) for w in (0.0, 1.0, 0.5, 0.2)])
    for t in (0.0, 5.5, 31.0):
        out = run(ev, t)
        a, b = WALK.sample(t), RUN.sample(t)
        assert_pose_close(out[0], a, atol=1e-6)
        assert_pose_close(out[1], b, atol=1e-6)
        assert_pose_close(out[2], sqt.blend2(a, b, 0.5), atol=1e-6)
        assert_pose_close(out[3], sqt.blend2(a, b, 0.2), atol=1e-6)
        assert np.abs(out[2] - a).max() > 1e-2            # the blend is not a child


def test_blend2_weight_bound_to_parameter():
    ev = make([Blend2(ClipPlayer("walk"), ClipPlayer("idle"), "speed")] * 1)
    t = 8.25
    a, b = WALK.sample(t), IDLE.sample(t)
    assert_pose_close(run(ev, t), a[None], atol=1e-6)          # unset parameter -> 0
    for value, expect in ((0.3, 0.3), (1.0, 1.0), (1.7, 1.0), (-2.0, 0.0)):
        ev.ctx.params[0]["speed"] = value
        assert_pose_close(run(ev, t)[0], sqt.blend2(a, b, expect), atol=1e-6)


# ------------------------------------------------------------------- BlendMask

def bone_group(name):
    if any(k in name for k in ("shoulder", "arm", "hand", "finger")):
        return 1
    if any(k in name for k in ("thigh", "shin", "foot", "toe")):
        return 2
    return 0


def test_blend_mask_all_ones_for_one_child_equals_that_child():
    kids = ["walk", "run", "idle"]
    roots = []
    for k in range(3):
        masks = np.zeros((3, B))
        masks[k] = 1
        roots.append(BlendMask([ClipPlayer(c) for c in kids], masks))
    ev = make(roots)
    for t in (0.0, 6.5, 40.0):
        out = run(ev, t)
        for k, c in enumerate(CLIPS):
            assert_pose_close(out[k], c.sample(t), atol=1e-6)


def test_blend_mask_eq3_head_arms_legs():
    groups = np.array([bone_group(n) for n in SK.bone_names])
    assert set(groups) == {0, 1, 2}
    masks = [{n: 1.0 for n, g in zip(SK.bone_names, groups) if g == k} for k in range(3)]
    ev = make([BlendMask([ClipPlayer("walk"), ClipPlayer("run"), ClipPlayer("idle")], masks)])
    for t in (2.0, 17.3):
        out = run(ev, t)[0]
        for k, c in enumerate(CLIPS):
            assert_pose_close(out[groups == k], c.sample(t)[groups == k], atol=1e-6)


def test_blend_mask_validate_names_uncovered_bone():
    masks = [{"head": 1.0}, {"neck": 1.0}]
    node = BlendMask([ClipPlayer("walk"), ClipPlayer("run")], masks)
    with pytest.raises(CrowdError, match=r"bone 'root' has no weight in any mask"):
        node.validate(SimpleNamespace(skeleton=SK))


# ----------------------------------------------------------------------- Layer

ARM_R = ["upperarm.R", "forearm.R", "hand.R"]


def test_layer_override_changes_only_weighted_bones():
    idx = [SK.bone_index(n) for n in ARM_R]
    others = np.setdiff1d(np.arange(B), idx)
    full = Layer(ClipPlayer("walk"), ClipPlayer("run"), "override", {n: 1 for n in ARM_R})
    half = Layer(ClipPlayer("walk"), ClipPlayer("run"), "override", {n: 1 for n in ARM_R},
                 weight="wave")
    ev = make([full, half])
    ev.ctx.params[1]["wave"] = 0.5
    for t in (3.0, 11.75):
        out = run(ev, t)
        walk, runp = WALK.sample(t), RUN.sample(t)
        assert_pose_close(out[0, others], walk[others], atol=1e-6)
        assert_pose_close(out[0, idx], runp[idx], atol=1e-6)
        assert_pose_close(out[1, others], walk[others], atol=1e-6)
        assert_pose_close(out[1, idx], sqt.blend2(walk[idx], runp[idx], 0.5), atol=1e-6)


def test_layer_additive_with_reference_pose_leaves_base():
    held = Layer(ClipPlayer("walk"), ClipPlayer("run", speed=0.0, start=10.0), "additive",
                 reference=("run", 10.0))
    bind_keys = np.broadcast_to(SK.bind_pose, (3, B, 10))
    rest = Clip("rest", bind_keys)
    on_bind = Layer(ClipPlayer("walk"), ClipPlayer("rest"), "additive")
    ev = make([held, on_bind], clips=CLIPS + [rest])
    for t in (0.0, 9.5, 23.0):
        out = run(ev, t)
        assert_pose_close(out[0], WALK.sample(t), atol=2e-6)
        assert_pose_close(out[1], WALK.sample(t), atol=2e-6)


def wave_clip():
    """Arms swing; every other bone and every translation stays at the bind pose."""
    arms = [n for n in SK.bone_names if bone_group(n) == 1]
    keys = periodic_clip(SK, "wave0", frames=31, seed=4, amplitude=0.8, bones=arms).keys.copy()
    keys[..., TRANS] = SK.bind_pose[:, TRANS]
    return Clip("wave", keys, bone_names=SK.bone_names), arms


def test_layer_additive_wave_on_walk_changes_only_masked_bones():
    wave, arms = wave_clip()
    arm_idx = np.array([SK.bone_index(n) for n in arms])
    still = np.setdiff1d(np.arange(B), arm_idx)
    r_idx = np.array([SK.bone_index(n) for n in ARM_R])
    ev = make([Layer(ClipPlayer("walk"), ClipPlayer("wave"), "additive"),
               Layer(ClipPlayer("walk"), ClipPlayer("wave"), "additive",
                     bone_weights={n: 1 for n in ARM_R})], clips=CLIPS + [wave])
    rot = lambda p: quat.to_matrix(p[..., ROT].astype(np.float64))   # noqa: E731
    for t in (4.0, 12.5):
        out = run(ev, t)
        walk, wv = WALK.sample(t), wave.sample(t)
        assert_pose_close(out[0, still], walk[still], atol=2e-6)
        # masked bones: R_walk @ R_bind^-1 @ R_wave (independent matrix math)
        expect = rot(walk) @ np.linalg.inv(rot(SK.bind_pose)) @ rot(wv)
        np.testing.assert_allclose(rot(out[0])[arm_idx], expect[arm_idx], atol=1e-5)
        assert np.abs(rot(out[0])[arm_idx] - rot(walk)[arm_idx]).max() > 1e-2
        # the bone weights restrict the layer to the right arm
        np.testing.assert_allclose(rot(out[1])[r_idx], expect[r_idx], atol=1e-5)
        other = np.setdiff1d(np.arange(B), r_idx)
        assert_pose_close(out[1, other], walk[other], atol=2e-6)


# ---------------------------------------------------------------- BlendSpace2D

POINTS = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.2], [-0.7, 0.4]])


@pytest.mark.parametrize("seed", range(4))
def test_blend_space_weights_one_hot_at_samples(seed):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(2, 7))
    pts = rng.uniform(-3, 3, (k, 2))
    w = blend_space_weights(np.broadcast_to(pts, (k, k, 2)), pts)   # node j at sample j
    np.testing.assert_array_equal(w, np.eye(k))


@pytest.mark.parametrize("seed", range(4))
def test_blend_space_weights_partition_of_unity_everywhere(seed):
    rng = np.random.default_rng(10 + seed)
    k = int(rng.integers(1, 7))
    n = 300
    pts = np.broadcast_to(rng.uniform(-1, 1, (k, 2)), (n, k, 2))
    p = np.concatenate([rng.uniform(-1, 1, (n // 3, 2)), rng.uniform(-50, 50, (n // 3, 2)),
                        rng.normal(scale=1e4, size=(n - 2 * (n // 3), 2))])
    w = blend_space_weights(pts, p)
    assert w.shape == (n, k) and np.isfinite(w).all()
    assert (w >= 0).all()
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    # the nearest sample always carries weight (never all mass on far samples)
    near = np.argmin(np.linalg.norm(pts - p[:, None], axis=-1), axis=1)
    assert (w[np.arange(n), near] > 0).all()


def test_blend_space_two_points_is_linear():
    pts = np.array([[[0.0, 0.0], [2.0, 0.0]]] * 4)
    p = np.array([[0.5, 0.0], [1.0, 3.0], [1.5, -1.0], [-4.0, 0.0]])
    np.testing.assert_allclose(blend_space_weights(pts, p),
                               [[0.75, 0.25], [0.5, 0.5], [0.25, 0.75], [1.0, 0.0]], atol=1e-12)


def test_blend_space_controller_at_sample_point_equals_child():
    kids = ["walk", "run", "idle", "walk", "run"]
    starts = [0.0, 0.0, 0.0, 11.0, 5.0]
    node = lambda: BlendSpace2D([ClipPlayer(c, start=s) for c, s in zip(kids, starts)],  # noqa
                                POINTS, x="vx", y="vy")
    ev = make([node() for _ in POINTS])
    for r, pt in enumerate(POINTS):
        ev.ctx.params[r].update(vx=pt[0], vy=pt[1])
    clip = {c.name: c for c in CLIPS}
    t = 6.5
    out = run(ev, t)
    for r in range(len(POINTS)):
        assert_pose_close(out[r], clip[kids[r]].sample(starts[r] + t), atol=1e-6)
    # between samples it is the blend_space_weights mix of the children
    ev.ctx.params[0].update(vx=0.4, vy=0.3)
    out = run(ev, t)[0]
    w = blend_space_weights(POINTS[None], np.array([[0.4, 0.3]]))
    kid_poses = np.stack([clip[c].sample(s + t) for c, s in zip(kids, starts)])[None]
    assert_pose_close(out, sqt.blend_weighted(kid_poses, w.astype(np.float32))[0], atol=1e-6)


def test_blend_space_zero_weight_child_does_not_flip_the_blend():
    clips = [static_clip("r0", [0, 0, 0], 0.0), static_clip("r80", [0, 0, 0], np.radians(80)),
             static_clip("r200", [0, 0, 0], np.radians(200))]
    pts = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    ev = make([BlendSpace2D([ClipPlayer(c.name) for c in clips], pts)], clips=clips)
    ev.ctx.params[0].update(x=1.0, y=1.0)                 # weights (0, 0.5, 0.5)
    out = run(ev, 0)[0]
    assert_pose_close(out, sqt.blend2(clips[1].sample(0), clips[2].sample(0), 0.5), atol=1e-5)


# -------------------------------------------------------------- StateMachine

def machine(transitions, initial=None, states=("idle", "walk", "run")):
    return StateMachine({s: ClipPlayer(s) for s in states}, transitions, initial)


def sm_batch(ev):
    return next(b for b in ev.batches if isinstance(b, StateMachine.Batch))


def test_state_machine_starts_in_initial_state_at_time_zero():
    ev = make([machine([], initial="run"), machine([])])
    for t in range(100, 110):
        out = run(ev, t)
        assert_pose_close(out[0], RUN.sample(t - 100), atol=1e-6)
        assert_pose_close(out[1], IDLE.sample(t - 100), atol=1e-6)


def test_state_machine_trigger_cross_fade():
    L = 6.0
    ev = make([machine([StateTransition("idle", "walk", L, trigger="go")])])
    sm = sm_batch(ev)
    for t in range(0, 10):
        assert_pose_close(run(ev, t)[0], IDLE.sample(t), atol=1e-6)
    ev.set_trigger(0, "go")
    t0 = 10
    for t in range(t0, t0 + 15):
        out = run(ev, t)[0]
        s = (t - t0) / L
        if t == t0:
            assert_pose_close(out, IDLE.sample(t), atol=1e-6)     # fade starts at the source
        elif s < 1:
            assert_pose_close(out, sqt.blend2(IDLE.sample(t), WALK.sample(t - t0), s),
                              atol=1e-6)
        else:
            assert_pose_close(out, WALK.sample(t - t0), atol=1e-6)  # target from 0 at entry
        assert sm.state(0) == "walk"
        assert not ev.ctx.triggers[0]                                # consumed


def test_state_machine_parameter_condition_and_any_source():
    trs = [StateTransition("idle", "walk", 0, condition=("speed", ">", 0.5)),
           StateTransition("*", "run", 0, trigger="flee")]
    ev = make([machine(trs)])
    sm = sm_batch(ev)
    ev.ctx.params[0]["speed"] = 0.2
    run(ev, 0)
    run(ev, 1)
    assert sm.state(0) == "idle"
    ev.ctx.params[0]["speed"] = 0.8
    assert_pose_close(run(ev, 2)[0], WALK.sample(0), atol=1e-6)   # a cut: target at 0
    assert sm.state(0) == "walk"
    assert_pose_close(run(ev, 5)[0], WALK.sample(3), atol=1e-6)
    ev.set_trigger(0, "flee")
    assert_pose_close(run(ev, 6)[0], RUN.sample(0), atol=1e-6)
    assert sm.state(0) == "run"
    ev.set_trigger(0, "flee")                                  # already there
    assert_pose_close(run(ev, 7)[0], RUN.sample(1), atol=1e-6)


def test_state_machine_trigger_consumed_when_not_applicable():
    trs = [StateTransition("walk", "run", 0, trigger="go"),
           StateTransition("idle", "walk", 0, trigger="start")]
    ev = make([machine(trs)])
    sm = sm_batch(ev)
    ev.set_trigger(0, "go")                  # ignored in idle, and not kept
    run(ev, 0)
    assert sm.state(0) == "idle" and not ev.ctx.triggers[0]
    ev.set_trigger(0, "start")
    run(ev, 1)
    run(ev, 2)
    assert sm.state(0) == "walk"


def test_state_machine_interrupted_fade_does_not_pop():
    sa = static_clip("A", [0, 0, 0], 0.0)
    sb = static_clip("B", [10, 0, 0], 1.2)
    sc = static_clip("C", [0, 20, 0], -1.0)
    L = 10.0
    trs = [StateTransition("A", "B", L, trigger="b"), StateTransition("*", "C", L, trigger="c")]
    ev = make([machine(trs, states=("A", "B", "C"))], clips=[sa, sb, sc])
    frames = []
    for t in range(40):
        if t in (5, 10):                         # 10 is halfway through A -> B
            ev.set_trigger(0, {5: "b", 10: "c"}[t])
        frames.append(run(ev, t)[0])
    frames = np.array(frames, np.float64)
    step = np.abs(np.diff(frames, axis=0))
    # translation moves along straight fades: at most |X - Y| / L per frame
    assert step[..., TRANS].max() <= np.hypot(5, 20) / L + 1e-5
    # rotations: nlerp's speed is within 2x the chord rate for these angles
    assert step[..., ROT].max() <= 2 * 2 * np.sin(1.1 / 2) / L
    np.testing.assert_allclose(frames[10], frames[9], atol=1e-6)   # fades from the shown pose
    np.testing.assert_allclose(frames[10, 0, TRANS], [4, 0, 0], atol=1e-5)  # s = 4/10
    assert_pose_close(frames[-1], sc.sample(0.0), atol=1e-6)


def test_nested_state_machine_restarts_when_reentered():
    inner = machine([StateTransition("walk", "run", 0, trigger="fast")], states=("walk", "run"))
    outer = StateMachine({"x": inner, "idle": ClipPlayer("idle")},
                         [StateTransition("x", "idle", 0, trigger="stop"),
                          StateTransition("idle", "x", 0, trigger="back")])
    ev = make([outer])
    for t in range(46):
        trig = {15: "fast", 20: "stop", 40: "back"}.get(t)
        if trig:
            ev.set_trigger(0, trig)
        out = run(ev, t)[0]
    # re-entered at 40: whichever inner state it shows, its clip restarted at 0
    err = min(np.abs(out - WALK.sample(5)).max(), np.abs(out - RUN.sample(5)).max())
    assert err < 1e-5


# ------------------------------------------------------------------- batching

def tree(i):
    sm = StateMachine({"idle": ClipPlayer("idle", start=i), "go": Blend2(
        ClipPlayer("walk", speed=1 + 0.1 * i), ClipPlayer("run"), "w")},
        [StateTransition("idle", "go", 4, trigger="go"),
         StateTransition("go", "idle", 3, condition=("w", "<", 0.1))])
    return Layer(sm, ClipPlayer("wave", start=2 * i), "additive",
                 bone_weights={n: 1 for n in ARM_R}, weight="lw")


def drive(ev, roots, t):
    """Per-root parameters and triggers, a deterministic function of (root, t)."""
    for k, r in enumerate(roots):
        ev.ctx.params[k]["w"] = ((r * 7 + t) % 10) / 9.0
        ev.ctx.params[k]["lw"] = ((r + t) % 4) / 3.0
        if (t + r) % 6 == 0:
            ev.set_trigger(k, "go")
    return run(ev, t)


def test_batching_many_roots_few_batches_same_results():
    wave, _ = wave_clip()
    clips = CLIPS + [wave]
    n = 12
    together = make([tree(i) for i in range(n)], clips=clips)
    alone_one = make([tree(0)], clips=clips)
    assert len(together.batches) == len(alone_one.batches) <= 7
    alone = [make([tree(i)], clips=clips) for i in range(n)]
    for t in range(30):
        out = drive(together, range(n), t)
        for i in range(n):
            ref = drive(alone[i], [i], t)[0]
            np.testing.assert_allclose(out[i], ref, atol=1e-6)


def test_batching_mixed_skeleton_sizes():
    small = humanoid("kid", bones=24)
    hop = periodic_clip(small, "hop", frames=21, seed=9)
    clips = CLIPS + [hop]
    masks = lambda sk: [{n: 1 for n in sk.bone_names if (bone_group(n) == 1) == k}  # noqa
                        for k in (False, True)]
    roots = [(BlendMask([ClipPlayer("hop"), ClipPlayer("hop", start=5)], masks(small)), small),
             (BlendMask([ClipPlayer("walk"), ClipPlayer("run")], masks(SK)), SK)]
    ev = TreeEvaluator(roots, ClipBank(clips, B), B)
    assert len(ev.batches) == 2
    out = run(ev, 7.5)
    ref_small = run(TreeEvaluator([roots[0]], ClipBank([hop], 24), 24), 7.5)[0]
    assert_pose_close(out[0, :24], ref_small, atol=1e-6)
    np.testing.assert_array_equal(out[0, 24:], sqt.identity_pose(B - 24))
    ref_big = run(make([roots[1]]), 7.5)[0]
    assert_pose_close(out[1], ref_big, atol=1e-6)
