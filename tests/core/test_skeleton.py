"""Skeleton validation, parents-first ordering, bind matrices and local -> model."""

import numpy as np
import pytest

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.base import quaternion as quat
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.base.skeleton import Skeleton, local_to_model
from crowd_addon.core.authoring.synthetic import humanoid


def bind(n, seed=0):
    """Random valid bind pose (n, 10) with rotations, translations and scales."""
    rng = np.random.default_rng(seed)
    p = np.empty((n, 10))
    p[:, sqt.SCALE] = rng.uniform(0.8, 1.2, (n, 3))
    q = rng.normal(size=(n, 4))
    p[:, sqt.ROT] = q / np.linalg.norm(q, axis=1, keepdims=True)
    p[:, sqt.TRANS] = rng.normal(size=(n, 3))
    return p


def naive_model(local, parents):
    """Reference local -> model: one bone at a time, recursing to the root."""
    n, b = local.shape[:2]
    out = np.empty_like(local)
    for k in range(n):
        for i in range(b):
            m = local[k, i]
            p = parents[i]
            while p >= 0:
                m = local[k, p] @ m
                p = parents[p]
            out[k, i] = m
    return out


# ---------------------------------------------------------------- validation

def test_duplicate_bone_names():
    with pytest.raises(CrowdError, match=r"duplicate bone name 'arm'"):
        Skeleton("s", ["root", "arm", "arm"], [-1, 0, 0], bind(3))
    with pytest.raises(CrowdError, match=r"duplicate bone name 'arm'"):
        Skeleton.from_parent_names("s", ["arm", "root", "arm"], ["root", None, "root"],
                                   bind(3))


def test_parent_after_child():
    with pytest.raises(CrowdError, match=r"bone 'hand' comes before its parent 'arm'"):
        Skeleton("s", ["root", "hand", "arm"], [-1, 2, 0], bind(3))


def test_self_parent_is_a_cycle():
    with pytest.raises(CrowdError, match=r"cycle in parents: .*'?spin'?"):
        Skeleton("s", ["root", "spin"], [-1, 1], bind(2))


def test_cycle_direct():
    with pytest.raises(CrowdError, match=r"cycle in parents: (a -> b -> a|b -> a -> b)"):
        Skeleton("s", ["root", "a", "b"], [-1, 2, 1], bind(3))


def test_cycle_via_from_parent_names():
    with pytest.raises(CrowdError, match=r"cycle in parents: .*\bb\b.*\bc\b|cycle.*\bc\b.*\bb\b"):
        Skeleton.from_parent_names("s", ["a", "b", "c"], [None, "c", "b"], bind(3))


def test_cycle_reached_from_a_non_cycle_bone_names_the_cycle():
    # d hangs off a b <-> c loop; the message names the loop's bones
    with pytest.raises(CrowdError, match=r"cycle in parents: .*(b -> c|c -> b)"):
        Skeleton.from_parent_names("s", ["a", "d", "b", "c"], [None, "b", "c", "b"], bind(4))


def test_unknown_parent_name():
    with pytest.raises(CrowdError, match=r"bone 'hand' has unknown parent 'arm'"):
        Skeleton.from_parent_names("s", ["root", "hand"], [None, "arm"], bind(2))


@pytest.mark.parametrize("bad", [3, 7, -2])
def test_parent_out_of_range(bad):
    with pytest.raises(CrowdError, match=rf"bone 'c' has parent index {bad}, outside -1..2"):
        Skeleton("s", ["a", "b", "c"], [-1, 0, bad], bind(3))


def test_zero_quaternion_names_bone():
    p = bind(3)
    p[1, sqt.ROT] = 0
    with pytest.raises(CrowdError, match=r"zero rotation quaternion at bone 'spine'"):
        Skeleton("s", ["root", "spine", "head"], [-1, 0, 1], p)


@pytest.mark.parametrize("col", [0, 4, 9])
@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_bind_pose_names_bone(col, value):
    p = bind(3)
    p[2, col] = value
    with pytest.raises(CrowdError, match=r"non-finite value at bone 'head'"):
        Skeleton("s", ["root", "spine", "head"], [-1, 0, 1], p)


def test_wrong_shapes():
    with pytest.raises(CrowdError, match=r"skeleton 'rig' bind pose: expected shape \(3, 10\)"):
        Skeleton("rig", ["a", "b", "c"], [-1, 0, 1], bind(3)[:, :9])
    with pytest.raises(CrowdError, match=r"skeleton 'rig' bind pose: expected shape \(3, 10\)"):
        Skeleton("rig", ["a", "b", "c"], [-1, 0, 1], bind(2))
    with pytest.raises(CrowdError, match=r"skeleton 'rig': 2 parents for 3 bones"):
        Skeleton("rig", ["a", "b", "c"], [-1, 0], bind(3))
    with pytest.raises(CrowdError, match=r"skeleton 'rig': inverse_bind must be finite"):
        Skeleton("rig", ["a", "b", "c"], [-1, 0, 1], bind(3), inverse_bind=np.zeros((3, 3, 3)))
    inv = np.broadcast_to(np.eye(4), (3, 4, 4)).copy()
    inv[1, 0, 0] = np.nan
    with pytest.raises(CrowdError, match=r"skeleton 'rig': inverse_bind must be finite"):
        Skeleton("rig", ["a", "b", "c"], [-1, 0, 1], bind(3), inverse_bind=inv)


def test_empty_skeleton_and_empty_name():
    with pytest.raises(CrowdError, match=r"skeleton 'e': it has no bones"):
        Skeleton("e", [], [], np.zeros((0, 10)))
    with pytest.raises(CrowdError, match=r"bone 1 has an empty name"):
        Skeleton("e", ["a", ""], [-1, 0], bind(2))


def test_from_parent_names_length_mismatch_is_crowd_error():
    with pytest.raises(CrowdError, match=r"skeleton 's'"):
        Skeleton.from_parent_names("s", ["a", "b", "c"], [None, "a"], bind(3))


def test_from_parent_names_bind_rows_mismatch_is_crowd_error():
    with pytest.raises(CrowdError, match=r"skeleton 's'"):
        Skeleton.from_parent_names("s", ["a", "b", "c"], [None, "a", "b"], bind(2))
    with pytest.raises(CrowdError, match=r"skeleton 's'"):
        Skeleton.from_parent_names("s", ["a", "b", "c"], [None, "a", "b"], bind(4))


def test_bone_index():
    sk = humanoid()
    assert sk.bone_index("head") == sk.bone_names.index("head")
    with pytest.raises(CrowdError, match=r"skeleton 'fan' has no bone 'tail'"):
        sk.bone_index("tail")


# ------------------------------------------------------------------ structure

def test_several_roots_allowed():
    p = bind(5, 1)
    sk = Skeleton("two", ["r1", "a", "r2", "b", "c"], [-1, 0, -1, 2, 3], p)
    assert sk.bone_count == 5
    np.testing.assert_array_equal(sk.parents, [-1, 0, -1, 2, 3])
    m = sqt.pose_to_matrices(sk.bind_pose)
    np.testing.assert_allclose(sk.bind_model[2], m[2], atol=1e-12)   # a root is its own
    np.testing.assert_allclose(sk.bind_model[4], m[2] @ m[3] @ m[4], atol=1e-12)


def test_bind_pose_normalised_float32():
    p = bind(3, 2)
    p[:, sqt.ROT] *= 3.0
    sk = Skeleton("s", ["a", "b", "c"], [-1, 0, 0], p)
    assert sk.bind_pose.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(sk.bind_pose[:, sqt.ROT], axis=1), 1, atol=1e-6)
    np.testing.assert_allclose(sk.bind_pose[:, sqt.ROT], p[:, sqt.ROT] / 3.0, atol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_from_parent_names_reorders_any_order(seed):
    ref = humanoid(bones=40)
    rng = np.random.default_rng(seed)
    perm = rng.permutation(ref.bone_count)
    names = [ref.bone_names[i] for i in perm]
    parent_names = [None if ref.parents[i] < 0 else ref.bone_names[ref.parents[i]]
                    for i in perm]
    pose = bind(ref.bone_count, seed)            # distinct rows so misalignment shows
    shuffled = pose[perm]
    sk = Skeleton.from_parent_names("shuf", names, parent_names, shuffled)
    assert sorted(sk.bone_names) == sorted(ref.bone_names)
    assert all(p < i for i, p in enumerate(sk.parents))
    for i, n in enumerate(sk.bone_names):
        j = ref.bone_names.index(n)
        p = sk.parents[i]
        expect_parent = None if ref.parents[j] < 0 else ref.bone_names[ref.parents[j]]
        assert (None if p < 0 else sk.bone_names[p]) == expect_parent
        np.testing.assert_allclose(sk.bind_pose[i], pose[j].astype(np.float32), atol=1e-7)


def test_from_parent_names_keeps_inverse_bind_rows_aligned():
    names = ["c", "a", "b"]
    parents = ["b", None, "a"]
    inv = np.stack([np.diag([k + 1.0, 1, 1, 1]) for k in range(3)])
    sk = Skeleton.from_parent_names("s", names, parents, bind(3), inverse_bind=inv)
    assert sk.bone_names == ("a", "b", "c")
    for i, n in enumerate(sk.bone_names):
        np.testing.assert_array_equal(sk.inverse_bind[i], inv[names.index(n)])


def test_from_parent_names_depth_first_siblings_in_given_order():
    sk = Skeleton.from_parent_names(
        "s", ["x2", "root", "x1", "y", "x1c"], ["root", None, "root", None, "x1"], bind(5))
    # roots in given order (root, y); children of root in given order (x2, x1)
    assert sk.bone_names == ("root", "x2", "x1", "x1c", "y")
    np.testing.assert_array_equal(sk.parents, [-1, 0, 0, 2, -1])


# ----------------------------------------------------------- bind matrices

def test_bind_model_times_inverse_bind_is_identity():
    for sk in (humanoid(), Skeleton("r", list("abcdef"), [-1, 0, 1, 0, 3, -1], bind(6, 3))):
        prod = sk.bind_model @ sk.inverse_bind
        np.testing.assert_allclose(prod, np.broadcast_to(np.eye(4), prod.shape), atol=1e-9)


def test_humanoid_bind_model_translations_are_summed_offsets():
    sk = humanoid()
    off = sk.bind_pose[:, sqt.TRANS].astype(np.float64)
    for i in range(sk.bone_count):
        total, p = off[i].copy(), sk.parents[i]
        while p >= 0:
            total += off[p]
            p = sk.parents[p]
        np.testing.assert_allclose(sk.bind_model[i, :3, 3], total, atol=1e-6)
        np.testing.assert_allclose(sk.bind_model[i, :3, :3], np.eye(3), atol=1e-12)


def test_bind_model_matches_naive_loop():
    sk = Skeleton("r", list("abcdefg"), [-1, 0, 1, 1, 3, -1, 5], bind(7, 4))
    local = sqt.pose_to_matrices(sk.bind_pose)[None]
    np.testing.assert_allclose(sk.bind_model, naive_model(local, sk.parents)[0], atol=1e-12)


def test_explicit_inverse_bind_is_kept():
    inv = np.broadcast_to(np.eye(4), (3, 4, 4)).copy()
    inv[:, 0, 3] = [1, 2, 3]
    sk = Skeleton("s", ["a", "b", "c"], [-1, 0, 1], bind(3), inverse_bind=inv)
    np.testing.assert_array_equal(sk.inverse_bind, inv)


# ------------------------------------------------------------ local_to_model

@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_local_to_model_matches_naive_loop(dtype):
    sk = humanoid()
    rng = np.random.default_rng(5)
    n = 3
    poses = np.empty((n, sk.bone_count, 10))
    poses[..., sqt.SCALE] = rng.uniform(0.9, 1.1, (n, sk.bone_count, 3))
    poses[..., sqt.ROT] = quat.normalize(rng.normal(size=(n, sk.bone_count, 4)))
    poses[..., sqt.TRANS] = rng.normal(scale=0.2, size=(n, sk.bone_count, 3))
    local = sqt.pose_to_matrices(poses).astype(dtype)
    out = local_to_model(local, sk)
    assert out.dtype == dtype and out.shape == local.shape
    ref = naive_model(local.astype(np.float64), sk.parents)
    np.testing.assert_allclose(out, ref, atol=1e-12 if dtype == np.float64 else 2e-5)
    # the input is not modified
    np.testing.assert_array_equal(local, sqt.pose_to_matrices(poses).astype(dtype))


def test_local_to_model_several_roots_and_levels():
    sk = Skeleton("r", list("abcdefgh"), [-1, 0, -1, 1, 2, 4, 0, 5], bind(8, 6))
    depths = [len(b) for b, _ in sk.levels]
    assert sum(depths) == 6                     # every non-root bone in exactly one level
    local = sqt.pose_to_matrices(np.stack([bind(8, 7), bind(8, 8)]))
    np.testing.assert_allclose(local_to_model(local, sk), naive_model(local, sk.parents),
                               atol=1e-12)
