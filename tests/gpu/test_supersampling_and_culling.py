"""The moderngl preview's anti-aliasing (k x k supersampling, each pixel the mean of its
samples) and the back faces culled on closed levels (the same pixels as drawn
two-sided), docs/gpu.md "Anti-aliasing" (issue 36, item 5)."""

import numpy as np

from crowd_addon.core.base.camera import frame_crowd
from crowd_addon.gpu.proxies import ProxyBuffers

SIZE = (120, 90)
FAR = (1e3, 2e3, 3e3)          # every agent its full mesh, whatever the image height


def _box(split_seams=False, flip=False):
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3)]                            # counter-clockwise seen from outside
    tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    pos = corners
    if split_seams:                                   # a vertex per face corner, as UVs do
        pos, tris = corners[tris.reshape(-1)], np.arange(tris.size).reshape(-1, 3)
    if flip:
        tris = tris[:, ::-1]
    return ProxyBuffers("box", {"pos": pos.astype(np.float32)},
                        np.ascontiguousarray(tris.reshape(-1), np.uint32))


def test_closed_surfaces_are_told_from_open_or_inside_out_ones():
    assert _box().closed and _box(split_seams=True).closed
    assert not _box(flip=True).closed                 # inside out: its fronts face in
    open_box = _box()
    open_box = ProxyBuffers("open", open_box.attributes, open_box.indices[:-6])
    assert not open_box.closed
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], np.float32)
    card = ProxyBuffers("card", {"pos": np.concatenate([quad, quad[:, [1, 0, 2]]])},
                        np.array([0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7], np.uint32))
    assert not card.closed


def test_supersampled_image_is_the_mean_of_the_drawing_twice_as_large(h, renderer):
    cfg = h.make_config(M=8, agents=12, spacing=0.9, lod_distances=FAR)
    cfg.lod_budget_px = float("inf")         # the far level as made: a closed box a part
    cfg.add_mesh(cfg.meshes["fan"][0], lods=("card",))
    crowd = h.Crowd(cfg)
    for _ in range(3):
        crowd.step()
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    small = renderer(crowd, SIZE, samples=4)
    assert (small.scale, small.samples) == (2, 4)
    small.render(camera)
    image = small.read_image().astype(int)
    large = renderer(crowd, (2 * SIZE[0], 2 * SIZE[1]), samples=0)
    large.render(camera)
    big = large.read_image().astype(int)
    mean = big.reshape(SIZE[1], 2, SIZE[0], 2, 4).sum((1, 3)) / 4
    assert np.abs(image - mean).max() <= 1                          # rounding only
    assert (image[..., :3] != image[0, 0, :3]).any(-1).mean() > 0.03   # agents show


def test_culling_back_faces_changes_no_pixel(h, renderer):
    cfg = h.make_config(M=8, agents=12, spacing=0.9, lod_distances=FAR)
    cfg.lod_budget_px = float("inf")         # the far level as made: a closed box a part
    cfg.add_mesh(cfg.meshes["fan"][0], lods=("card",))
    crowd = h.Crowd(cfg)
    for _ in range(3):
        crowd.step()
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    culled = renderer(crowd, SIZE, samples=4)
    assert any(m.cull for m in culled.meshes.values())   # the boxes are closed
    culled.render(camera)
    two_sided = renderer(crowd, SIZE, samples=4)
    for m in two_sided.meshes.values():
        m.cull = False
    two_sided.render(camera)
    assert np.array_equal(culled.read_image(), two_sided.read_image())


def test_the_look_stage_runs_only_for_the_agents_that_look(h, renderer):
    import math

    from crowd_addon.core.runtime.look_at import LookRig, LookTarget
    cfg = h.make_config(M=8, agents=24)
    cfg.look_rigs["fan"] = LookRig(("neck", "head"), (0.4, 0.6),
                                   yaw_limit=math.radians(70), pitch_limit=math.radians(35))
    t = np.arange(60.0)
    cfg.look_targets["ball"] = LookTarget(
        "ball", -3, np.c_[4 + 9 * np.cos(t / 9), 4 + 9 * np.sin(t / 9), 2.5 + 0 * t],
        smoothing=3.0)
    crowd = h.Crowd(cfg)
    r = renderer(crowd, SIZE, samples=0)
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    everyone = np.arange(crowd.agents.count)
    assert not r.plan.looks.active(crowd.frame)
    crowd.look_at(everyone[::2], "ball", blend=3, hold=4)
    seen = []
    for _ in range(14):
        crowd.step()
        r.sync()
        looking = bool((crowd.looks.weights(crowd.frame, everyone) > 0).any())
        active = r.plan.looks.active(crowd.frame)
        assert active or not looking
        seen.append(active)
        r.render(camera)
        image = r.read_image()
        if active:                  # the lookers are drawn apart, the rest without it
            parts = [p for d in r.plan.draws(camera.view_projection, r.light)
                     for p in r._look_parts(d)]
            assert {looks for _, looks in parts} == {False, True}
        r._look_parts = lambda draw: [(draw, True)]          # the look stage everywhere
        r.render(camera)
        assert np.array_equal(r.read_image(), image)
        del r._look_parts
    assert seen[0] and not seen[-1]            # on while looking, off once it is over
