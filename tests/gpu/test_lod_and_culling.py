"""LOD by the agents' projected height in pixels (CrowdConfig.lod_pixels, or
lod_distances said in the reference view),
culling, and the draw calls."""

import numpy as np

from crowd_addon.core.base.camera import Camera, frame_crowd
from crowd_addon.gpu.draw_lists import REFERENCE_FOCAL_PX, lod_levels, view_distances


def test_lod_levels_follow_thresholds_and_available_levels():
    d = np.array([0.0, 29.9, 30.0, 89.0, 90.0, 500.0, 500.0])
    levels = np.array([3, 3, 3, 3, 3, 3, 2])
    np.testing.assert_array_equal(lod_levels(d, (30.0, 90.0), levels), [0, 0, 1, 1, 2, 2, 1])


def _row_scene(h, renderer, size, lod_distances=(60.0, 150.0)):
    """Twelve agents in a row along +X from 3 to 25 m, seen along the row by a camera
    at x = -1 (depth = x + 1) in an image of ``size``."""
    n = 12
    cfg = h.make_config(agents=n, lod_distances=lod_distances)
    cfg.agent_position[:] = np.c_[np.linspace(3.0, 25.0, n), np.zeros(n), np.zeros(n)]
    crowd = h.Crowd(cfg)
    r = renderer(crowd, size)
    crowd.step()
    r.sync()
    return crowd, r, Camera((-1.0, 0.0, 1.0), (30.0, 0.0, 1.0), aspect=4 / 3, far=100.0)


def _expected_lod(crowd, camera, pixels_high, lod_distances):
    """LOD from the camera's definition: the agent's projected height in pixels (its
    body's height times its scale over its depth times the focal length in pixels) against the pixel
    thresholds ``lod_distances`` say (a 1.8 m agent in the reference view, 1080 px and
    40 degrees, at those distances)."""
    depth = crowd.agents.position[:, 0] + 1.0
    focal = 0.5 * pixels_high / np.tan(camera.fov_y / 2)
    body = crowd.config.meshes["fan"][0].positions[:, 2]
    seen = float(np.ptp(body)) * crowd.agents.scale * focal / depth
    ref = 1.8 * (540.0 / np.tan(np.radians(20.0))) / np.asarray(lod_distances)
    return np.searchsorted(-ref, -seen, side="left").clip(max=2)


def test_far_agents_are_drawn_with_the_coarse_mesh(h, renderer):
    crowd, r, camera = _row_scene(h, renderer, (160, 120))
    stats = r.render(camera)
    levels = crowd.config.meshes["fan"]
    assert [m.vertex_count for m in levels] == sorted((m.vertex_count for m in levels),
                                                      reverse=True)
    want = _expected_lod(crowd, camera, 120, (60.0, 150.0))
    assert set(want.tolist()) == {0, 1, 2}
    np.testing.assert_array_equal(r.plan.lists.lod, want)
    assert {g.lod: g.count for g in r.plan.lists.groups} == {k: int((want == k).sum()) for k in
                                                         range(3)}
    assert stats.vertices == sum(int((want == k).sum()) * levels[k].vertex_count
                                 for k in range(3))
    assert stats.draws == 3 and stats.instances == crowd.agents.count


def test_a_taller_image_or_a_longer_lens_keeps_detail_further(h, renderer):
    """The same agents look twice as big in a twice as tall image, or through a lens
    with half the field of view's tangent: they switch LOD twice as far away."""
    crowd, small, camera = _row_scene(h, renderer, (160, 120))
    small.render(camera)
    big = renderer(crowd, (320, 240))
    big.render(camera)
    want = _expected_lod(crowd, camera, 240, (60.0, 150.0))
    np.testing.assert_array_equal(big.plan.lists.lod, want)
    coarse, fine = small.plan.lists.lod, big.plan.lists.lod
    assert (fine <= coarse).all() and (fine < coarse).any()
    zoom = Camera(camera.eye, camera.target, 2 * np.arctan(np.tan(camera.fov_y / 2) / 2),
                  camera.aspect, far=100.0)
    small.render(zoom)
    np.testing.assert_array_equal(small.plan.lists.lod, want)
    # the lists follow the target's height even when the camera stays
    fbo = small.ctx.simple_framebuffer((320, 240))
    try:
        assert small.render(camera, target=fbo).list_bytes > 0
        np.testing.assert_array_equal(small.plan.lists.lod, want)
    finally:
        fbo.release()


def test_view_distances_in_the_reference_view_and_orthographic():
    # the reference view itself: the distance is the depth
    cam = Camera((0.0, 0.0, 0.0), (0.0, 10.0, 0.0), np.radians(40.0), 16 / 9, 0.1, 500.0)
    pts = np.array([[0.0, 5.0, 0.0], [3.0, 50.0, -2.0], [0.0, 200.0, 1.0]])
    np.testing.assert_allclose(view_distances(pts, cam.view_projection, 1080), pts[:, 1],
                               rtol=1e-9)
    # orthographic, 20 m high on 540 px: 27 px a metre at any depth, as big as the
    # reference view shows things 1484 / 27 m away
    ortho = np.diag([0.1 * 9 / 16, 0.1, -0.01, 1.0])
    np.testing.assert_allclose(view_distances(pts, ortho, 540), REFERENCE_FOCAL_PX / 27.0,
                               rtol=1e-9)


def test_culling_drops_only_agents_outside_the_view(h, renderer):
    cfg = h.make_config(agents=36, spacing=2.0)
    crowd = h.Crowd(cfg)
    crowd.step()
    # stand inside the crowd looking along +Y: agents behind are culled
    camera = Camera((5.0, 4.5, 1.5), (5.0, 30.0, 1.0), aspect=4 / 3)
    culled, full = renderer(crowd), renderer(crowd, culling=False)
    s_culled, s_full = culled.render(camera), full.render(camera)
    behind = crowd.agents.position[:, 1] < 2.0
    assert behind.any()
    assert (culled.plan.lists.lod[behind] == -1).all()
    assert s_culled.instances < s_full.instances == crowd.agents.count
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
    crowd.place_agents([3], position=crowd.agents.position[[3]] + (0.5, 0.0, 0.0))
    crowd.step()
    r.sync()
    assert r.render(camera).list_bytes > 0


def test_lod_off_draws_every_agent_with_its_full_mesh(h, renderer):
    """``--lod off`` (``lod=False``): the same agents, every one at level 0."""
    crowd, r, camera = _row_scene(h, renderer, (160, 120))
    off = renderer(crowd, (160, 120), lod=False)
    stats = off.render(camera)
    r.render(camera)
    assert (r.plan.lists.lod > 0).any()
    np.testing.assert_array_equal(off.plan.lists.lod, np.zeros(crowd.agents.count))
    full = crowd.config.meshes["fan"][0].vertex_count
    assert stats.vertices == crowd.agents.count * full and stats.draws == 1


def test_agents_at_any_far_level_cast_no_shadow(h, renderer):
    """The shadow map draws the agents nearer than the far levels, as the coarsest level;
    agents drawn at a far level (boxes, or boxes joined) cast none: a second far level
    once made the first one's agents cast (the 65k demo's frame 20% slower)."""
    n = 12
    cfg = h.make_config(agents=n, lods=(0.25, 0.06, "card", "card"),
                        lod_distances=(40.0, 80.0, 120.0, 200.0))
    cfg.agent_position[:] = np.c_[np.linspace(3.0, 25.0, n), np.zeros(n), np.zeros(n)]
    crowd = h.Crowd(cfg)
    r = renderer(crowd, (160, 120))
    crowd.step()
    r.sync()
    camera = Camera((-1.0, 0.0, 1.0), (30.0, 0.0, 1.0), aspect=4 / 3, far=100.0)
    r.render(camera)
    drawn = {g.lod for g in r.plan.lists.groups}
    assert {3, 4} <= drawn and drawn & {0, 1, 2}, drawn
    levels = crowd.view.bodies[0].levels
    assert levels[3].name.endswith(".card") and levels[4].name.endswith(".joined.card")
    casters = r.plan.caster_draws(camera.view_projection, r.light)
    near = sum(g.count for g in r.plan.lists.groups if g.lod < 3)
    assert sum(d.agents for d in casters) == near
    assert {d.key[1] for d in casters} == {4}                  # as the coarsest level
