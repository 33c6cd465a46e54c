"""Armature arrays -> skeletons, local transforms, SQT and skin influences
(crowd_addon.core.bake.armature_math), against matrix products computed here. Blender's
rest pose and Armature modifier as the oracle: tests/blender/test_armature.py."""

import numpy as np
import pytest

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.base import quaternion as quat
from crowd_addon.core.bake.armature_math import (check_hierarchy, relative_to_parent,
                                                 rest_skeleton, sqt_from_matrices,
                                                 vertex_influences)
from crowd_addon.core.base.errors import CrowdError

# children before their parents, as Blender may list them
NAMES = ["hand", "arm", "root", "leg"]
PARENTS = ["arm", "root", None, "root"]


def random_pose(rng, shape, scale=(0.5, 2.0)):
    """Random SQT poses (float64, unit rotations)."""
    pose = np.empty(shape + (sqt.WIDTH,))
    pose[..., sqt.SCALE] = rng.uniform(*scale, shape + (3,))
    pose[..., sqt.ROT] = quat.normalize(rng.normal(size=shape + (4,)))
    pose[..., sqt.TRANS] = rng.normal(size=shape + (3,))
    return pose


def model_matrices(local, parents):
    """Model matrices of local ones, parents listed anywhere (recursive product)."""
    model = np.empty_like(local)
    done = {}

    def of(i):
        if i not in done:
            own = local[..., i, :, :]
            done[i] = own if parents[i] < 0 else of(parents[i]) @ own
        return done[i]

    for i in range(len(parents)):
        model[..., i, :, :] = of(i)
    return model


def test_relative_to_parent_inverts_the_model_product():
    rng = np.random.default_rng(0)
    parents = np.array([1, 2, -1, 2])
    local = sqt.pose_to_matrices(random_pose(rng, (3, 4)))                # (3, 4, 4, 4)
    model = model_matrices(local, parents)
    np.testing.assert_allclose(relative_to_parent(model, parents), local, atol=1e-10)
    inverse = np.linalg.inv(model[0])
    np.testing.assert_allclose(relative_to_parent(model[0], parents, inverse), local[0],
                               atol=1e-10)


def test_rest_skeleton_orders_parents_first_and_binds_the_rest_pose():
    rng = np.random.default_rng(1)
    parents = np.array([1, 2, -1, 2])
    local = sqt.pose_to_matrices(random_pose(rng, (4,), scale=(1, 1)))
    rest = model_matrices(local, parents)                                  # armature space
    sk, rel, rot = rest_skeleton("Rig", NAMES, PARENTS, rest)
    assert sk.name == "Rig" and sk.bone_names == ("root", "arm", "hand", "leg")
    order = [NAMES.index(n) for n in sk.bone_names]
    np.testing.assert_allclose(sk.bind_model, rest[order], atol=1e-6)   # float32 bind pose
    np.testing.assert_allclose(sk.inverse_bind, np.linalg.inv(rest[order]), atol=1e-10)
    np.testing.assert_allclose(rel, local, atol=1e-10)                     # armature order
    np.testing.assert_allclose(quat.to_matrix(rot), local[:, :3, :3], atol=1e-10)
    check_hierarchy(sk, "Rig", NAMES, PARENTS)
    with pytest.raises(CrowdError, match=r"does not match armature 'Other': bones only in "
                                         r"the skeleton \['leg'\], only in the armature "
                                         r"\['tail'\]"):
        check_hierarchy(sk, "Other", NAMES[:3] + ["tail"], PARENTS)
    with pytest.raises(CrowdError, match=r"bone 'hand' has a different parent than in "
                                         r"armature 'Other' \('root'\)"):
        check_hierarchy(sk, "Other", NAMES, ["root", "root", None, "root"])


def test_sqt_from_matrices_round_trips_and_flips_mirrored_x():
    rng = np.random.default_rng(2)
    pose = random_pose(rng, (5, 3))
    got = sqt_from_matrices(sqt.pose_to_matrices(pose), ["a", "b", "c"], "test")
    np.testing.assert_allclose(pose_to_abs_rot(got), pose_to_abs_rot(pose), atol=1e-9)
    mirrored = sqt.pose_to_matrices(pose)
    mirrored[..., :3, 0] *= -1
    flipped = sqt_from_matrices(mirrored, ["a", "b", "c"], "test")
    assert (flipped[..., 0] < 0).all()
    np.testing.assert_allclose(sqt.pose_to_matrices(flipped), mirrored, atol=1e-9)


def pose_to_abs_rot(p):
    """SQT with the rotation sign made unique (q and -q are one rotation)."""
    p = p.copy()
    p[..., sqt.ROT] *= np.where(p[..., 3:4] < 0, -1, 1)
    return p


def test_sqt_from_matrices_names_shear_and_zero_scale():
    m = np.tile(np.eye(4), (4, 2, 1, 1))
    m[2, 1, 0, 1] = 0.5                                      # shear
    with pytest.raises(CrowdError, match=r"action 'Walk': bone 'b' at frame 7.5 has shear"):
        sqt_from_matrices(m, ["a", "b"], "action 'Walk'", frame_labels=[1, 3, 7.5, 9])
    m = np.tile(np.eye(4), (2, 1, 1))
    m[0, 1, 1] = 0.0
    with pytest.raises(CrowdError, match=r"rest: bone 'a' has zero scale"):
        sqt_from_matrices(m, ["a", "b"], "rest")


def test_vertex_influences_pack_memberships_per_vertex():
    # vertex 0: groups 0 (bone 1) and 2 (bone 3); vertex 1: none; vertex 2: group 1
    # (deforms no bone) and group 7 (no such group)
    idx, wt = vertex_influences(np.array([2, 0, 2]), np.array([0, 2, 1, 7]),
                                np.array([0.5, 0.3, 0.9, 0.4]), np.array([1, -1, 3, -1]))
    assert idx.tolist() == [[1, 3], [0, 0], [0, 0]]
    np.testing.assert_array_equal(wt, [[0.5, 0.3], [0, 0], [0, 0]])
    idx, wt = vertex_influences(np.zeros(2, np.int64), np.zeros(0), np.zeros(0),
                                np.array([-1]))
    assert idx.shape == wt.shape == (2, 1) and not wt.any()


def test_affine_inverse_equals_lapack_on_rest_and_scaled_matrices():
    from crowd_addon.core.base.skeleton import affine_inverse
    rng = np.random.default_rng(3)
    m = np.zeros((64, 4, 4))
    m[:, :3, :3] = rng.normal(size=(64, 3, 3))
    m[:, :3, 3] = rng.normal(size=(64, 3)) * 5
    m[:, 3, 3] = 1
    np.testing.assert_allclose(affine_inverse(m), np.linalg.inv(m), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(affine_inverse(m[:2].reshape(2, 1, 4, 4))[:, 0],
                               np.linalg.inv(m[:2]), rtol=1e-9, atol=1e-9)
