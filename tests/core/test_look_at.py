"""Look-at (core/look_at.py): the head turned toward a point on top of a shared pose.

Oracles: geometry. The head's forward after the turn (the skinned rows' rotation of
the character's forward) against the direction from the head's pivot to the target,
measured with plain vector maths; the limits as angles from the body's forward; the
skinned mesh of bones the chain does not reach is untouched; lag and smoothing
against their written definitions.
"""

import math

import numpy as np
import pytest

from crowd_addon.core import synthetic as sy
from crowd_addon.core.errors import CrowdError
from crowd_addon.core.look_at import (LookChain, LookRig, LookTarget, agent_lags, apply_look,
                                      head_direction, look_turns)
from crowd_addon.core.skinning import skinning_matrices

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
