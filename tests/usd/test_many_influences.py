"""A character whose mesh has six bone influences a vertex, read back with pxr.UsdSkel:
the joint influences' element size is the mesh's influence width (8; 4 for meshes of
four influences or fewer) and UsdSkel's own skinning of the points matches core's
skinning with all six influences."""

import numpy as np
import pytest
from pxr import Gf, Usd, UsdSkel, Vt

from crowd_addon.core.authoring import synthetic
from crowd_addon.core.meshes.mesh import ProxyMesh
from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices
from crowd_addon.usd.character import character_layer


def six_influence_mesh(sk, seed=0):
    body = synthetic.humanoid_mesh(sk)
    heads = sk.bind_model[:, :3, 3]
    d = np.linalg.norm(body.positions[:, None].astype(np.float64) - heads[None], axis=2)
    idx = np.argsort(d, axis=1, kind="stable")[:, :6]
    w = 1.0 / (np.take_along_axis(d, idx, 1) + 0.05) ** 2
    w *= np.random.default_rng(seed).uniform(0.5, 1.5, w.shape)
    mesh = ProxyMesh.from_influences("body", sk.name, body.positions, body.triangles, idx, w,
                                     bone_count=sk.bone_count)
    return mesh, idx, w


def skinning_query(skeleton, mesh):
    layer, _ = character_layer(skeleton, mesh, "usda", 24.0, "fan")
    stage = Usd.Stage.Open(layer)
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath("/fan"))
    assert cache.Populate(root, Usd.PrimDefaultPredicate)
    (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    (target,) = binding.GetSkinningTargets()
    return stage, target


@pytest.mark.parametrize("wide", [False, True])
def test_usdskel_skins_every_influence_of_the_mesh(wide):
    sk = synthetic.humanoid("fan", bones=30)
    if wide:
        mesh, idx, w = six_influence_mesh(sk)
    else:
        mesh = synthetic.humanoid_mesh(sk)
        idx, w = mesh.bone_indices, mesh.bone_weights
    stage, target = skinning_query(sk, mesh)
    assert target.GetNumInfluencesPerComponent() == (8 if wide else 4)
    prim = stage.GetPrimAtPath(target.GetPrim().GetPath())
    assert prim.GetAttribute("primvars:skel:jointIndices").GetMetadata("elementSize") == \
        (8 if wide else 4)
    clip = synthetic.periodic_clip(sk, "c", amplitude=0.8)
    rows = skinning_matrices(clip.keys[7:8], sk)
    xforms = Vt.Matrix4dArray([Gf.Matrix4d(m.T.tolist()) for m in rows[0]])
    points = Vt.Vec3fArray.FromNumpy(mesh.positions.copy())
    assert target.ComputeSkinnedPoints(xforms, points, Usd.TimeCode.Default())
    want = skin_vertices(mesh.positions, idx, w, rows)[0]
    err = np.abs(np.asarray(points, np.float64) - want).max()
    assert err < 1e-5 * np.abs(want).max()
