"""Pose channels -> local SQT (crowd_addon.core.bake.pose_channels), checked against
independent matrix math: a bone's local matrix is its rest matrix (relative to the
parent) times ``T(location) @ R(rotation by mode) @ S(scale)``. The same code against
Blender's own pose evaluation is tests/blender/test_bake.py."""

import numpy as np
import pytest

from crowd_addon.core.bake import fcurve
from crowd_addon.core.base import quaternion as quat
from crowd_addon.core.base.pose import pose_to_matrices
from crowd_addon.core.bake.pose_channels import (CHANNEL_WIDTH, CHANNELS, RigChannels,
                                                 basis_rotation, channel_targets, local_sqt)

MODES = ("QUATERNION", "AXIS_ANGLE", "XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


def rotation(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def channels(seed, frames, bones):
    rng = np.random.default_rng(seed)
    chan = rng.normal(size=(CHANNEL_WIDTH, frames, bones))
    chan[14:17] = rng.uniform(0.5, 2.0, (3, frames, bones))       # positive scale
    return chan


def test_data_paths_map_to_bones_and_columns():
    paths = ('pose.bones["arm.L"].location', 'pose.bones["a\\"b"].scale',
             'pose.bones["ghost"].rotation_euler', "location",
             'pose.bones["arm.L"].rotation_mode', 'pose.bones["arm.L"]["custom"]')
    bone, first, width, mode, missing = channel_targets(paths, ("arm.L", 'a"b'))
    assert bone.tolist() == [0, 1, -1, -1, 0, 0] and missing == ("ghost",)
    assert first.tolist() == [0, 14, 0, 0, 0, 0] and width.tolist() == [3, 3, 0, 0, 0, 0]
    assert mode.tolist() == [False, False, False, False, True, False]
    assert not bone.flags.writeable
    assert sorted(c for c, _ in CHANNELS.values()) == [0, 3, 7, 10, 14]


def test_basis_rotation_by_mode_matches_matrix_math():
    chan = channels(1, 6, len(MODES))
    q = basis_rotation(chan, MODES)                                        # (4, F, B)
    got = quat.to_matrix(np.moveaxis(q, 0, -1))                            # (F, B, 3, 3)
    for b, mode in enumerate(MODES):
        for f in range(6):
            if mode == "QUATERNION":
                raw = chan[3:7, f, b]
                want = quat.to_matrix(raw / np.linalg.norm(raw))
            elif mode == "AXIS_ANGLE":
                angle, axis = chan[10, f, b], chan[11:14, f, b]
                want = quat.to_matrix(np.concatenate(
                    [[np.cos(angle / 2)], np.sin(angle / 2) * axis / np.linalg.norm(axis)]))
            else:                                  # first letter applied first
                want = np.eye(3)
                for letter in mode:
                    axis = "XYZ".index(letter)
                    want = rotation(axis, chan[7 + axis, f, b]) @ want
            np.testing.assert_allclose(got[f, b], want, atol=1e-12, err_msg=mode)
    np.testing.assert_allclose(np.linalg.norm(q, axis=0), 1.0, atol=1e-12)


def test_zero_quaternions_and_axes_follow_blender():
    chan = np.zeros((CHANNEL_WIDTH, 1, 2), np.float32)
    chan[10, 0, 1] = 0.7                              # an angle about a zero axis
    q = basis_rotation(chan, ("QUATERNION", "AXIS_ANGLE"))[:, 0]
    np.testing.assert_array_equal(q.T, [[0, 1, 0, 0], [1, 0, 0, 0]])


def rig_of(modes, seed=2, connected=None):
    """A rig of random rest matrices (rotation and offset) and default channels."""
    rng = np.random.default_rng(seed)
    b = len(modes)
    rot = rng.normal(size=(b, 4))
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    rest = np.tile(np.eye(4), (b, 1, 1))
    rest[:, :3, :3] = quat.to_matrix(rot)
    rest[:, :3, 3] = rng.normal(size=(b, 3))
    defaults = channels(seed + 1, 1, b)[:, 0].T.astype(np.float32)
    connected = np.zeros(b, bool) if connected is None else np.asarray(connected)
    return RigChannels(defaults, tuple(modes), connected, rest, rot)


def expected_local(rig, chan):
    """rest @ T(loc) @ R @ S per frame and bone, from channels (17, F, B) float64."""
    loc = np.where(rig.connected, 0.0, chan[0:3])
    r = quat.to_matrix(np.moveaxis(basis_rotation(chan, rig.modes), 0, -1))
    basis = np.tile(np.eye(4), chan.shape[1:] + (1, 1))
    basis[..., :3, :3] = r * np.moveaxis(chan[14:17], 0, -1)[..., None, :]
    basis[..., :3, 3] = np.moveaxis(loc, 0, -1)
    return rig.rest @ basis


def test_local_sqt_composes_channels_with_the_rest_pose():
    rig = rig_of(MODES, connected=[False, True] + [False] * 6)
    frames = np.array([1.0, 4.0, 7.0])
    # location x of bone 0 and of the connected bone 1 (ignored), Euler y of bone 2
    cs = fcurve.CurveSet(np.array([[1, 0], [7, 3], [1, 0], [7, 3], [1, -1], [7, 1]],
                                  np.float32), np.full(6, fcurve.LINEAR, np.int32), None,
                         None, np.array([0, 2, 4, 6]), np.zeros(3, bool))
    keys = local_sqt(rig, cs, [0, 0, 8], [0, 1, 2], frames)
    assert keys.shape == (3, 8, 10) and keys.dtype == np.float32
    chan = np.repeat(rig.defaults.T[:, None, :].astype(np.float64), 3, axis=1)
    chan[0, :, 0] = chan[0, :, 1] = [0.0, 1.5, 3.0]
    chan[8, :, 2] = [-1.0, 0.0, 1.0]
    np.testing.assert_allclose(pose_to_matrices(keys), expected_local(rig, chan), atol=2e-5)


def test_curves_numpy_cannot_reproduce_come_from_the_callback():
    rig = rig_of(("QUATERNION",))
    cs = fcurve.CurveSet(np.array([[0, 0], [10, 1]], np.float32),
                         np.full(2, fcurve.LINEAR, np.int32), None, None,
                         np.array([0, 2]), np.zeros(1, bool))
    seen = []

    def evaluate(c, times):
        seen.append((c, times.tolist()))
        return np.cos(times)

    keys = local_sqt(rig, cs, [15], [0], [0.0, 2.0], fast=[False], evaluate=evaluate)
    assert seen == [(0, [0.0, 2.0])]
    np.testing.assert_allclose(keys[:, 0, 1], np.cos([0.0, 2.0]), atol=1e-7)   # scale y
    with pytest.raises(ValueError, match=r"curves \[0\] are not fast and no evaluate"):
        local_sqt(rig, cs, [15], [0], [0.0], fast=[False])
