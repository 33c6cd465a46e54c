"""Mesh variants and props drawn by the moderngl backend: one draw per (body, LOD).

Oracles: core's CPU skinning (``skin_vertices`` on ``crowd.agent_rows``, then each
agent's scale, heading and position: ``conftest.world_reference``) of the body's own
level (the variant's level with its props merged in; the variant's card alone),
against the vertices the draw program's vertex stage skins, read back per body; and
for the image, every agent's body skinned on the CPU and rasterised by the same GL
and fragment shader (as tests/gpu/test_render_images.py does for one body)."""

import numpy as np
import pytest

from crowd_addon.core import CrowdError
from crowd_addon.core.authoring import synthetic as sy
from crowd_addon.core.meshes.bodies import is_card
from crowd_addon.core.base.camera import frame_crowd

SIZE = (200, 150)
FAR = (1e3, 2e3, 3e3)           # every agent at LOD 0 in the images


def bodies_config(h, agents=24, props=True, **kw):
    """``conftest.make_config`` (three streams, a unique, LODs and a card) with a second
    mesh variant "slim", and props "flag" (a long pole in the left hand, bit 0) and
    "cap" (bit 1): agent ``i`` has variant ``(i // 4) % 2`` and props ``i % 4`` (every
    one of the eight bodies), two agents on the unique."""
    cfg = h.make_config(M=8, agents=agents, **kw)
    fan = cfg.skeletons["fan"]
    cfg.add_variant(sy.humanoid_mesh(fan, sides=5, name="slim"))
    cfg.add_prop(sy.box_prop(fan, "hand.L", "flag", size=(0.05, 0.05, 0.9),
                             offset=(0.0, 0.0, 0.35)))
    cfg.add_prop(sy.box_prop(fan, "head", "cap", size=(0.3, 0.3, 0.1), offset=(0.0, 0.0, 0.23)))
    i = np.arange(agents)
    cfg.agent_variant = ((i // 4) % 2).astype(np.int16)
    cfg.agent_props = (i % 4 if props else np.zeros(agents)).astype(np.uint8)
    h.make_unique(cfg, [5, 14])
    return cfg


def test_each_body_is_skinned_like_its_level_on_the_cpu(h, renderer):
    crowd = h.Crowd(bodies_config(h))
    view = crowd.view
    assert len(view.bodies) == 8
    r = renderer(crowd)
    for _ in range(3):
        crowd.step()
    r.sync()
    for b, body in enumerate(view.bodies):
        agents = np.flatnonzero(view.agent_body == b)
        assert agents.size == 3
        card = len(body.levels) - 1
        # the far level is a box per body part (8 vertices a part), unless the silhouette
        # check refused it for this body or the level before is lighter (then it is the
        # level before, under its name)
        far = body.levels[card]
        refused = any(far.name in note and "refused" in note for note in crowd.config.lod_notes)
        own = crowd.config.mesh_variants(list(crowd.config.skeletons)[body.skeleton])
        own = own[body.variant]
        lighter = own[-1].triangle_count == own[-2].triangle_count
        assert is_card(far) and (far.vertex_count % 8 == 0 or refused or lighter)
        for lod, mesh in enumerate(body.levels):
            gpu = r.skinned_positions(agents, lod=lod)
            assert gpu.shape == (agents.size, mesh.vertex_count, 3), (body.name, lod)
            h.assert_close_relative(gpu, h.world_reference(crowd, agents, mesh))
        # the props are there at LOD 0: the tail of the read-back is each prop's rigid
        # motion (its bone's skinning matrix on its bind positions)
        full = r.skinned_positions(agents)
        start = view.config.mesh_variants("fan")[body.variant][0].vertex_count
        for j in body.prop_ids:
            prop = view.config.props["fan"][j]
            part = full[:, start:start + prop.mesh.vertex_count]
            rows = crowd.agent_rows(agents)[:, prop.bone].astype(np.float64)      # (n, 3, 4)
            local = np.einsum("nrc,vc->nvr", rows[..., :3], prop.mesh.positions) + \
                rows[:, None, :, 3]
            rigid = h.world_reference(crowd, agents, prop.mesh)
            h.assert_close_relative(part, rigid)
            assert np.abs(local - prop.mesh.positions).max() > 0.01          # not the bind
            start += prop.mesh.vertex_count
        assert start == body.levels[0].vertex_count


def test_reading_back_agents_of_several_bodies_is_an_error_naming_them(h, renderer):
    crowd = h.Crowd(bodies_config(h))
    r = renderer(crowd)
    crowd.step()
    r.sync()
    names = [b.name for b in crowd.view.bodies]
    body = crowd.view.agent_body
    a, b = int(np.flatnonzero(body == names.index("fan_body"))[0]), \
        int(np.flatnonzero(body == names.index("slim+flag+cap"))[0])
    with pytest.raises(CrowdError, match=r"skinned_positions: the agents have several bodies "
                                         r"\['fan_body', 'slim\+flag\+cap'\]"):
        r.skinned_positions([b, a])
    # one body at a time is fine, and a level it lacks is named with the body
    assert r.skinned_positions([a]).shape[0] == 1
    with pytest.raises(CrowdError, match=r"body 'slim\+flag\+cap' has no LOD 5"):
        r.skinned_positions([b], lod=5)


def differs(a, b, level=12):
    """(H, W) bool: pixels whose channels differ by more than ``level``."""
    return np.abs(a.astype(int) - b.astype(int)).max(-1) > level


def pixels(points, camera):
    """(n, 2) image column, row (first row at the top) of world ``points`` (n, 3)."""
    clip = np.c_[points, np.ones(len(points))] @ np.asarray(camera.view_projection).T
    ndc = clip[:, :2] / clip[:, 3:]
    return np.c_[(ndc[:, 0] + 1) / 2 * SIZE[0], (1 - ndc[:, 1]) / 2 * SIZE[1]]


def test_props_show_in_the_image_where_they_are(gl, h, renderer):
    """The image with props is the CPU reference of every agent's body; the same crowd
    without props differs from it, and only around the props' projected vertices."""
    with_props = h.Crowd(bodies_config(h, agents=15, spacing=1.2, lod_distances=FAR))
    without = h.Crowd(bodies_config(h, agents=15, spacing=1.2, lod_distances=FAR,
                                    props=False))
    for c in (with_props, without):
        for _ in range(4):
            c.step()
    camera = frame_crowd(with_props, aspect=SIZE[0] / SIZE[1])
    images = []
    for c in (with_props, without):
        r = renderer(c, SIZE)
        r.render(camera)
        images.append(r.read_image())
    image, plain = images
    reference = h.reference_image(gl, with_props, camera, r.light, SIZE)
    assert differs(image, reference).mean() < 0.002
    changed = differs(image, plain)
    assert changed.mean() > 0.003, changed.mean()                     # the props show
    # every changed pixel is near a prop: inside the screen box of its agent's props
    view, near = with_props.view, np.zeros(changed.shape, bool)
    for b, body in enumerate(view.bodies):
        agents = np.flatnonzero(view.agent_body == b)
        for j in body.prop_ids:
            prop = view.config.props["fan"][j]
            world = h.world_reference(with_props, agents, prop.mesh)
            for a in range(agents.size):
                xy = pixels(world[a], camera)
                lo, hi = np.floor(xy.min(0)).astype(int) - 2, np.ceil(xy.max(0)).astype(int) + 2
                near[max(lo[1], 0):max(hi[1] + 1, 0), max(lo[0], 0):max(hi[0] + 1, 0)] = True
    assert near.any() and not (changed & ~near).any(), int((changed & ~near).sum())
