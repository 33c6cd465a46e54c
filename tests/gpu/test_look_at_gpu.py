"""Look-at on the GPU (gpu_shaders/look_at.glsl): the vertex stage turns the heads of
looking agents from their look state, pose row and the frame alone; read back, their
vertices equal core's CPU skinning of ``Crowd.agent_rows`` (the CPU reference of the
look stage, core/runtime/look_at.py) to 1e-5 of the scene's size."""

import math

import numpy as np
import pytest

from crowd_addon.core.runtime.look_at import LookRig, LookTarget

TOL = 1e-5


def look_config(h, agents=24, rig=None, lag="offset", influences=None):
    cfg = h.make_config(M=8, agents=agents, influences=influences)
    cfg.look_rigs["fan"] = rig or LookRig(("neck", "head"), (0.4, 0.6),
                                          yaw_limit=math.radians(70),
                                          pitch_limit=math.radians(35))
    t = np.arange(120.0)
    # a ball circling over the crowd, and a point that jumps (smoothing spreads it)
    ball = np.c_[4 + 9 * np.cos(t / 9), 4 + 9 * np.sin(t / 9), 2.5 + np.sin(t / 5)]
    jump = np.where((t // 30 % 2 == 0)[:, None], [[-6.0, 3.0, 1.0]], [[12.0, 9.0, 4.0]])
    cfg.look_targets["ball"] = LookTarget("ball", -3, ball, smoothing=3.0)
    cfg.look_targets["jump"] = LookTarget("jump", 5, jump, smoothing=6.0)
    cfg.look_lag = lag
    return cfg


def check(h, r, crowd, agents, mesh, lod=0):
    """Read back within 1e-5 m of core's skinning (llvmpipe: about 2e-6 m)."""
    expected = h.world_reference(crowd, agents, mesh)
    gpu = r.skinned_positions(agents, lod=lod)
    assert np.abs(gpu - expected).max() <= TOL
    h.assert_close_relative(gpu, expected, rtol=TOL)


def test_looking_agents_match_cpu_skinning_frame_by_frame(h, renderer):
    cfg = look_config(h)
    crowd = h.Crowd(cfg)
    r = renderer(crowd)
    mesh = cfg.meshes["fan"][0]
    everyone = np.arange(crowd.agents.count)
    crowd.look_at(everyone[::2], "ball", blend=4)
    crowd.look_at(everyone[1::4], "jump", blend=0, hold=9)
    still = h.world_reference(crowd, everyone, mesh)
    turned = False
    for frame in range(14):
        crowd.step()
        r.sync()
        if frame == 6:
            crowd.look_away(everyone[::6], blend=3)
        check(h, r, crowd, everyone, mesh)
        w = crowd.looks.weights(crowd.frame, everyone)
        turned |= bool(((w > 0) & (w < 1)).any())
    assert turned                                      # blends were seen part way
    moved = np.abs(h.world_reference(crowd, everyone, mesh) - still).max()
    assert moved > 0.05                                # the heads did turn


def test_looks_with_a_chest_seeded_lags_and_eight_influences(h, renderer):
    rig = LookRig(("spine2", "neck", "head"), (0.2, 0.3, 0.5),
                  yaw_limit=math.radians(100), pitch_limit=math.radians(60))
    cfg = look_config(h, agents=17, rig=rig, lag="seeded", influences=8)
    crowd = h.Crowd(cfg, skinning="gpu")
    r = renderer(crowd)
    mesh = cfg.meshes["fan"][0]
    everyone = np.arange(crowd.agents.count)
    crowd.look_at(everyone, "jump", blend=2)
    for _ in range(10):
        crowd.step()
        r.sync()
    check(h, r, crowd, everyone, mesh)
    assert (crowd.looks.weights(crowd.frame, everyone) == 1).all()


def test_a_frame_uploads_nothing_for_looks_until_a_look_changes(h, renderer):
    cfg = look_config(h)
    crowd = h.Crowd(cfg)
    r = renderer(crowd)
    crowd.step()
    assert r.sync().look_bytes == 0
    crowd.look_at([3, 4, 5], "ball", blend=5)
    crowd.step()
    assert r.sync().look_bytes == 3 * 2 * 16           # three agents' two texels
    for _ in range(4):
        crowd.step()
        assert r.sync().look_bytes == 0                 # blending in costs nothing
    check(h, r, crowd, np.arange(crowd.agents.count), cfg.meshes["fan"][0])


@pytest.mark.parametrize("lod", [1, 3])
def test_every_lod_turns_like_its_mesh_on_the_cpu(h, renderer, lod):
    cfg = look_config(h)
    crowd = h.Crowd(cfg)
    r = renderer(crowd)
    everyone = np.arange(crowd.agents.count)
    crowd.look_at(everyone, "ball", blend=0)
    for _ in range(3):
        crowd.step()
    r.sync()
    check(h, r, crowd, everyone, cfg.meshes["fan"][lod], lod)
