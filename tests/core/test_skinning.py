"""Skinning matrices (paper Eq. 1) and the CPU reference skinning.

The oracle here is a naive float64 implementation written from the definitions:
local = T @ R @ S, model = model[parent] @ local, skin = model @ inverse(bind model).
"""

import numpy as np
import pytest

from crowd_addon.core import Skeleton, SkinningPlan, skin_vertices, skinning_matrices
from crowd_addon.core.base import pose as sqt
from crowd_addon.core.authoring.synthetic import humanoid

# several roots (0, 4, 9); depth is not sorted by index
PARENTS = [-1, 0, 1, 2, -1, 4, 0, 6, 3, -1, 9, 5, 1, 8, 11]


def random_pose(rng, n, b, scale=(0.6, 1.5)):
    q = rng.normal(size=(n, b, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return sqt.make_pose(scale=rng.uniform(*scale, (n, b, 3)), rotation=q,
                         translation=rng.normal(0, 0.5, (n, b, 3))).astype(np.float32)


def quat_matrix(q):
    w, x, y, z = (float(v) for v in q)
    n = w * w + x * x + y * y + z * z
    w, x, y, z = (v / np.sqrt(n) for v in (w, x, y, z))
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def naive_model(local, parents):
    """(B, 10) SQT -> (B, 4, 4) float64 model matrices, one bone at a time."""
    out = np.zeros((len(parents), 4, 4))
    for i, p in enumerate(parents):
        m = np.eye(4)
        m[:3, :3] = quat_matrix(local[i, 3:7]) @ np.diag(np.float64(local[i, 0:3]))
        m[:3, 3] = local[i, 7:10]
        out[i] = m if p < 0 else out[p] @ m
    return out


def naive_skin(local, skeleton_bind, parents):
    bind_model = naive_model(np.asarray(skeleton_bind, np.float64), parents)
    model = naive_model(np.asarray(local, np.float64), parents)
    return np.stack([model[i] @ np.linalg.inv(bind_model[i]) for i in range(len(parents))])


@pytest.fixture(scope="module")
def forest():
    rng = np.random.default_rng(7)
    bind = random_pose(rng, 1, len(PARENTS), scale=(0.8, 1.3))[0]
    names = [f"b{i}" for i in range(len(PARENTS))]
    return Skeleton("forest", names, PARENTS, bind)


def test_forest_really_has_unsorted_depth(forest):
    depth = []
    for p in PARENTS:
        depth.append(0 if p < 0 else depth[p] + 1)
    assert sum(d == 0 for d in depth) == 3
    assert depth != sorted(depth)


def test_plan_rows_match_float64_reference(forest):
    rng = np.random.default_rng(1)
    local = random_pose(rng, 6, forest.bone_count)
    rows = SkinningPlan(forest).rows(local)
    assert rows.shape == (6, forest.bone_count, 3, 4) and rows.dtype == np.float32
    ref = skinning_matrices(local, forest)
    for n in range(6):
        naive = naive_skin(local[n], forest.bind_pose, PARENTS)
        scale = np.abs(naive).max()
        np.testing.assert_allclose(ref[n], naive, atol=1e-6 * scale)  # float32 inputs
        np.testing.assert_allclose(rows[n], naive[:, :3, :], rtol=1e-5, atol=2e-6 * scale)
        np.testing.assert_array_equal(ref[n, :, 3], np.tile([0, 0, 0, 1], (15, 1)))


def test_plan_rows_humanoid_with_nonuniform_scale():
    sk = humanoid(bones=28)
    rng = np.random.default_rng(3)
    local = np.broadcast_to(sk.bind_pose, (4, 28, 10)).copy()
    pert = random_pose(rng, 4, 28, scale=(0.7, 1.4))
    local[..., sqt.SCALE] = pert[..., sqt.SCALE]
    local[..., sqt.ROT] = pert[..., sqt.ROT]
    rows = SkinningPlan(sk).rows(local)
    for n in range(4):
        naive = naive_skin(local[n], sk.bind_pose, list(sk.parents))
        np.testing.assert_allclose(rows[n], naive[:, :3], rtol=1e-5,
                                   atol=2e-6 * np.abs(naive).max())


def test_plan_rows_wider_row_and_out_view(forest):
    rng = np.random.default_rng(2)
    local = random_pose(rng, 3, forest.bone_count)
    wide = np.concatenate([local, random_pose(rng, 3, 5)], axis=1)   # extra bones ignored
    plan = SkinningPlan(forest, row_bones=20)
    out = np.full((3, 20, 3, 4), 7.0, np.float32)
    got = plan.rows(wide, out=out)
    assert got is out
    np.testing.assert_array_equal(out[:, 15:], 7.0)                   # untouched
    fresh = plan.rows(local)
    assert fresh.shape == (3, 20, 3, 4)
    np.testing.assert_array_equal(fresh[:, 15:], np.broadcast_to(np.eye(4)[:3], (3, 5, 3, 4)))
    np.testing.assert_array_equal(fresh[:, :15], out[:, :15])
    ref = skinning_matrices(local, forest)[:, :, :3]
    np.testing.assert_allclose(fresh[:, :15], ref, rtol=1e-5, atol=2e-6 * np.abs(ref).max())


def test_bind_pose_gives_identity_skinning(forest):
    for sk in (forest, humanoid(bones=24)):
        rows = SkinningPlan(sk).rows(sk.bind_pose[None])[0]
        np.testing.assert_allclose(rows, np.broadcast_to(np.eye(4)[:3], rows.shape),
                                   atol=1e-5)
        ref = skinning_matrices(sk.bind_pose[None], sk)[0]
        np.testing.assert_allclose(ref, np.broadcast_to(np.eye(4), ref.shape), atol=1e-6)


# ------------------------------------------------------------- vertex skinning


def mesh(rng, v=40, b=15):
    verts = rng.normal(size=(v, 3))
    idx = rng.integers(0, b, (v, 4))
    w = rng.uniform(0, 2, (v, 4))
    w[::3, 3] = 0                      # some vertices with fewer influences
    w[::5, 1:] = 0                     # some with a single bone
    return verts, idx, w


def naive_vertices(verts, idx, w, mats):
    out = np.zeros((mats.shape[0], len(verts), 3))
    for n in range(mats.shape[0]):
        for v in range(len(verts)):
            total = sum(w[v])
            acc = np.zeros(3)
            for i in range(4):
                m = np.asarray(mats[n, idx[v, i]], np.float64)
                acc += (w[v, i] / total) * (m[:3, :3] @ verts[v] + m[:3, 3])
            out[n, v] = acc
    return out


def test_skin_vertices_equals_naive_loop(forest):
    rng = np.random.default_rng(5)
    verts, idx, w = mesh(rng)
    rows = SkinningPlan(forest).rows(random_pose(rng, 3, forest.bone_count))
    got = skin_vertices(verts, idx, w, rows)
    assert got.shape == (3, 40, 3) and got.dtype == np.float64
    np.testing.assert_allclose(got, naive_vertices(verts, idx, w, rows), rtol=1e-10,
                               atol=1e-10)
    # (n, B, 4, 4) matrices give the same result as their top three rows
    full = skinning_matrices(random_pose(rng, 2, forest.bone_count), forest)
    np.testing.assert_allclose(skin_vertices(verts, idx, w, full),
                               naive_vertices(verts, idx, w, full), rtol=1e-10, atol=1e-10)


def test_skin_vertices_renormalises_weights(forest):
    rng = np.random.default_rng(6)
    verts, idx, w = mesh(rng)
    rows = SkinningPlan(forest).rows(random_pose(rng, 2, forest.bone_count))
    unit = w / w.sum(1, keepdims=True)
    np.testing.assert_allclose(skin_vertices(verts, idx, w * 3.7, rows),
                               skin_vertices(verts, idx, unit, rows), rtol=1e-12, atol=1e-12)


def test_bind_pose_gives_rest_vertices(forest):
    rng = np.random.default_rng(8)
    verts, idx, w = mesh(rng)
    rows = SkinningPlan(forest).rows(forest.bind_pose[None])
    np.testing.assert_allclose(skin_vertices(verts, idx, w, rows)[0], verts, atol=1e-5)
    ref = skinning_matrices(forest.bind_pose[None], forest)
    np.testing.assert_allclose(skin_vertices(verts, idx, w, ref)[0], verts, atol=1e-9)


def test_single_bone_vertex_follows_its_bone(forest):
    rng = np.random.default_rng(9)
    local = random_pose(rng, 1, forest.bone_count)
    mats = naive_skin(local[0], forest.bind_pose, PARENTS)
    v = rng.normal(size=(1, 3))
    got = skin_vertices(v, np.array([[13, 0, 0, 0]]), np.array([[1.0, 0, 0, 0]]),
                        skinning_matrices(local, forest))[0, 0]
    np.testing.assert_allclose(got, mats[13, :3, :3] @ v[0] + mats[13, :3, 3], atol=1e-6)


def test_repeated_calls_with_varying_batch_sizes_do_not_alias(forest):
    rng = np.random.default_rng(11)
    plan = SkinningPlan(forest)
    batches = [random_pose(rng, n, forest.bone_count) for n in (5, 1, 9, 5, 2)]
    results = [plan.rows(b) for b in batches]
    for b, r in zip(batches, results):
        ref = skinning_matrices(b, forest)[:, :, :3]
        np.testing.assert_allclose(r, ref, rtol=1e-5, atol=2e-6 * np.abs(ref).max())
    assert plan.rows(batches[0][:0]).shape == (0, forest.bone_count, 3, 4)
