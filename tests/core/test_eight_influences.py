"""Meshes with more than four bone influences a vertex (up to eight are kept exactly).

The oracle is linear blend skinning written from its definition, one vertex and one
influence at a time, over every influence the vertex was given: ``v' = sum_i w_i
(M_i M_ref_i^-1) v / sum_i w_i``.
"""

import hashlib
import json

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, CrowdConfig, CrowdError
from crowd_addon.core.authoring import synthetic
from crowd_addon.core.authoring.config_io import load_config, save_config
from crowd_addon.core.meshes.levels import build_lods, card_lod
from crowd_addon.core.meshes.mesh import ProxyMesh
from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices

QUAD = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_TRI = np.array([[0, 1, 2], [0, 2, 3]])


spread = synthetic.spread_weights


def exact(positions, idx, w, matrices):
    """(V, 3) float64 skinned positions, vertex by vertex, influence by influence."""
    out = np.zeros((len(positions), 3))
    for v, p in enumerate(np.asarray(positions, np.float64)):
        total = w[v].sum()
        for b, wi in zip(idx[v], w[v]):
            out[v] += wi / total * (matrices[b] @ np.append(p, 1.0))[:3]
    return out


@pytest.fixture(scope="module")
def rig():
    sk = synthetic.humanoid("fan", bones=30)
    clip = synthetic.periodic_clip(sk, "c", amplitude=0.8)
    return sk, skinning_matrices(clip.keys[7:8], sk)[0]


@pytest.mark.parametrize("k", [5, 6, 8])
def test_mesh_with_up_to_eight_influences_skins_exactly(rig, k):
    sk, matrices = rig
    pos, tri, idx, w = spread(sk, k)
    mesh = ProxyMesh.from_influences("body", sk.name, pos, tri, idx, w,
                                     bone_count=sk.bone_count)
    got = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights, matrices[None])
    want = exact(pos, idx, w, matrices)
    # the cut to the four strongest was off by centimetres on this body
    assert np.abs(got[0] - want).max() < 1e-6
    assert mesh.bone_indices.shape == mesh.bone_weights.shape == (len(pos), 8)
    assert mesh.notes == ()


def test_meshes_with_four_influences_or_fewer_stay_four_wide():
    sk = synthetic.humanoid("fan", bones=24)
    assert synthetic.humanoid_mesh(sk).bone_indices.shape[1] == 4
    pos, tri, idx, w = spread(sk, 4)
    assert ProxyMesh.from_influences("b", "fan", pos, tri, idx, w).bone_weights.shape[1] == 4
    # eight columns whose last four weigh nothing are four influences
    w8 = np.pad(w / w.sum(1, keepdims=True), ((0, 0), (0, 4)))
    m = ProxyMesh("b", "fan", pos, tri, np.pad(idx, ((0, 0), (0, 4))), w8)
    assert m.bone_indices.shape == m.bone_weights.shape == (len(pos), 4)


def test_more_than_eight_influences_keep_the_eight_strongest_and_say_so():
    idx = np.tile(np.arange(10), (4, 1))
    w = np.tile(np.arange(1.0, 11.0), (4, 1))
    w[1, 8:] = 0                                  # vertex 1 has exactly eight
    m = ProxyMesh.from_influences("Hero Body", "sk", QUAD, QUAD_TRI, idx, w, bone_count=10)
    assert m.bone_indices[0].tolist() == [9, 8, 7, 6, 5, 4, 3, 2]
    np.testing.assert_allclose(m.bone_weights[0], np.arange(10.0, 2.0, -1) / 52, rtol=1e-6)
    assert m.bone_indices[1].tolist() == [7, 6, 5, 4, 3, 2, 1, 0]
    assert m.notes == ("mesh 'Hero Body': 3 of 4 vertices have more than 8 bone influences "
                       "(up to 10); each keeps its 8 strongest, renormalised, so they "
                       "deform slightly differently",)


def test_direct_meshes_take_four_or_eight_columns():
    ok = ProxyMesh("q", "sk", QUAD, QUAD_TRI, np.tile(np.arange(8), (4, 1)),
                   np.tile([0.5, 0.2, 0.1, 0.1, 0.1, 0, 0, 0], (4, 1)))
    assert ok.bone_weights.shape == (4, 8)
    with pytest.raises(CrowdError, match=r"must be \(4, 4\) or \(4, 8\)"):
        ProxyMesh("q", "sk", QUAD, QUAD_TRI, np.zeros((4, 6), int),
                  np.tile([1.0, 0, 0, 0, 0, 0], (4, 1)))


def test_lods_and_card_carry_all_eight_influences(rig):
    sk, matrices = rig
    pos, tri, idx, w = spread(sk, 6)
    mesh = ProxyMesh.from_influences("body", sk.name, pos, tri, idx, w,
                                     bone_count=sk.bone_count)
    full = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights, matrices[None])[0]
    def keys(m):         # a vertex: its position and all its influences
        return [(tuple(p), tuple(i), tuple(w)) for p, i, w in
                zip(m.positions.tolist(), m.bone_indices.tolist(), m.bone_weights.tolist())]

    rows = {key: k for k, key in enumerate(keys(mesh))}
    for lod in build_lods(mesh, (0.25, 0.06))[1:]:
        assert lod.bone_indices.shape[1] == 8
        src = [rows[key] for key in keys(lod)]        # every LOD vertex is a mesh vertex
        low = skin_vertices(lod.positions, lod.bone_indices, lod.bone_weights, matrices[None])
        np.testing.assert_allclose(low[0], full[src], rtol=1e-12)
    card = card_lod(mesh)
    assert card.bone_indices.shape == (8, 4)          # one bone a corner


def test_config_round_trip_keeps_eight_columns(tmp_path, rig):
    sk, _ = rig
    pos, tri, idx, w = spread(sk, 7)
    mesh = ProxyMesh.from_influences("body", sk.name, pos, tri, idx, w,
                                     bone_count=sk.bone_count)
    cfg = CrowdConfig(max_offset=4, transition_slots=2)
    cfg.add_skeleton(sk)
    cfg.add_clip(synthetic.periodic_clip(sk, "c"))
    cfg.add_stream("s", sk.name, ClipPlayer("c"))
    cfg.add_mesh(mesh, lods=(0.25, "card"))
    cfg.add_agents(3)
    save_config(cfg, tmp_path / "crowd.json")
    loaded = load_config(tmp_path / "crowd.json")
    widths = [lv.bone_indices.shape[1] for lv in loaded.meshes[sk.name]]
    # the full mesh and LOD 1 keep 8 columns; the far level (a box per body part whose
    # corners take the weights of the part's nearest vertex) keeps what it was built with
    assert widths[:2] == [8, 8]
    assert widths == [lv.bone_indices.shape[1] for lv in cfg.meshes[sk.name]]
    for a, b in zip(cfg.meshes[sk.name], loaded.meshes[sk.name]):
        assert a.bone_indices.tobytes() == b.bone_indices.tobytes()
        assert a.bone_weights.tobytes() == b.bone_weights.tobytes()


def test_config_with_another_influence_width_is_named(tmp_path, rig):
    sk, _ = rig
    cfg = CrowdConfig(max_offset=4, transition_slots=2)
    cfg.add_skeleton(sk)
    cfg.add_clip(synthetic.periodic_clip(sk, "c"))
    cfg.add_stream("s", sk.name, ClipPlayer("c"))
    cfg.add_mesh(synthetic.humanoid_mesh(sk), lods=())
    cfg.add_agents(2)
    path = tmp_path / "crowd.json"
    save_config(cfg, path)
    npz = path.with_suffix(".npz")
    with np.load(npz) as z:
        arrays = dict(z)
    key = "meshes[0].levels[0].bone_weights"
    assert arrays[key].shape[1] == 4                   # four-wide files are what was written
    arrays[key] = np.pad(arrays[key], ((0, 0), (0, 2)))
    np.savez(npz, **arrays)
    m = json.loads(path.read_text())
    m["meshes"][0]["levels"][0]["bone_weights"]["shape"][1] = 6
    m["arrays"]["sha256"] = hashlib.sha256(npz.read_bytes()).hexdigest()
    path.write_text(json.dumps(m))
    with pytest.raises(CrowdError, match=r"meshes\[0\]\.levels\[0\]\.bone_weights: array "
                                         r".* has shape \(\d+, 6\), expected \(\*, 4\) or "
                                         r"\(\*, 8\)"):
        load_config(path)
