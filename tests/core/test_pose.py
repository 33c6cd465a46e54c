"""SQT pose blending (paper Eq. 2), N-way blends and additive layers vs float64 math."""

import numpy as np
import pytest

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.base import quaternion as quat

ROT, TRANS, SCALE = sqt.ROT, sqt.TRANS, sqt.SCALE


def random_poses(shape, seed):
    """float32 SQT poses with positive scales and unit quaternions in both hemispheres."""
    rng = np.random.default_rng(seed)
    shape = tuple(np.atleast_1d(shape))
    p = np.empty(shape + (10,))
    p[..., SCALE] = rng.uniform(0.5, 2.0, shape + (3,))
    q = rng.normal(size=shape + (4,))
    p[..., ROT] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    p[..., TRANS] = rng.normal(size=shape + (3,))
    return p.astype(np.float32)


def assert_rot_close(a, b, atol):
    """Rotations equal up to the q / -q sign."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    d = np.minimum(np.abs(a - b).max(axis=-1), np.abs(a + b).max(axis=-1))
    assert d.max() <= atol, f"rotation distance {d.max()}"


def assert_pose_close(p, ref, atol=1e-6):
    np.testing.assert_allclose(p[..., SCALE], ref[..., SCALE], atol=atol)
    np.testing.assert_allclose(p[..., TRANS], ref[..., TRANS], atol=atol)
    assert_rot_close(p[..., ROT], ref[..., ROT], atol)


def blend2_ref(a, b, w):
    """Eq. 2 in float64: lerp S and T, shortest-arc nlerp R; ``w`` broadcast to (..., B)."""
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    w = np.broadcast_to(np.asarray(w, np.float64), a.shape[:-1])[..., None]
    out = a + (b - a) * w
    qa, qb = a[..., ROT], b[..., ROT]
    sign = np.where(np.sum(qa * qb, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    q = qa + (sign * qb - qa) * w
    out[..., ROT] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return out


# ------------------------------------------------------------------ helpers

def test_identity_and_make_pose():
    p = sqt.identity_pose(3)
    assert p.shape == (3, 10) and p.dtype == np.float32
    np.testing.assert_array_equal(p[0], [1, 1, 1, 1, 0, 0, 0, 0, 0, 0])
    m = sqt.make_pose(translation=np.ones((2, 4, 3)))
    assert m.shape == (2, 4, 10)
    np.testing.assert_array_equal(m[..., TRANS], 1)
    np.testing.assert_array_equal(m[..., ROT], np.broadcast_to([1, 0, 0, 0], (2, 4, 4)))
    np.testing.assert_array_equal(sqt.make_pose(bones=5), sqt.identity_pose(5))


def test_pose_to_matrices_is_t_r_s():
    p = random_poses(6, 1)
    m = sqt.pose_to_matrices(p)
    assert m.shape == (6, 4, 4) and m.dtype == np.float64
    for i in range(6):
        t = np.eye(4)
        t[:3, 3] = p[i, TRANS]
        r = np.eye(4)
        r[:3, :3] = quat.to_matrix(p[i, ROT].astype(np.float64))
        s = np.diag(np.r_[p[i, SCALE], 1.0])
        np.testing.assert_allclose(m[i], t @ r @ s, atol=1e-12)


# ------------------------------------------------------------------- blend2

def test_blend2_endpoints_exact():
    a, b = random_poses((4, 7), 2), random_poses((4, 7), 3)
    p0 = sqt.blend2(a, b, 0.0)
    p1 = sqt.blend2(a, b, 1.0)
    assert p0.dtype == np.float32 and p0.shape == a.shape
    np.testing.assert_allclose(p0, a, rtol=0, atol=2e-7)
    assert_pose_close(p1, b, atol=4e-7)


def test_blend2_matches_eq2_reference():
    a, b = random_poses((5, 9), 4), random_poses((5, 9), 5)
    for w in (0.25, 0.5, 0.9):
        assert_pose_close(sqt.blend2(a, b, w), blend2_ref(a, b, w), atol=2e-6)
    # midpoint of translation and scale is exactly the average (Eq. 2, s = 0.5)
    mid = sqt.blend2(a, b, 0.5)
    np.testing.assert_allclose(mid[..., TRANS], (a[..., TRANS] + b[..., TRANS]) / 2, atol=1e-6)


def test_blend2_per_bone_weights():
    a, b = random_poses(6, 6), random_poses(6, 7)
    w = np.array([0.0, 1.0, 0.3, 0.5, 0.7, 0.1], np.float32)
    out = sqt.blend2(a, b, w)
    for i in range(6):
        assert_pose_close(out[i], blend2_ref(a[i:i + 1], b[i:i + 1], w[i])[0], atol=2e-6)
    np.testing.assert_allclose(out[0], a[0], atol=2e-7)
    assert_pose_close(out[1], b[1], atol=4e-7)


def test_blend2_per_pose_and_per_pose_bone_weights():
    a, b = random_poses((3, 4), 8), random_poses((3, 4), 9)
    w = np.array([0.0, 0.4, 1.0], np.float32)
    assert_pose_close(sqt.blend2(a, b, w), blend2_ref(a, b, w[:, None]), atol=2e-6)
    wb = np.random.default_rng(10).uniform(size=(3, 4)).astype(np.float32)
    assert_pose_close(sqt.blend2(a, b, wb), blend2_ref(a, b, wb), atol=2e-6)


def test_blend2_shortest_arc():
    a, b = random_poses(50, 11), random_poses(50, 12)
    flipped = b.copy()
    flipped[:, ROT] *= -1
    for w in (0.2, 0.5, 0.8):
        assert_pose_close(sqt.blend2(a, b, w), sqt.blend2(a, flipped, w), atol=1e-6)
    # 160 degrees about z, given in the far hemisphere: the midpoint turns 80 degrees
    qa = sqt.identity_pose(1)
    qb = sqt.identity_pose(1)
    qb[0, ROT] = -np.array([np.cos(1.4), 0, 0, np.sin(1.4)])
    mid = sqt.blend2(qa, qb, 0.5)[0, ROT].astype(np.float64)
    assert_rot_close(mid, [np.cos(0.7), 0, 0, np.sin(0.7)], 1e-6)


def test_blend2_out_argument():
    a, b = random_poses(5, 13), random_poses(5, 14)
    out = np.empty_like(a)
    r = sqt.blend2(a, b, 0.3, out=out)
    assert r is out
    assert_pose_close(out, blend2_ref(a, b, 0.3), atol=2e-6)


def test_blend2_leaves_inputs_untouched():
    a, b = random_poses(5, 15), random_poses(5, 16)
    a0, b0 = a.copy(), b.copy()
    sqt.blend2(a, b, 0.6)
    np.testing.assert_array_equal(a, a0)
    np.testing.assert_array_equal(b, b0)


# ------------------------------------------------------------ blend_weighted

def blend_weighted_ref(poses, weights):
    p = poses.astype(np.float64)
    w = np.asarray(weights, np.float64)
    if w.ndim == 2:
        w = np.broadcast_to(w[:, :, None], p.shape[:3])
    w = w / w.sum(axis=1, keepdims=True)
    out = np.zeros((p.shape[0],) + p.shape[2:])
    for n in range(p.shape[0]):
        for k in range(p.shape[1]):
            q = p[n, k].copy()
            flip = np.sum(q[:, ROT] * p[n, 0, :, ROT], axis=-1) < 0
            q[flip, 3:7] *= -1
            out[n] += w[n, k][:, None] * q
    out[..., ROT] /= np.linalg.norm(out[..., ROT], axis=-1, keepdims=True)
    return out


def test_blend_weighted_one_hot_equals_child():
    poses = random_poses((4, 3, 8), 17)
    for k in range(3):
        w = np.zeros((4, 3), np.float32)
        w[:, k] = 1
        out = sqt.blend_weighted(poses, w)
        assert out.shape == (4, 8, 10) and out.dtype == np.float32
        assert_pose_close(out, poses[:, k], atol=3e-7)


def test_blend_weighted_normalises_weights():
    poses = random_poses((2, 2, 5), 18)
    w = np.array([[2.0, 6.0], [0.5, 0.5]], np.float32)
    out = sqt.blend_weighted(poses, w)
    norm = sqt.blend_weighted(poses, w / w.sum(axis=1, keepdims=True))
    assert_pose_close(out, norm, atol=1e-6)
    assert_pose_close(out, blend_weighted_ref(poses, w), atol=2e-6)


def test_blend_weighted_two_children_equals_blend2():
    poses = random_poses((6, 2, 7), 19)
    w = np.linspace(0, 1, 6).astype(np.float32)
    out = sqt.blend_weighted(poses, np.stack([1 - w, w], axis=1))
    assert_pose_close(out, sqt.blend2(poses[:, 0], poses[:, 1], w), atol=2e-6)


def clustered_poses(n, k, b, seed):
    """Children whose rotations lie within 40 degrees of a common one per bone, with
    random q / -q signs: their weighted average is the same whichever child the signs
    are aligned to."""
    rng = np.random.default_rng(seed)
    poses = random_poses((n, k, b), seed)
    base = random_poses((n, 1, b), seed + 1)[..., ROT].astype(np.float64)
    axis = rng.normal(size=(n, k, b, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    half = rng.uniform(0, np.radians(20), (n, k, b, 1))
    small = np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)
    q = quat.multiply(base, small) * rng.choice([-1.0, 1.0], (n, k, b, 1))
    poses[..., ROT] = q
    return poses


def test_blend_weighted_per_bone_weights_and_shortest_arc():
    poses = clustered_poses(3, 4, 6, 20)
    rng = np.random.default_rng(21)
    w = rng.uniform(0.0, 1.0, (3, 4, 6)).astype(np.float32)
    assert_pose_close(sqt.blend_weighted(poses, w), blend_weighted_ref(poses, w), atol=2e-6)
    flipped = poses.copy()
    flipped[:, 1:, :, ROT] *= -1
    assert_pose_close(sqt.blend_weighted(flipped, w), sqt.blend_weighted(poses, w), atol=2e-6)
    # bone-exclusive weights pick each child's bone (Eq. 3 style)
    onehot = np.zeros((3, 4, 6), np.float32)
    pick = np.arange(6) % 4
    onehot[:, pick, np.arange(6)] = 1
    out = sqt.blend_weighted(poses, onehot)
    assert_pose_close(out, poses[:, pick, np.arange(6)], atol=3e-7)


# ---------------------------------------------------------------- additive

def test_additive_round_trip():
    p, ref = random_poses((3, 10), 22), random_poses((3, 10), 23)
    delta = sqt.additive_delta(p, ref)
    assert_pose_close(sqt.apply_additive(ref, delta, 1.0), p, atol=2e-6)


def test_additive_delta_of_reference_is_identity():
    ref = random_poses(9, 24)
    delta = sqt.additive_delta(ref, ref)
    assert_pose_close(delta, sqt.identity_pose(9), atol=2e-7)


def test_apply_additive_weight_zero_gives_base():
    base, p, ref = random_poses(8, 25), random_poses(8, 26), random_poses(8, 27)
    out = sqt.apply_additive(base, sqt.additive_delta(p, ref), 0.0)
    np.testing.assert_allclose(out, base, rtol=0, atol=2e-7)


def test_apply_additive_matches_matrix_composition():
    base, p, ref = random_poses(8, 28), random_poses(8, 29), random_poses(8, 30)
    out = sqt.apply_additive(base, sqt.additive_delta(p, ref), 1.0)
    r = lambda x: quat.to_matrix(x[:, ROT].astype(np.float64))   # noqa: E731
    expect = r(base) @ np.linalg.inv(r(ref)) @ r(p)
    np.testing.assert_allclose(r(out), expect, atol=3e-6)
    np.testing.assert_allclose(out[:, TRANS], base[:, TRANS] + p[:, TRANS] - ref[:, TRANS],
                               atol=1e-6)
    np.testing.assert_allclose(out[:, SCALE], base[:, SCALE] * p[:, SCALE] / ref[:, SCALE],
                               rtol=1e-6)


def test_apply_additive_partial_and_per_bone_weight():
    base = random_poses(4, 31)
    delta = sqt.identity_pose(4)
    angle = 1.2
    delta[:, ROT] = [np.cos(angle / 2), 0, np.sin(angle / 2), 0]
    delta[:, TRANS] = [0.0, 2.0, 0.0]
    delta[:, SCALE] = 3.0
    w = np.array([0.0, 0.5, 1.0, 0.25], np.float32)
    out = sqt.apply_additive(base, delta, w)
    np.testing.assert_allclose(out[0], base[0], atol=2e-7)
    np.testing.assert_allclose(out[:, TRANS], base[:, TRANS] + w[:, None] * [0, 2, 0],
                               atol=1e-6)
    np.testing.assert_allclose(out[:, SCALE], base[:, SCALE] * (1 + 2 * w[:, None]), rtol=1e-6)
    # w = 1 applies the full delta; 0.5 (nlerp of identity and delta) lies between
    full = quat.multiply(base[2, ROT].astype(np.float64), delta[2, ROT].astype(np.float64))
    assert_rot_close(out[2, ROT], full, 1e-6)
    half_delta = quat.nlerp(np.array([1.0, 0, 0, 0]), delta[1, ROT].astype(np.float64), 0.5)
    assert_rot_close(out[1, ROT], quat.multiply(base[1, ROT].astype(np.float64), half_delta),
                     1e-6)


@pytest.mark.parametrize("seed", range(5))
def test_additive_round_trip_property(seed):
    rng = np.random.default_rng(100 + seed)
    b = int(rng.integers(1, 30))
    p, ref = random_poses(b, 200 + seed), random_poses(b, 300 + seed)
    back = sqt.apply_additive(ref, sqt.additive_delta(p, ref), 1.0)
    assert_pose_close(back, p, atol=3e-6)
    np.testing.assert_allclose(np.linalg.norm(back[:, ROT], axis=1), 1, atol=1e-6)


def rot_z(angle_deg):
    p = sqt.identity_pose(1)
    a = np.radians(angle_deg)
    p[0, ROT] = [np.cos(a / 2), 0, 0, np.sin(a / 2)]
    return p


def test_blend_weighted_ignores_zero_weight_child_for_shortest_arc():
    # 80 and 200 degrees about z are 120 degrees apart: their midpoint is 140 degrees.
    # Child 0 (0 degrees, weight 0) must not change that.
    poses = np.stack([rot_z(0), rot_z(80), rot_z(200)])[None]
    out = sqt.blend_weighted(poses, np.array([[0.0, 0.5, 0.5]], np.float32))
    assert_pose_close(out[0], rot_z(140), atol=1e-6)
