"""The moderngl backend's two agent feeds (docs/gpu.md, *Two feeds*): the draws read
their agents' records as per-instance vertex attributes gathered once a frame, every
mesh drawn one agent an instance (``agent_feed="attributes"``, the default), or from
the agent, look and list textures, small meshes drawn several agents an instance
(``"texture"``, Blender's only way). Same GLSL, same values: the images are
identical, frame after frame while agents change, and equal the CPU-skinned
reference."""

from dataclasses import replace

import numpy as np
import pytest

from crowd_addon.core.base.camera import frame_crowd
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.meshes.mesh import Look
from crowd_addon.core.runtime.look_at import LookRig, LookTarget
from crowd_addon.gpu.moderngl_backend import AGENT_FEEDS
from crowd_addon.gpu.proxies import copies_per_instance

SIZE = (240, 160)
FAR = (1e3, 2e3, 3e3)


def differing(a, b, level=12):
    return float((np.abs(a.astype(int) - b.astype(int)).max(-1) > level).mean())


def dressed_config(h, agents=21, lod_distances=FAR):
    """82 bones, so the humanoid body has 2,058 vertices (one agent an instance), and
    every fifth agent a slim variant of 197 (five an instance when read from textures).
    Shirts in two palette colours, every third agent unique, the body's LODs."""
    from crowd_addon.core.authoring.synthetic import humanoid_mesh
    cfg = h.make_config(M=8, agents=agents, bones=82, spacing=1.2, lod_distances=lod_distances)
    cfg.add_variant(humanoid_mesh(cfg.skeletons["fan"], sides=3, rings=1, name="slim"),
                    lods=())
    cfg.agent_variant = (np.arange(agents) % 5 == 4).astype(np.int16)
    body = cfg.meshes["fan"][0]
    upper = body.positions[body.triangles].mean(1)[:, 2] > np.median(body.positions[:, 2])
    looks = (Look("shirt", (0.9, 0.9, 0.9, 1.0)), Look("skin", (0.8, 0.5, 0.35, 1.0)))
    cfg.meshes["fan"][0] = replace(body, material=np.where(upper, 0, 1).astype(np.uint16),
                                   looks=looks)
    palette = np.full((agents, 4, 3), -1.0, np.float32)
    palette[:, 0] = np.where((np.arange(agents) % 2 == 0)[:, None], (0.9, 0.1, 0.1),
                             (0.1, 0.2, 0.9))
    cfg.agent_palette, cfg.palette_materials = palette, {"fan": ("shirt",)}
    h.make_unique(cfg, np.arange(0, agents, 3))
    return cfg


def both(h, renderer, cfg, **kw):
    """``{feed: (crowd, renderer)}``: a crowd of ``cfg`` for each feed (a crowd's upload
    regions go to one renderer), driven alike by :func:`step`."""
    out = {}
    for feed in AGENT_FEEDS:
        crowd = h.Crowd(cfg)
        out[feed] = crowd, renderer(crowd, SIZE, agent_feed=feed, **kw)
    return out


def step(pairs, change=None):
    for crowd, _ in pairs.values():
        if change is not None:
            change(crowd)
        crowd.step()


def images(pairs, camera):
    out = {}
    for feed, (_, r) in pairs.items():
        r.sync()
        r.render(camera)
        out[feed] = r.read_image()
    return out


def fed_programs(r) -> set:
    """The draw programs ``r`` compiled to take their agents as attributes."""
    return {key[0] for key in r._programs if key[0].endswith("_attr")}


def test_the_attribute_feed_draws_the_cpu_reference_and_the_texture_feeds_image(gl, h,
                                                                                renderer):
    cfg = dressed_config(h)
    assert copies_per_instance(cfg.meshes["fan"][0].vertex_count) == 1
    assert copies_per_instance(cfg.variants["fan"][0][0].vertex_count) == 5
    pairs = both(h, renderer, cfg)
    crowd, r = pairs["attributes"]
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    step(pairs)
    got = images(pairs, camera)
    fed, tex = got["attributes"], got["texture"]
    assert fed_programs(r) == {"crowd_draw_attr"} and not fed_programs(pairs["texture"][1])
    assert r.stats.draws == 2                                      # the body and the slim
    slim = (1, 0)                                                  # (body, level)
    assert pairs["texture"][1].meshes[slim].copies == 5
    assert r.meshes[slim].copies == 1                  # fed: one agent an instance
    assert np.array_equal(fed, tex)
    reference = h.reference_image(gl, crowd, camera, r.light, SIZE)
    assert differing(fed, reference) < 0.002
    assert (fed[..., :3] != fed[0, 0, :3]).any(-1).mean() > 0.03         # agents on screen


def test_the_feeds_agree_every_frame_while_agents_change(h, renderer):
    """Transitions start and end (kind, ref and offset change), an agent moves and
    turns, looks start and blend, the sun's shadows are cast, the camera moves back so
    the levels switch: the gathered records follow every change, so the images stay
    identical. A gather that kept the last frame's records would draw the moved agent
    where it was."""
    from crowd_addon.core.base.camera import Camera
    cfg = dressed_config(h, agents=30, lod_distances=None)
    cfg.look_rigs["fan"] = LookRig(("neck", "head"), (0.4, 0.6))
    t = np.arange(80.0)
    cfg.look_targets["ball"] = LookTarget("ball", 0, np.c_[3 + 8 * np.cos(t / 7),
                                                           3 + 8 * np.sin(t / 7),
                                                           np.full_like(t, 2.0)])
    pairs = both(h, renderer, cfg, shadows=True)
    everyone = np.arange(cfg.agent_count)
    near, far = (Camera(eye, (6.0, 5.0, 0.8), aspect=SIZE[0] / SIZE[1])
                 for eye in ((-2.0, -2.0, 1.7), (-8.0, -8.0, 3.0)))
    levels = set()

    def change(frame):
        def at(crowd):
            if frame == 1:
                crowd.transition_to_streamed(everyone[1::4], "s2", 3)
                crowd.look_at(everyone[::2], "ball", blend=3)
            if frame == 4:
                crowd.place_agents([7], position=[[4.0, -3.0, 0.5]], heading=[1.0])
        return at
    for frame in range(10):
        step(pairs, change(frame))
        got = images(pairs, near if frame < 6 else far)
        assert np.array_equal(got["attributes"], got["texture"]), frame
        levels |= {g.lod for g in pairs["attributes"][1].plan.lists.groups if g.count}
    assert levels >= {0, 1, 2, 3}                 # every level of the body was drawn
    assert fed_programs(pairs["attributes"][1]) and not fed_programs(pairs["texture"][1])


def test_an_unknown_feed_is_refused(h, renderer):
    crowd = h.Crowd(h.make_config(agents=4))
    with pytest.raises(CrowdError, match="agent_feed must be one of attributes, texture"):
        renderer(crowd, agent_feed="vertex")


def test_blender_cannot_build_the_gather_program():
    from crowd_addon.gpu.assembler import blender_create_info, gl_sources
    from crowd_addon.gpu.programs import AGENT_GATHER
    assert "layout(std430, binding = 0) writeonly buffer records_block { vec4 records[]; };" \
        in gl_sources(AGENT_GATHER)["compute_shader"]
    with pytest.raises(CrowdError, match="no storage buffers; it is a moderngl program"):
        blender_create_info(AGENT_GATHER)
