"""The two conventions that differ between core and USD (quaternion order, matrix
layout), pinned against Gf's own math, and the names USD needs."""

import numpy as np
from pxr import Gf, Sdf, Usd, UsdSkel, Vt

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.base import quaternion as quat
from crowd_addon.usd import convert
from crowd_addon.usd.naming import joint_paths, unique_identifiers


def random_quats(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32)


def test_quaternion_round_trip_through_gf_quatf():
    q = random_quats(16)                                       # core (w, x, y, z)
    pose = sqt.make_pose(rotation=q)
    _, rotations, _ = convert.sqt_components(pose)
    vt = convert.rotations(rotations)
    for k, g in enumerate(vt):
        assert g == Gf.Quatf(*q[k].tolist())                   # Gf.Quatf(real, i, j, k)
        assert g.GetReal() == q[k, 0]
        assert tuple(g.GetImaginary()) == tuple(q[k, 1:].tolist())
    back = np.array([[g.GetReal(), *g.GetImaginary()] for g in vt], np.float32)
    np.testing.assert_array_equal(back, q)


def test_rotation_matrix_from_usd_quaternion_is_cores():
    """Gf builds the rotation from the converted quaternion; it must be core's (row
    vectors in Gf, so transposed)."""
    q = random_quats(8, seed=1)
    _, rotations, _ = convert.sqt_components(sqt.make_pose(rotation=q))
    for k, g in enumerate(convert.rotations(rotations)):
        gf = np.array(Gf.Matrix4d().SetRotate(Gf.Quatd(g.GetReal(), Gf.Vec3d(g.GetImaginary()))))
        np.testing.assert_allclose(gf[:3, :3].T, quat.to_matrix(q[k].astype(np.float64)),
                                   atol=1e-6)


def test_quaternions_survive_a_written_skel_animation(tmp_path):
    """Through an actual layer file and UsdSkel's decomposition of the local transform."""
    q = random_quats(5, seed=2)
    pose = sqt.make_pose(rotation=q, translation=np.arange(15).reshape(5, 3))
    t, r, s = convert.sqt_components(pose)
    stage = Usd.Stage.CreateNew(str(tmp_path / "q.usda"))
    anim = UsdSkel.Animation.Define(stage, "/Anim")
    anim.CreateJointsAttr(Vt.TokenArray([f"j{i}" for i in range(5)]))
    anim.CreateRotationsAttr(convert.rotations(r))
    anim.CreateTranslationsAttr(convert.translations(t))
    anim.CreateScalesAttr(convert.scales(s))
    stage.Save()
    del stage, anim                                   # release the layer: read the file
    reopened = Usd.Stage.Open(str(tmp_path / "q.usda"))
    anim = UsdSkel.Animation(reopened.GetPrimAtPath("/Anim"))
    local = np.array(anim.GetTransforms(Usd.TimeCode.Default())).transpose(0, 2, 1)
    np.testing.assert_allclose(local, sqt.pose_to_matrices(pose), atol=1e-6)


def test_matrices_are_transposed_for_gf():
    m = np.eye(4)[None].repeat(2, 0)
    m[:, :3, :3] = quat.to_matrix(random_quats(2, seed=3).astype(np.float64))
    m[:, :3, 3] = [[1, 2, 3], [-4, 5, 0.5]]
    p = np.array([0.3, -0.7, 2.0])
    for k, g in enumerate(convert.matrices(m)):
        np.testing.assert_allclose(np.array(g.Transform(Gf.Vec3d(*p))),
                                   m[k, :3, :3] @ p + m[k, :3, 3], atol=1e-12)


def test_joint_paths_are_valid_and_distinct():
    names = ["root", "a.b", "a_b", "a b", "spine", "3rd", "x.y"]
    parents = [-1, 0, 0, 0, 0, 4, 1]
    paths = joint_paths(names, parents)
    assert paths[:5] == ["root", "root/a_b", "root/a_b_1", "root/a_b_2", "root/spine"]
    assert paths[6] == "root/a_b/x_y"
    assert len(set(paths)) == len(paths)
    assert all(Sdf.Path.IsValidPathString(p) for p in paths)
    topo = UsdSkel.Topology(Vt.TokenArray(paths))
    np.testing.assert_array_equal(topo.GetParentIndices(), parents)


def test_file_names_are_distinct_ignoring_case():
    assert unique_identifiers(["Walk", "walk", "walk.1"], casefold=True) == \
        ["Walk", "walk_1", "walk_1_1"]
