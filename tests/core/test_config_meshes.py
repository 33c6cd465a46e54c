"""``CrowdConfig.add_mesh`` with ready LOD meshes (a character's own LOD models) instead
of the automatic vertex-clustering levels, optionally followed by the far card."""

import numpy as np
import pytest

from crowd_addon.core.authoring import synthetic
from crowd_addon.core.authoring.config import CrowdConfig
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.meshes.levels import CARD, card_lod, parts_lod
from crowd_addon.core.meshes.mesh import ProxyMesh


@pytest.fixture
def cfg():
    cfg = CrowdConfig()
    cfg.add_skeleton(synthetic.humanoid("fan", bones=24))
    cfg.add_skeleton(synthetic.humanoid("kid", bones=20))
    return cfg


def test_ready_levels_are_used_as_given_then_the_card(cfg):
    sk = cfg.skeletons["fan"]
    body = synthetic.humanoid_mesh(sk, sides=8, rings=4, name="body")
    mid = synthetic.humanoid_mesh(sk, sides=5, rings=2, name="mid")
    low = synthetic.humanoid_mesh(sk, sides=3, rings=1, name="low")
    cfg.lod_budget_px = float("inf")     # as given: no silhouette check
    levels = cfg.add_mesh(body, lods=(mid, low, CARD))
    assert [lv.name for lv in levels[:3]] == ["body", "mid", "low"]
    assert levels[1] is mid and levels[2] is low and cfg.meshes["fan"] is levels
    want = parts_lod(body)             # a card per body part
    assert levels[3].vertex_count == want.vertex_count and levels[3].name == "body.card"
    np.testing.assert_array_equal(levels[3].positions, want.positions)
    assert [lv.name for lv in cfg.add_mesh(body, lods=(mid,))] == ["body", "mid"]


def test_ready_levels_of_another_skeleton_or_mixed_with_ratios_are_named(cfg):
    fan, kid = cfg.skeletons["fan"], cfg.skeletons["kid"]
    body = synthetic.humanoid_mesh(fan, name="body")
    other = synthetic.humanoid_mesh(kid, name="kid_low")
    with pytest.raises(CrowdError, match=r"mesh 'body': LOD 1 'kid_low' is for skeleton "
                                         r"'kid', not 'fan'"):
        cfg.add_mesh(body, lods=(other,))
    big = synthetic.humanoid_mesh(synthetic.humanoid("big", bones=40), name="big")
    wide = ProxyMesh("wide", "fan", big.positions, big.triangles, big.bone_indices,
                     big.bone_weights)
    with pytest.raises(CrowdError, match=r"mesh 'body': LOD 2: mesh 'wide': uses bone \d+ "
                                         r"but skeleton 'fan' has 24 bones"):
        cfg.add_mesh(body, lods=(synthetic.humanoid_mesh(fan, name="ok"), wide))
    low = synthetic.humanoid_mesh(fan, sides=3, rings=1, name="low")
    for lods in ((low, 0.06), (0.25, low), (CARD, low), (low, CARD, CARD)):
        with pytest.raises(CrowdError, match="LODs are either triangle ratios or ready "
                                             "meshes"):
            cfg.add_mesh(body, lods=lods)
    assert cfg.meshes == {}                         # nothing was set by the failures
