"""Quaternion math, (w, x, y, z) order, checked against independent float64 math."""

import numpy as np
import pytest

from crowd_addon.core.base import quaternion as quat

RNG_SEED = 1234


def random_quats(n, seed=RNG_SEED, dtype=np.float64):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(dtype)


def axis_angle(axis, angle):
    """Reference quaternion (w, x, y, z) for a rotation of ``angle`` about ``axis``."""
    axis = np.asarray(axis, np.float64)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = np.asarray(angle, np.float64)[..., None]
    return np.concatenate([np.cos(angle / 2), np.sin(angle / 2) * axis], axis=-1)


def rodrigues(axis, angle):
    """Reference rotation matrix (float64) from the axis-angle formula."""
    k = np.asarray(axis, np.float64)
    k = k / np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def hamilton_ref(a, b):
    """Hamilton product from the scalar/vector definition."""
    wa, va = a[..., 0], a[..., 1:]
    wb, vb = b[..., 0], b[..., 1:]
    w = wa * wb - np.sum(va * vb, axis=-1)
    v = wa[..., None] * vb + wb[..., None] * va + np.cross(va, vb)
    return np.concatenate([w[..., None], v], axis=-1)


def same_rotation(a, b, atol):
    """q and -q are the same rotation."""
    d = np.minimum(np.abs(a - b).max(axis=-1), np.abs(a + b).max(axis=-1))
    assert d.max() <= atol, f"max quaternion distance {d.max()}"


def angle_between(a, b):
    d = np.clip(np.abs(np.sum(a * b, axis=-1)), 0.0, 1.0)
    return 2 * np.arccos(d)


# ---------------------------------------------------------------- basics

def test_identity_shapes_and_values():
    assert quat.identity().shape == (4,)
    np.testing.assert_array_equal(quat.identity(), [1, 0, 0, 0])
    assert quat.identity(3).shape == (3, 4)
    q = quat.identity((2, 5), dtype=np.float64)
    assert q.shape == (2, 5, 4) and q.dtype == np.float64
    np.testing.assert_array_equal(q[..., 0], 1)
    np.testing.assert_array_equal(q[..., 1:], 0)


def test_normalize_unit_and_zero_stays_zero():
    q = np.array([[2.0, 0, 0, 0], [1, 1, 1, 1], [0, 0, 0, 0]])
    n = quat.normalize(q)
    np.testing.assert_allclose(n[0], [1, 0, 0, 0])
    np.testing.assert_allclose(n[1], [0.5, 0.5, 0.5, 0.5])
    np.testing.assert_array_equal(n[2], 0)
    assert np.isfinite(n).all()


def test_w_first_order_matches_axis_angle():
    # 90 degrees about z maps +x to +y; w is the first component.
    q = axis_angle([0, 0, 1], np.pi / 2)
    np.testing.assert_allclose(q, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)])
    np.testing.assert_allclose(quat.rotate(q, np.array([1.0, 0, 0])), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(quat.to_matrix(q), [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
                               atol=1e-15)


# ------------------------------------------------------------- multiply

def test_multiply_matches_reference_product():
    a, b = random_quats(50, 1), random_quats(50, 2)
    np.testing.assert_allclose(quat.multiply(a, b), hamilton_ref(a, b), atol=1e-15)


def test_multiply_is_matrix_product_apply_b_first():
    a, b = random_quats(50, 3), random_quats(50, 4)
    lhs = quat.to_matrix(quat.multiply(a, b))
    rhs = quat.to_matrix(a) @ quat.to_matrix(b)
    np.testing.assert_allclose(lhs, rhs, atol=1e-13)
    # and it is not commutative: the opposite order differs for generic rotations
    other = quat.to_matrix(b) @ quat.to_matrix(a)
    assert np.abs(lhs - other).max() > 1e-2


def test_multiply_broadcasts():
    a = random_quats(5, 5).reshape(5, 1, 4)
    b = random_quats(3, 6).reshape(1, 3, 4)
    out = quat.multiply(a, b)
    assert out.shape == (5, 3, 4)
    for i in range(5):
        for j in range(3):
            np.testing.assert_allclose(out[i, j], hamilton_ref(a[i, 0], b[0, j]), atol=1e-15)


def test_multiply_parts_on_components_and_into_views():
    """The component-major product (used on (4, F, B) channels and on the strided
    rotation views of packed poses) is the same product, written into ``out``."""
    a, b = random_quats(12, 7).astype(np.float32), random_quats(12, 8).astype(np.float32)
    parts = quat.multiply_parts(a.T, b.T)
    assert len(parts) == 4 and parts[0].dtype == np.float32
    np.testing.assert_array_equal(np.stack(parts, -1), quat.multiply(a, b))
    packed = np.zeros((12, 10), np.float32)                    # SQT rows, rotation 3:7
    out = quat.multiply_parts(a.T, b.T, out=[packed[:, c] for c in range(3, 7)])
    np.testing.assert_array_equal(packed[:, 3:7], np.stack(parts, -1))
    assert np.shares_memory(out[0], packed) and not packed[:, :3].any()


def test_conjugate_is_inverse():
    q = random_quats(20, 7)
    np.testing.assert_allclose(quat.multiply(q, quat.conjugate(q)),
                               np.tile([1.0, 0, 0, 0], (20, 1)), atol=1e-15)
    np.testing.assert_allclose(quat.multiply(quat.conjugate(q), q),
                               np.tile([1.0, 0, 0, 0], (20, 1)), atol=1e-15)


def test_rotate_matches_rodrigues():
    rng = np.random.default_rng(8)
    for _ in range(20):
        axis = rng.normal(size=3)
        angle = rng.uniform(-np.pi, np.pi)
        v = rng.normal(size=3)
        q = axis_angle(axis, angle)
        np.testing.assert_allclose(quat.rotate(q, v), rodrigues(axis, angle) @ v, atol=1e-13)


def test_dtype_float32_kept():
    q = random_quats(4, 9, np.float32)
    assert quat.multiply(q, q).dtype == np.float32
    assert quat.normalize(q).dtype == np.float32
    assert quat.to_matrix(q).dtype == np.float32
    assert quat.nlerp(q, q[::-1], 0.3).dtype == np.float32
    assert quat.slerp(q, q[::-1], 0.3).dtype == np.float32


# --------------------------------------------------- to_matrix / from_matrix

def test_to_matrix_matches_rodrigues():
    rng = np.random.default_rng(10)
    for _ in range(30):
        axis = rng.normal(size=3)
        angle = rng.uniform(-np.pi, np.pi)
        np.testing.assert_allclose(quat.to_matrix(axis_angle(axis, angle)),
                                   rodrigues(axis, angle), atol=1e-13)


def test_to_matrix_is_orthonormal_and_sign_invariant():
    q = random_quats(100, 11)
    m = quat.to_matrix(q)
    np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(3), m.shape),
                               atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-13)
    np.testing.assert_allclose(quat.to_matrix(-q), m, atol=1e-15)


def test_from_matrix_round_trip_random():
    q = random_quats(500, 12)
    back = quat.from_matrix(quat.to_matrix(q))
    assert back.dtype == np.float64
    assert (back[:, 0] >= 0).all()
    same_rotation(back, q, 1e-12)


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 1, 1),
                                  (0.3, -0.2, 0.9), (-1, 2, -3)])
@pytest.mark.parametrize("eps", [0.0, 1e-9, 1e-6, 1e-3, 0.05])
def test_from_matrix_near_180_degrees(axis, eps):
    for angle in (np.pi - eps, -(np.pi - eps), np.pi + eps):
        m = rodrigues(axis, angle)
        q = quat.from_matrix(m)
        np.testing.assert_allclose(np.linalg.norm(q), 1.0, atol=1e-12)
        np.testing.assert_allclose(quat.to_matrix(q), m, atol=1e-9)
        same_rotation(q, axis_angle(axis, angle), 1e-8)


def test_from_matrix_exact_half_turns_and_identity():
    for axis in np.eye(3):
        q = quat.from_matrix(rodrigues(axis, np.pi))
        same_rotation(q, np.concatenate([[0.0], axis]), 1e-12)
    np.testing.assert_allclose(quat.from_matrix(np.eye(3)), [1, 0, 0, 0], atol=1e-15)


def test_from_matrix_batched_shape():
    q = random_quats(24, 13).reshape(2, 3, 4, 4)
    back = quat.from_matrix(quat.to_matrix(q))
    assert back.shape == (2, 3, 4, 4)
    same_rotation(back.reshape(-1, 4), q.reshape(-1, 4), 1e-12)


# ------------------------------------------------------------------ nlerp

def test_nlerp_endpoints():
    a, b = random_quats(30, 14), random_quats(30, 15)
    np.testing.assert_allclose(quat.nlerp(a, b, 0.0), a, atol=1e-15)
    same_rotation(quat.nlerp(a, b, 1.0), b, 1e-15)


def test_nlerp_shortest_arc_q_and_minus_q_same_result():
    a, b = random_quats(200, 16), random_quats(200, 17)
    for t in (0.1, 0.5, 0.77):
        np.testing.assert_allclose(quat.nlerp(a, b, t), quat.nlerp(a, -b, t), atol=1e-15)


def test_nlerp_takes_short_way():
    a = axis_angle([0, 0, 1], 0.0)
    b = -axis_angle([0, 0, 1], 2.8)            # 160 degrees, given in the far hemisphere
    mid = quat.nlerp(a, b, 0.5)
    np.testing.assert_allclose(angle_between(mid, a), 1.4, atol=1e-12)
    np.testing.assert_allclose(angle_between(mid, b), 1.4, atol=1e-12)
    assert mid[3] > 0                           # turns the same way as +z


def test_nlerp_reference_and_per_element_t():
    a, b = random_quats(40, 18), random_quats(40, 19)
    t = np.linspace(0, 1, 40)
    sign = np.where(np.sum(a * b, axis=1) < 0, -1.0, 1.0)[:, None]
    ref = a * (1 - t[:, None]) + sign * b * t[:, None]
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    np.testing.assert_allclose(quat.nlerp(a, b, t), ref, atol=1e-14)


# ------------------------------------------------------------------ slerp

def test_slerp_endpoints():
    a, b = random_quats(30, 20), random_quats(30, 21)
    np.testing.assert_allclose(quat.slerp(a, b, 0.0), a, atol=1e-14)
    same_rotation(quat.slerp(a, b, 1.0), b, 1e-14)


def test_slerp_midpoint_angle_and_constant_speed():
    a, b = random_quats(100, 22), random_quats(100, 23)
    theta = angle_between(a, b)
    mid = quat.slerp(a, b, 0.5)
    np.testing.assert_allclose(angle_between(a, mid), theta / 2, atol=1e-7)
    np.testing.assert_allclose(angle_between(mid, b), theta / 2, atol=1e-7)
    for t in (0.1, 0.3, 0.9):
        np.testing.assert_allclose(angle_between(a, quat.slerp(a, b, t)), t * theta, atol=1e-7)


def test_slerp_matches_axis_angle_path():
    axis = np.array([0.2, -0.5, 0.8])
    a = axis_angle(axis, 0.3)
    b = axis_angle(axis, 2.9)
    for t in np.linspace(0, 1, 11):
        same_rotation(quat.slerp(a, b, t), axis_angle(axis, 0.3 + t * 2.6), 1e-12)


def test_slerp_shortest_arc_and_close_inputs():
    a, b = random_quats(50, 24), random_quats(50, 25)
    np.testing.assert_allclose(quat.slerp(a, b, 0.3), quat.slerp(a, -b, 0.3), atol=1e-14)
    # nearly identical inputs take the nlerp fallback, still finite and unit length
    c = quat.normalize(a + 1e-9)
    out = quat.slerp(a, c, 0.5)
    assert np.isfinite(out).all()
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-12)
    same_rotation(out, a, 1e-8)
