"""How characters look in the USD: texture coordinates (``primvars:st``), a
UsdPreviewSurface material per look with its base colour or texture, bound to the
triangles that wear it; read back through ``UsdShade`` and checked by the validators."""

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdShade

from crowd_addon.core.meshes.mesh import Look, ProxyMesh

from .conftest import make_config, recording
from .test_layout import usdchecker

SHIRT = Look("shirt", (0.8, 0.1, 0.1, 1.0))
SKIN_PNG = "skin.png"


#: a 1x1 PNG
PNG = bytes.fromhex("89504e470d0a1a0a0000000d4948445200000001000000010802000000907753de0000000c"
                    "4944415408d763f8cfc000000301010018dd8db00000000049454e44ae426082")


def dressed(mesh, looks):
    t = mesh.triangle_count
    rng = np.random.default_rng(1)
    return ProxyMesh(mesh.name, mesh.skeleton, mesh.positions, mesh.triangles,
                     mesh.bone_indices, mesh.bone_weights, mesh.normals, mesh.bone_count,
                     uvs=rng.uniform(0, 1, (t, 3, 2)), material=np.arange(t) % len(looks),
                     looks=looks)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from crowd_addon.usd import export_crowd

    art = tmp_path_factory.mktemp("art")
    (art / SKIN_PNG).write_bytes(PNG)
    skin = Look("skin.main", (0.9, 0.7, 0.6, 0.5), texture=str(art / SKIN_PNG))
    cfg = make_config()
    cfg.meshes["fan"] = [dressed(cfg.meshes["fan"][0], (SHIRT, skin))]
    cfg.meshes["kid"] = [dressed(cfg.meshes["kid"][0], (SHIRT,))]
    path = tmp_path_factory.mktemp("looks") / "shot.usda"
    export_crowd(recording(cfg), path)
    return cfg, Usd.Stage.Open(str(path))


def mesh_of(stage, agent):
    (mesh,) = [p for p in Usd.PrimRange(stage.GetPrimAtPath(f"/Crowd/Agents/agent_{agent:02d}"),
                                        Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Mesh)]
    return mesh


def surface_of(material):
    shader = material.ComputeSurfaceSource()[0]
    assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
    return shader


def test_texture_coordinates_are_face_varying_per_triangle_corner(exported):
    cfg, stage = exported
    st = UsdGeom.PrimvarsAPI(mesh_of(stage, 0)).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying
    assert st.GetTypeName() == Sdf.ValueTypeNames.TexCoord2fArray
    np.testing.assert_array_equal(np.array(st.Get()), cfg.meshes["fan"][0].uvs.reshape(-1, 2))


def test_each_look_is_a_preview_surface_bound_to_its_triangles(exported):
    cfg, stage = exported
    mesh = cfg.meshes["fan"][0]
    prim = mesh_of(stage, 0)
    subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
    assert len(subsets) == 2
    seen = {}
    for subset in subsets:
        faces = np.array(subset.GetIndicesAttr().Get())
        material, _ = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()
        k = int(mesh.material[faces[0]])
        assert (mesh.material[faces] == k).all()
        seen[k] = faces.size
        shader = surface_of(material)
        look = mesh.looks[k]
        assert shader.GetInput("opacity").Get() == pytest.approx(look.color[3])
        color = shader.GetInput("diffuseColor")
        if look.texture:                    # the texture, read at st, gives the colour
            (source,), _ = color.GetConnectedSources()
            texture = UsdShade.Shader(source.source.GetPrim())
            assert texture.GetIdAttr().Get() == "UsdUVTexture" and source.sourceName == "rgb"
            file = texture.GetInput("file").Get()
            assert file.path == "../textures/skin.png"         # copied beside the layers
            assert open(file.resolvedPath, "rb").read() == PNG
            (reader,), _ = texture.GetInput("st").GetConnectedSources()
            assert UsdShade.Shader(reader.source.GetPrim()).GetInput("varname").Get() == "st"
        else:
            assert tuple(color.Get()) == pytest.approx(look.color[:3])
    assert seen == {0: np.sum(mesh.material == 0), 1: np.sum(mesh.material == 1)}


def test_one_look_binds_the_whole_mesh(exported):
    _, stage = exported
    prim = mesh_of(stage, 44)                       # a kid
    assert not UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    assert tuple(surface_of(material).GetInput("diffuseColor").Get()) == \
        pytest.approx(SHIRT.color[:3])


def test_the_validators_pass_with_materials(exported):
    _, stage = exported
    assert usdchecker(stage) == []


def test_a_missing_texture_is_refused_before_anything_runs(tmp_path):
    from crowd_addon.core import CrowdError
    from crowd_addon.usd import check_export

    cfg = make_config()
    gone = Look("skin", texture=str(tmp_path / "gone.png"))
    cfg.meshes["fan"] = [dressed(cfg.meshes["fan"][0], (SHIRT, gone))]
    with pytest.raises(CrowdError, match=r"look 'skin' of mesh 'fan_body' uses texture "
                                         r"'.*gone\.png', which is not a file"):
        check_export(cfg, tmp_path / "shot.usdc")
    assert not list(tmp_path.iterdir())


def test_the_lightest_lod_is_the_characters_proxy(tmp_path):
    """With LODs, the character holds its full mesh (purpose render) and its lightest
    LOD that is not a card (purpose proxy), both skinned: UsdSkel skins the proxy as
    core skins that LOD."""
    from pxr import UsdSkel

    from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices
    from crowd_addon.usd import export_crowd

    from .conftest import FIRST, core_truth

    cfg = make_config()
    full = cfg.meshes["fan"][0]
    cfg.meshes.pop("fan")
    cfg.add_mesh(full, lods=(0.5, 0.25, "card"))
    levels = cfg.meshes["fan"]
    export_crowd(recording(cfg), tmp_path / "shot.usda")
    stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    assert usdchecker(stage) == []
    agent = stage.GetPrimAtPath("/Crowd/Agents/agent_05")
    meshes = {UsdGeom.Imageable(p).ComputePurpose(): p
              for p in Usd.PrimRange(agent, Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Mesh)}
    assert set(meshes) == {UsdGeom.Tokens.render, UsdGeom.Tokens.proxy}
    assert len(meshes["proxy"].GetAttribute("points").Get()) == levels[2].vertex_count
    assert len(meshes["render"].GetAttribute("points").Get()) == full.vertex_count
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(agent)
    cache.Populate(root, Usd.TraverseInstanceProxies())
    (binding,) = cache.ComputeSkelBindings(root, Usd.TraverseInstanceProxies())
    query = cache.GetSkelQuery(binding.GetSkeleton())
    (target,) = [t for t in binding.GetSkinningTargets() if t.GetPrim() == meshes["proxy"]]
    points = UsdGeom.Mesh(meshes["proxy"]).GetPointsAttr().Get(FIRST)
    assert target.ComputeSkinnedPoints(query.ComputeSkinningTransforms(FIRST), points, FIRST)
    pose = core_truth()["poses"][FIRST][5:6]
    lod = levels[2]
    core = skin_vertices(lod.positions, lod.bone_indices, lod.bone_weights,
                         skinning_matrices(pose, cfg.skeletons["fan"]))[0]
    np.testing.assert_allclose(np.array(points), core, atol=1e-5)
