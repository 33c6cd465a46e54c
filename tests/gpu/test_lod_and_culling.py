"""LOD by camera distance (CrowdConfig.lod_distances), culling, and the draw calls."""

import numpy as np

from crowd_addon.gpu.camera import Camera, frame_crowd
from crowd_addon.gpu.draw_lists import lod_levels


def test_lod_levels_follow_thresholds_and_available_levels():
    d = np.array([0.0, 29.9, 30.0, 89.0, 90.0, 500.0, 500.0])
    levels = np.array([3, 3, 3, 3, 3, 3, 2])
    np.testing.assert_array_equal(lod_levels(d, (30.0, 90.0), levels), [0, 0, 1, 1, 2, 2, 1])


def test_far_agents_are_drawn_with_the_coarse_mesh(h, renderer):
    # a row of agents along +X, the camera at the origin looking along the row
    n = 12
    cfg = h.make_config(agents=n, lod_distances=(5.0, 12.0))
    cfg.agent_position[:] = np.c_[np.linspace(3.0, 25.0, n), np.zeros(n), np.zeros(n)]
    crowd = h.Crowd(cfg)
    r = renderer(crowd)
    crowd.step()
    r.sync()
    camera = Camera((-1.0, 0.0, 1.0), (30.0, 0.0, 1.0), aspect=4 / 3, far=100.0)
    stats = r.render(camera)
    levels = cfg.meshes["fan"]
    assert [m.vertex_count for m in levels] == sorted((m.vertex_count for m in levels),
                                                      reverse=True)
    dist = np.linalg.norm(crowd.agent_position - np.array(camera.eye, np.float32)
                          - [0, 0, r.lists.bounds[0, 0]], axis=1)
    want = np.where(dist < 5, 0, np.where(dist < 12, 1, 2))
    np.testing.assert_array_equal(r.lists.lod, want)
    assert {g.lod: g.count for g in r.lists.groups} == {k: int((want == k).sum()) for k in
                                                         range(3)}
    assert stats.vertices == sum(int((want == k).sum()) * levels[k].vertex_count
                                 for k in range(3))
    assert stats.draws == 3 and stats.instances == n


def test_culling_drops_only_agents_outside_the_view(h, renderer):
    cfg = h.make_config(agents=36, spacing=2.0)
    crowd = h.Crowd(cfg)
    crowd.step()
    # stand inside the crowd looking along +Y: agents behind are culled
    camera = Camera((5.0, 4.5, 1.5), (5.0, 30.0, 1.0), aspect=4 / 3)
    culled, full = renderer(crowd), renderer(crowd, culling=False)
    s_culled, s_full = culled.render(camera), full.render(camera)
    behind = crowd.agent_position[:, 1] < 2.0
    assert behind.any()
    assert (culled.lists.lod[behind] == -1).all()
    assert s_culled.instances < s_full.instances == crowd.N
    np.testing.assert_array_equal(culled.read_image(), full.read_image())


def test_lists_are_rebuilt_only_when_the_camera_or_agents_move(h, renderer):
    crowd = h.Crowd(h.make_config())
    r = renderer(crowd)
    camera = frame_crowd(crowd)
    crowd.step()
    r.sync()
    assert r.render(camera).list_bytes > 0
    crowd.step()
    r.sync()
    assert r.render(camera).list_bytes == 0
    crowd.agent_position[3] += (0.5, 0.0, 0.0)
    crowd.step()
    r.sync()
    assert r.render(camera).list_bytes > 0
