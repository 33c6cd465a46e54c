"""How a proxy mesh looks: texture coordinates per triangle corner and a Look
(material) per triangle, checked on construction, kept by the LODs for the triangles
they keep, and saved in configuration files."""

import numpy as np
import pytest

from crowd_addon.core import CrowdConfig, CrowdError
from crowd_addon.core.authoring.config_io import load_config, save_config
from crowd_addon.core.meshes.levels import build_lods, card_lod
from crowd_addon.core.meshes.mesh import Look, ProxyMesh
from crowd_addon.core.authoring.synthetic import humanoid, humanoid_mesh

SHIRT = Look("shirt", (0.8, 0.1, 0.1, 1.0))
SKIN = Look("skin", (0.9, 0.7, 0.6, 1.0), texture="//textures/skin.png")


def dressed(mesh: ProxyMesh) -> ProxyMesh:
    """``mesh`` with a texture coordinate that names its triangle (u = index, v = the
    corner) and the looks alternating by triangle."""
    t = mesh.triangle_count
    uvs = np.stack([np.repeat(np.arange(t, dtype=np.float32)[:, None], 3, 1),
                    np.tile(np.arange(3, dtype=np.float32), (t, 1))], -1)
    return ProxyMesh(mesh.name, mesh.skeleton, mesh.positions, mesh.triangles,
                     mesh.bone_indices, mesh.bone_weights, mesh.normals, mesh.bone_count,
                     uvs=uvs, material=np.arange(t) % 2, looks=(SHIRT, SKIN))


@pytest.fixture(scope="module")
def body():
    return dressed(humanoid_mesh(humanoid("fan", 24)))


def test_lods_keep_the_uvs_and_look_of_each_triangle_they_keep(body):
    for lod in build_lods(body, (0.5, 0.2))[1:]:
        assert lod.triangle_count < body.triangle_count and lod.looks == body.looks
        source = lod.uvs[:, 0, 0].astype(np.int64)          # the triangle it came from
        assert (lod.uvs[:, :, 0] == source[:, None]).all()
        assert (lod.uvs[:, :, 1] == np.arange(3)).all()     # corners in order
        assert (lod.material == source % 2).all()
        # each corner is its source corner's cluster representative: close by
        size = np.ptp(body.positions, 0).max()
        corners = body.positions[body.triangles[source].astype(np.int64)]
        near = np.linalg.norm(lod.positions[lod.triangles.astype(np.int64)] - corners, axis=2)
        assert near.max() < 0.35 * size


def test_the_card_shows_the_look_that_covers_most_of_the_upper_half(body):
    p = body.positions.astype(np.float64)
    t = body.triangles.astype(np.int64)
    upper = p[t].mean(1)[:, 2] > (p[:, 2].min() + p[:, 2].max()) / 2
    # shirt above the middle, skin below, and more skin than shirt overall
    legs = np.flatnonzero(~upper)
    dressed_up = ProxyMesh(body.name, body.skeleton, body.positions, body.triangles,
                           body.bone_indices, body.bone_weights, body.normals,
                           body.bone_count, material=np.where(upper, 0, 1),
                           looks=(SHIRT, SKIN))
    area = np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
    assert area[legs].sum() > area[~np.isin(np.arange(len(t)), legs)].sum()
    card = card_lod(dressed_up)
    assert card.uvs is None and card.looks == (SHIRT, SKIN)
    assert (card.material == 0).all()


@pytest.mark.parametrize("change, message", [
    ({"uvs": np.zeros((3, 3, 2))}, r"uvs must be \(\d+, 3, 2\) \(per triangle corner\)"),
    ({"uvs": "nan"}, "uvs of triangle 0 are not finite"),
    ({"material": np.zeros(4, np.int64)}, r"material must be \(\d+,\) integers"),
    ({"material": "big"}, "uses look 2, but the mesh has 2 look"),
    ({"looks": (SHIRT, SHIRT)}, "two looks are named the same"),
    ({"looks": ("shirt",)}, "looks must be Look objects"),
])
def test_bad_looks_are_named(body, change, message):
    kw = {"uvs": body.uvs, "material": body.material, "looks": body.looks}
    if isinstance(change.get("uvs"), str):
        change = {"uvs": np.where(np.arange(body.triangle_count)[:, None, None] == 0, np.nan,
                                  body.uvs)}
    if isinstance(change.get("material"), str):
        change = {"material": np.full(body.triangle_count, 2)}
    kw.update(change)
    with pytest.raises(CrowdError, match=message):
        ProxyMesh(body.name, body.skeleton, body.positions, body.triangles, body.bone_indices,
                  body.bone_weights, **kw)


@pytest.mark.parametrize("args, message", [
    (("", (1, 1, 1, 1)), "a name is needed"),
    (("cloth", (1, 1, 1)), r"color must be 4 numbers in 0\.\.1"),
    (("cloth", (1, 1, 2, 1)), r"color must be 4 numbers in 0\.\.1"),
    (("cloth", "red"), r"color must be 4 numbers"),
    (("cloth", (1, 1, 1, 1), None), "texture must be a file path"),
])
def test_bad_look_fields_are_named(args, message):
    with pytest.raises(CrowdError, match=message):
        Look(*args)


def test_looks_round_trip_through_a_configuration_file(body, tmp_path):
    cfg = CrowdConfig(max_offset=4, transition_slots=2)
    cfg.add_skeleton(humanoid("fan", 24))
    cfg.add_mesh(body, lods=(0.3, "card"))
    save_config(cfg, tmp_path / "crowd.json")
    loaded = load_config(tmp_path / "crowd.json").meshes["fan"]
    for a, b in zip(cfg.meshes["fan"], loaded, strict=True):
        assert b.looks == a.looks == (SHIRT, SKIN)
        assert (b.material == a.material).all()
        assert (a.uvs is None and b.uvs is None) or (b.uvs == a.uvs).all()
