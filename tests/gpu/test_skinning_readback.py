"""Skinned vertices read back from the GPU (transform feedback of the draw program's
vertex stage) against core's CPU reference skinning, paper Eq. 1."""

import numpy as np
import pytest

from crowd_addon.core import TRANSITION, UNIQUE


def test_streamed_agents_at_every_offset_match_cpu_skinning(h, renderer):
    cfg = h.make_config(M=8, agents=24)
    crowd = h.Crowd(cfg)
    r = renderer(crowd)
    mesh = cfg.meshes["fan"][0]
    for _ in range(3):
        crowd.step()
        r.sync()
        agents = np.arange(crowd.agents.count)
        assert set(crowd.agents.offset[agents].tolist()) == set(range(crowd.streams.max_offset))
        gpu = r.skinned_positions(agents)
        h.assert_close_relative(gpu, h.world_reference(crowd, agents, mesh))


def test_unique_agents_match_cpu_skinning(h, renderer):
    cfg = h.make_config(uniques=2)
    h.make_unique(cfg, [1, 5, 9], unique=0)
    h.make_unique(cfg, [2, 7], unique=1)
    crowd = h.Crowd(cfg)
    r = renderer(crowd)
    for _ in range(4):
        crowd.step()
    r.sync()
    agents = np.array([1, 2, 5, 7, 9])
    assert (crowd.agents.kind[agents] == UNIQUE).all()
    mesh = cfg.meshes["fan"][0]
    h.assert_close_relative(r.skinned_positions(agents), h.world_reference(crowd, agents, mesh))


@pytest.mark.parametrize("skinning", ["cpu", "gpu"])
def test_agents_mid_transition_match_cpu_skinning(h, renderer, skinning):
    cfg = h.make_config(NT=4)
    crowd = h.Crowd(cfg, skinning=skinning)
    r = renderer(crowd)
    crowd.step()
    r.sync()
    agents = np.array([0, 3, 4, 10])
    crowd.transition_to_streamed(agents[:3], "s2", 6, offset=5)
    crowd.transition_to_unique(agents[3:], "u0", 5)
    mesh = cfg.meshes["fan"][0]
    for _ in range(3):
        crowd.step()
        r.sync()
        assert (crowd.agents.kind[agents] == TRANSITION).all()
        h.assert_close_relative(r.skinned_positions(agents),
                                h.world_reference(crowd, agents, mesh))


def test_every_lod_is_skinned_like_its_mesh_on_the_cpu(h, renderer):
    cfg = h.make_config()
    crowd = h.Crowd(cfg)
    r = renderer(crowd)
    crowd.step()
    r.sync()
    agents = np.arange(0, crowd.agents.count, 3)
    for lod, mesh in enumerate(cfg.meshes["fan"]):
        gpu = r.skinned_positions(agents, lod=lod)
        assert gpu.shape == (agents.size, mesh.vertex_count, 3)
        h.assert_close_relative(gpu, h.world_reference(crowd, agents, mesh))
