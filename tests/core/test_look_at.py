"""Look-at (core/runtime/look_at.py): the head turned toward a point on top of a shared pose.

Oracles: geometry. The head's forward after the turn (the skinned rows' rotation of
the character's forward) against the direction from the head's pivot to the target,
measured with plain vector maths; the limits as angles from the body's forward; the
skinned mesh of bones the chain does not reach is untouched; lag and smoothing
against their written definitions.
"""

import math

import numpy as np
import pytest

from crowd_addon.core.authoring import synthetic as sy
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.runtime.look_at import (LookChain, LookRig, LookTarget, agent_lags,
                                              apply_look, head_direction, look_turns)
from crowd_addon.core.base.skinning import skinning_matrices

SK = sy.humanoid("fan", bones=24)
RIG = LookRig(("neck", "head"), (0.4, 0.6), yaw_limit=math.radians(70),
              pitch_limit=math.radians(35))
CHAIN = LookChain(RIG, SK)


def rows_of(poses):
    return skinning_matrices(np.asarray(poses), SK)[:, :, :3, :]


def clip_rows(n, seed=3):
    """n poses of a clip the head moves in (its own yaw, pitch and roll)."""
    clip = sy.periodic_clip(SK, "idle", frames=25, seed=seed, amplitude=0.4)
    return rows_of(clip.keys[np.arange(n) % clip.keys.shape[0]])


def angle(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


def yaw_pitch(v):
    """Degrees from the body's forward (-Y): sideways about +Z, up."""
    return (np.degrees(np.arctan2(v[..., 0], -v[..., 1])),
            np.degrees(np.arctan2(v[..., 2], np.hypot(v[..., 0], v[..., 1]))))


def test_the_head_points_at_a_target_the_limits_allow():
    rng = np.random.default_rng(1)
    n = 200
    rows = clip_rows(n)
    # targets 10-40 m away, within 60 degrees sideways and 25 up or down of forward
    yaw = np.radians(rng.uniform(-60, 60, n))
    pitch = np.radians(rng.uniform(-25, 25, n))
    dist = rng.uniform(10, 40, n)
    head = np.array([0.0, 0.0, 1.7])
    targets = head + dist[:, None] * np.c_[np.sin(yaw) * np.cos(pitch),
                                           -np.cos(yaw) * np.cos(pitch), np.sin(pitch)]
    looked = apply_look(rows, CHAIN, look_turns(rows, CHAIN, targets, np.ones(n)))
    pivot, f = head_direction(looked, CHAIN)
    assert angle(f, targets - pivot).max() < 1.0
    before = head_direction(rows, CHAIN)[1]
    assert angle(before, targets - pivot).max() > 10.0        # the clip did not already


def test_the_head_stops_at_the_limits():
    n = 4
    rows = clip_rows(n)
    head = np.array([0.0, 0.0, 1.7])
    targets = head + np.array([[20.0, 5.0, 0.0],      # behind to the side: yaw past 70
                               [-20.0, 5.0, 0.0],
                               [0.0, -10.0, 30.0],    # high above: pitch past 35
                               [0.0, -10.0, -30.0]])
    looked = apply_look(rows, CHAIN, look_turns(rows, CHAIN, targets, np.ones(n)))
    yaw, pitch = yaw_pitch(head_direction(looked, CHAIN)[1])
    np.testing.assert_allclose(yaw[:2], [70, -70], atol=1.0)
    np.testing.assert_allclose(pitch[2:], [35, -35], atol=1.0)


def test_the_turn_is_shared_along_the_chain_and_reaches_every_bone_below():
    rows = clip_rows(3)
    targets = np.tile([15.0, -15.0, 6.0], (3, 1))
    turns = look_turns(rows, CHAIN, targets, np.ones(3))
    looked = apply_look(rows, CHAIN, turns)
    ang = [np.degrees(np.arccos(np.clip((np.trace(turns[:, i, :, :3], axis1=1, axis2=2)
                                         - 1) / 2, -1, 1))) for i in range(2)]
    np.testing.assert_allclose(ang[0] / ang[1], 0.4 / 0.6, rtol=1e-6)
    untouched = [i for i, name in enumerate(SK.bone_names) if name not in ("neck", "head")]
    np.testing.assert_array_equal(looked[:, untouched], rows[:, untouched])
    # the head moves with the neck: its pivot is where the turned neck carries it
    neck, head = SK.bone_index("neck"), SK.bone_index("head")
    bind = np.linalg.inv(SK.inverse_bind)
    p = bind[head, :3, 3]
    moved = looked[:, neck, :, :3] @ p + looked[:, neck, :, 3]
    at = looked[:, head, :, :3] @ p + looked[:, head, :, 3]
    np.testing.assert_allclose(moved, at, atol=1e-9)


def test_weight_zero_leaves_the_pose_and_weights_between_turn_part_way():
    rows = clip_rows(3)
    targets = np.tile([12.0, -10.0, 1.7], (3, 1))
    still = apply_look(rows, CHAIN, look_turns(rows, CHAIN, targets, np.zeros(3)))
    np.testing.assert_allclose(still, rows, atol=1e-12)
    half = apply_look(rows, CHAIN, look_turns(rows, CHAIN, targets, np.full(3, 0.5)))
    full = apply_look(rows, CHAIN, look_turns(rows, CHAIN, targets, np.ones(3)))
    y0, y5, y1 = (yaw_pitch(head_direction(r, CHAIN)[1])[0] for r in (rows, half, full))
    np.testing.assert_allclose(y5, 0.5 * (y0 + y1), atol=0.5)


def test_smoothing_follows_its_definition_and_lag_reads_the_path_late():
    p = np.zeros((40, 3))
    p[10:, 0] = 10.0                               # a step at frame first + 10
    t = LookTarget("ball", 5, p, smoothing=4.0)
    s = t.smoothed()
    a = 1 - math.exp(-1 / 4.0)
    want = np.zeros(40)
    for k in range(1, 40):
        want[k] = want[k - 1] + a * (p[k, 0] - want[k - 1])
    np.testing.assert_allclose(s[:, 0], want, atol=1e-12)
    assert abs(s[14, 0] - 10 * (1 - math.exp(-5 / 4.0))) < 1e-9   # 63 % after 4 frames
    # held beyond both ends, read late by each agent's lag
    np.testing.assert_array_equal(t.at([0, 5, 44, 100])[:, 0], [0, 0, s[39, 0], s[39, 0]])
    lags = agent_lags(np.array([0, 3, 7]))
    np.testing.assert_array_equal(lags, [0, 3, 7])
    np.testing.assert_array_equal(t.at(30 - lags)[:, 0], s[[25, 22, 18], 0])
    seeded = agent_lags(np.zeros(500, np.int64), "seeded", max_lag=12, seed=3)
    assert seeded.min() == 0 and seeded.max() == 12 and len(np.unique(seeded)) == 13
    np.testing.assert_array_equal(seeded, agent_lags(np.zeros(500), "seeded", 12, 3))
    assert np.array_equal(LookTarget("b", 0, p, smoothing=0).smoothed(), p)


@pytest.mark.parametrize("make, match", [
    (lambda: LookRig(()), "distinct bone names"),
    (lambda: LookRig(("neck", "neck")), "distinct bone names"),
    (lambda: LookRig(("neck", "head"), (0.5, 0.6)), "summing to 1"),
    (lambda: LookRig(("head",), yaw_limit=4.0), "yaw_limit"),
    (lambda: LookRig(("head",), forward=(0, 0, 1)), "horizontal"),
    (lambda: LookChain(LookRig(("neck", "skull")), SK), "no bone named 'skull'"),
    (lambda: LookChain(LookRig(("head", "neck")), SK), "parent first"),
    (lambda: LookTarget("b", 0, np.zeros((3, 2))), r"\(frames, 3\)"),
    (lambda: LookTarget("b", 0, np.full((3, 3), np.nan)), "not finite"),
    (lambda: LookTarget("b", 0.5, np.zeros((3, 3))), "whole frame"),
    (lambda: LookTarget("b", 0, np.zeros((3, 3)), smoothing=-1), "smoothing"),
    (lambda: agent_lags([1, 2], "random"), "offset' or 'seeded"),
])
def test_bad_look_settings_are_named(make, match):
    with pytest.raises(CrowdError, match=match):
        make()


# ----------------------------------------------------------------- in a crowd
from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig  # noqa: E402
from crowd_addon.core.authoring.show import Action, Cue, Show  # noqa: E402

M = 8


def crowd_config(show=None, target=None):
    """16 agents in a row facing -Y (heading 0) on one stream at offsets 0..M-1, a look
    rig on the skeleton and a ball moving along +X in front of them."""
    cfg = CrowdConfig(max_offset=M, transition_slots=8, fps=24.0, start_frame=1)
    cfg.add_skeleton(SK)
    cfg.add_clip(sy.periodic_clip(SK, "idle", frames=25, seed=3, amplitude=0.3))
    cfg.add_stream("idle", "fan", ClipPlayer("idle"))
    n = 16
    cfg.add_agents(n, streams=np.zeros(n, np.int64), offsets=np.arange(n) % M,
                   positions=np.c_[np.arange(n) * 1.0, np.zeros(n), np.zeros(n)],
                   headings=np.linspace(-0.3, 0.3, n))
    frames = np.arange(120)
    path = np.c_[-20 + 0.5 * frames, np.full(120, -25.0), np.full(120, 1.0)]
    cfg.look_rigs = {"fan": RIG}
    cfg.look_targets = {"ball": target or LookTarget("ball", 1, path, smoothing=3.0)}
    cfg.show = show if show is not None else Show()
    return cfg


def world_head(crowd, ids):
    """(pivot, forward) of the agents' heads in world space, from agent_rows."""
    pivot, f = head_direction(crowd.agent_rows(ids).astype(np.float64), CHAIN)
    h = crowd.agents.heading[ids].astype(np.float64)
    c, s = np.cos(h), np.sin(h)
    rot = lambda v: np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], 1)
    return rot(pivot) * crowd.agents.scale[ids, None] + crowd.agents.position[ids], rot(f)


def test_a_look_cue_turns_every_head_to_the_ball_each_seeing_it_late_by_its_offset():
    cue = Cue("watch", 10, Action("look", "ball", duration=6))
    crowd = Crowd(crowd_config(Show((cue,))))
    quiet = Crowd(crowd_config())
    ids = np.arange(16)
    target = crowd.config.look_targets["ball"]
    for f in range(2, 40):
        crowd.step()
        quiet.step()
        pivot, f_dir = world_head(crowd, ids)
        if f < 10:            # before the cue: the animation as it is
            np.testing.assert_array_equal(crowd.agent_rows(ids), quiet.agent_rows(ids))
        if f >= 16:           # blended in: each head at the ball as it saw it, lag late
            seen = target.at(f - crowd.agents.offset[ids])
            assert angle(f_dir, seen - pivot).max() < 1.0, f
            now = target.at(np.full(16, f))
            late = crowd.agents.offset[ids] >= 4
            assert (angle(f_dir, now - pivot)[late] > 0.5).all()     # not the ball now
    assert crowd.show.stats["watch"]["agents"] == 16
    # only the chain and the bones below it move: the rest is the stream's pose
    neck = SK.bone_index("neck")
    below = [i for i in range(SK.bone_count) if CHAIN.depth[i] == 0]
    np.testing.assert_array_equal(crowd.agent_rows(ids)[:, below], quiet.agent_rows(ids)[:, below])
    assert not np.allclose(crowd.agent_rows(ids)[:, neck], quiet.agent_rows(ids)[:, neck])


def test_a_held_look_blends_away_and_a_snapshot_keeps_it():
    cue = Cue("glance", 5, Action("look", "ball", duration=4, hold=10))
    a = Crowd(crowd_config(Show((cue,))))
    quiet = Crowd(crowd_config())
    a.advance_to(9)
    np.testing.assert_allclose(a.looks.weights(9, np.arange(16)), 1.0)
    snap = a.snapshot()
    a.advance_to(16)
    np.testing.assert_allclose(a.looks.weights(16, [0]), 0.75)      # 1 of 4 frames out
    a.advance_to(20)
    quiet.advance_to(20)
    np.testing.assert_array_equal(a.agent_rows(), quiet.agent_rows())
    b = Crowd(crowd_config(Show((cue,))))
    b.restore(snap)
    b.advance_to(14)
    a.advance_to(14)
    np.testing.assert_array_equal(a.agent_rows(), b.agent_rows())


def test_look_at_by_hand_and_look_away():
    crowd = Crowd(crowd_config())
    crowd.look_at([2, 3], "ball", blend=0)
    crowd.step()
    np.testing.assert_array_equal(crowd.looks.weights(crowd.frame, [1, 2, 3]), [0, 1, 1])
    crowd.look_away([2], blend=4)            # from the next frame, over 4 frames
    crowd.step()
    np.testing.assert_allclose(crowd.looks.weights(crowd.frame, [2, 3]), [1, 1])
    crowd.step()
    np.testing.assert_allclose(crowd.looks.weights(crowd.frame, [2, 3]), [0.75, 1])
    for bad, match in ((lambda: crowd.look_at([1], "moon"), "unknown look target 'moon'"),
                       (lambda: crowd.look_at([1], "ball", blend=-1), "blend"),
                       (lambda: crowd.look_at([99], "ball"), "99")):
        with pytest.raises(CrowdError, match=match):
            bad()


def test_a_look_cue_leaves_transitions_and_holds_alone():
    show = Show((Cue("watch", 4, Action("look", "ball", duration=2)),
                 Cue("up", 6, Action("stream", "idle", duration=3, offset=0, hold=5),
                     agents=np.arange(4))))
    crowd = Crowd(crowd_config(show))
    crowd.advance_to(8)
    assert crowd.show.stats["up"]["agents"] == 4 and crowd.show.stats["up"]["skipped"] == 0
    assert (crowd.looks.target == 0).all()


@pytest.mark.parametrize("change, match", [
    (lambda c: c.look_rigs.update(kid=RIG), "look rig: unknown skeleton 'kid'"),
    (lambda c: c.look_rigs.update(fan=LookRig(("jaw",))), "no bone named 'jaw'"),
    (lambda c: c.look_targets.update(moon=LookTarget("sun", 0, np.zeros((1, 3)))),
     "look target 'moon'"),
    (lambda c: setattr(c, "show", Show((Cue("x", 5, Action("look", "moon")),))),
     "unknown look target 'moon'"),
])
def test_bad_look_configurations_are_named(change, match):
    cfg = crowd_config()
    change(cfg)
    with pytest.raises(CrowdError, match=match):
        Crowd(cfg)


def test_looks_survive_the_config_file(tmp_path):
    import json

    from crowd_addon.core.authoring.config_io import config_digest, load_config, save_config
    show = Show((Cue("watch", 10, Action("look", "ball", duration=6, hold=20)),))
    cfg = crowd_config(show)
    cfg.look_lag, cfg.look_max_lag = "seeded", 5
    save_config(cfg, tmp_path / "c.json")
    back = load_config(tmp_path / "c.json")
    assert back.look_rigs == cfg.look_rigs and (back.look_lag, back.look_max_lag) == ("seeded", 5)
    t, u = back.look_targets["ball"], cfg.look_targets["ball"]
    assert (t.first, t.smoothing) == (u.first, u.smoothing)
    np.testing.assert_array_equal(t.positions, u.positions)
    a, b = Crowd(cfg), Crowd(back)
    a.advance_to(30)
    b.advance_to(30)
    np.testing.assert_array_equal(a.agent_rows(), b.agent_rows())
    # a file without looks carries no "look" key (it reads and hashes as before)
    plain = crowd_config()
    plain.look_rigs, plain.look_targets = {}, {}
    save_config(plain, tmp_path / "p.json")
    assert "look" not in json.loads((tmp_path / "p.json").read_text())
    assert config_digest(plain) == config_digest(load_config(tmp_path / "p.json"))
