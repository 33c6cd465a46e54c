"""Rendered images: the instanced draw against a CPU-skinned reference rasterised by
the same GL and fragment shader, a wrong offset that must show, a wrapped pose
texture that must not, and the attached-context path."""

import numpy as np
import pytest

from crowd_addon.core.base.camera import frame_crowd

SIZE = (200, 150)


def differing(a, b, level=12):
    """Fraction of pixels whose channels differ by more than ``level``."""
    return float((np.abs(a.astype(int) - b.astype(int)).max(-1) > level).mean())


def render(renderer, crowd, camera, **kw):
    r = renderer(crowd, SIZE, **kw)
    r.render(camera)
    return r.read_image(), r


@pytest.mark.parametrize("feed", ["attributes", "texture"])
def test_render_matches_cpu_skinning_and_a_wrong_offset_shows(gl, h, renderer, feed):
    # 15 agents: read from textures (Blender's way), an odd count leaves a spare mesh
    # copy in the last instance; the reference draws the full mesh, so keep LOD 0 in
    # this small image
    far = (1e3, 2e3, 3e3)
    cfg = h.make_config(M=8, agents=15, spacing=0.9, lod_distances=far)
    wrong = h.make_config(M=8, agents=15, spacing=0.9, lod_distances=far)
    wrong.agent_offset[:] = 0
    crowd, crowd0 = h.Crowd(cfg), h.Crowd(wrong)
    for c in (crowd, crowd0):
        for _ in range(5):
            c.step()
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    image, r = render(renderer, crowd, camera, agent_feed=feed)
    image0, _ = render(renderer, crowd0, camera, agent_feed=feed)
    assert r.meshes[0, 0].copies == (1 if feed == "attributes" else 2)
    reference = h.reference_image(gl, crowd, camera, r.light, SIZE)
    assert differing(image, reference) < 0.002
    assert differing(image0, reference) > 0.02
    assert (image[..., :3] != image[0, 0, :3]).any(-1).mean() > 0.04    # agents are on screen


def test_materials_colour_the_body_and_the_agent_tints_its_grey_parts(gl, h, renderer):
    from dataclasses import replace

    from crowd_addon.core.meshes.mesh import Look
    far = (1e3, 2e3, 3e3)
    cfg = h.make_config(M=8, agents=15, spacing=0.9, lod_distances=far)
    body = cfg.meshes["fan"][0]
    upper = body.positions[body.triangles].mean(1)[:, 2] > np.median(body.positions[:, 2])
    looks = (Look("shirt", (0.9, 0.9, 0.9, 1.0)), Look("skin", (0.8, 0.5, 0.35, 1.0)))
    cfg.meshes["fan"] = [replace(body, material=np.where(upper, 1, 0).astype(np.uint16),
                                 looks=looks)]
    crowd = h.Crowd(cfg)
    crowd.step()
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    image, r = render(renderer, crowd, camera)
    reference = h.reference_image(gl, crowd, camera, r.light, SIZE)
    assert differing(image, reference) < 0.002
    # the skin keeps its colour on every agent: the upper halves look alike
    plain = h.Crowd(h.make_config(M=8, agents=15, spacing=0.9, lod_distances=far))
    plain.step()
    assert differing(image, render(renderer, plain, camera)[0]) > 0.01   # (sRGB: brights
    # are close together; the 8-bit steps between the two are fewer than in linear)


def test_wrapped_pose_texture_renders_identically(h, renderer):
    flat = h.make_config(M=24, streams=24, NT=8)
    wrapped = h.make_config(M=24, streams=24, NT=8, max_texture_size=256)
    crowds = [h.Crowd(flat), h.Crowd(wrapped)]
    assert crowds[0].storage.blocks == 1 and crowds[1].storage.blocks == 3
    images, positions = [], []
    for crowd in crowds:
        r = renderer(crowd, SIZE)
        for i in range(6):
            if i == 2:
                crowd.transition_to_streamed([1, 5, 6], "s7", 8, offset=20)
            crowd.step()
            r.sync()
        r.render(frame_crowd(crowd, aspect=SIZE[0] / SIZE[1]))
        images.append(r.read_image())
        positions.append(r.skinned_positions(np.arange(crowd.agents.count)))
    np.testing.assert_array_equal(images[0], images[1])
    np.testing.assert_array_equal(positions[0], positions[1])


GL_SRGB8_ALPHA8, GL_FRAMEBUFFER_SRGB = 0x8C43, 0x8DB9


def test_attached_context_renders_the_same_image(gl, h, renderer):
    """Drawn into the framebuffer a viewport draw handler finds bound -- Blender's
    viewport overlay: sRGB, encoding on write -- the attached renderer writes linear
    colours, which the framebuffer encodes: the image is the one the renderer's own
    image holds (which the shader encodes), to the last bit of 8-bit rounding."""
    from crowd_addon.gpu.moderngl_backend import ModernGLRenderer
    crowd = h.Crowd(h.make_config())
    crowd.step()
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    own, _ = render(renderer, crowd, camera)
    colour = gl.texture(SIZE, 4, internal_format=GL_SRGB8_ALPHA8)
    target = gl.framebuffer(color_attachments=[colour],
                            depth_attachment=gl.depth_renderbuffer(SIZE))
    target.use()
    gl.enable_direct(GL_FRAMEBUFFER_SRGB)
    other = h.Crowd(h.make_config())
    attached = ModernGLRenderer.attach(other.view, SIZE)
    try:
        other.step()
        attached.sync()
        attached.render(camera, target=attached.ctx.detect_framebuffer())
        assert not attached.encoding_srgb
        image = np.frombuffer(target.read(components=4, alignment=1), np.uint8)
    finally:
        gl.disable_direct(GL_FRAMEBUFFER_SRGB)
        attached.release()
        target.release()
        colour.release()
    image = image.reshape(SIZE[1], SIZE[0], 4)[::-1].astype(np.int16)
    covered = (own[..., :3] != own[0, 0, :3]).any(-1)          # not the background
    assert covered.sum() > 200
    assert np.abs(image[covered] - own[covered].astype(np.int16)).max() <= 1


def test_the_own_image_is_srgb_encoded(gl, h, renderer):
    """The renderer's own image holds the lit colours sRGB-encoded, as Blender's
    Standard view transform shows them: the same frame drawn linear (into a plain
    target) and encoded here on the CPU gives the own image. Before, the own image
    held the linear values, darker than Blender shows the same colours."""
    crowd = h.Crowd(h.make_config())
    crowd.step()
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    own, r = render(renderer, crowd, camera)
    plain = gl.framebuffer(color_attachments=[gl.renderbuffer(SIZE, 4)],
                           depth_attachment=gl.depth_renderbuffer(SIZE))
    try:
        r.render(camera, target=plain)
        assert not r.encoding_srgb
        linear = np.frombuffer(plain.read(components=4, alignment=1), np.uint8)
    finally:
        plain.release()
    linear = linear.reshape(SIZE[1], SIZE[0], 4)[::-1, :, :3] / 255.0
    encoded = np.where(linear <= 0.0031308, 12.92 * linear,
                       1.055 * linear ** (1 / 2.4) - 0.055) * 255.0
    background = own[0, 0, :3]                      # the clear colour, in both images
    covered = (own[..., :3] != background).any(-1) & \
        (np.rint(linear * 255.0) != background).any(-1) & (linear.max(-1) > 0.02)
    assert covered.sum() > 200
    assert np.abs(encoded[covered] - own[..., :3][covered]).max() <= 8   # 8-bit linear input
    assert (own[..., :3][covered].astype(np.float64) >= linear[covered] * 255.0 - 1).all()


@pytest.mark.parametrize("bad", [(0.0, 0.0, 0.0), (np.nan, 1.0, 1.0)])
def test_camera_rejects_degenerate_input(bad):
    from crowd_addon.core import CrowdError
    from crowd_addon.core.base.camera import Camera
    with pytest.raises(CrowdError, match="camera"):
        Camera(bad, (0.0, 0.0, 0.0)).view_projection


def test_palettes_colour_their_material_per_agent(gl, h, renderer):
    """A two-colour crowd: the shirt material takes each agent's palette colour (red
    or blue), the skin keeps its own. The image is the CPU reference's, and the
    colours are where the agents are: above each agent's feet, its own shirt colour."""
    from dataclasses import replace

    from crowd_addon.core.meshes.mesh import Look
    from crowd_addon.core.base.camera import Camera
    far = (1e3, 2e3, 3e3)
    cfg = h.make_config(M=8, agents=15, spacing=2.5, lod_distances=far)  # apart from above
    body = cfg.meshes["fan"][0]
    upper = body.positions[body.triangles].mean(1)[:, 2] > np.median(body.positions[:, 2])
    looks = (Look("shirt", (0.9, 0.9, 0.9, 1.0)), Look("skin", (0.8, 0.5, 0.35, 1.0)))
    cfg.meshes["fan"] = [replace(body, material=np.where(upper, 0, 1).astype(np.uint16),
                                 looks=looks)]
    red, blue = (0.9, 0.1, 0.1), (0.1, 0.2, 0.9)
    team = np.arange(15) % 2
    palette = np.full((15, 4, 3), -1.0, np.float32)
    palette[:, 0] = np.where(team[:, None] == 0, red, blue)
    cfg.agent_palette, cfg.palette_materials = palette, {"fan": ("shirt",)}
    cfg.agent_heading[:] = 0.0
    crowd = h.Crowd(cfg)
    crowd.step()
    camera = frame_crowd(crowd, aspect=SIZE[0] / SIZE[1])
    image, r = render(renderer, crowd, camera)
    reference = h.reference_image(gl, crowd, camera, r.light, SIZE)
    assert differing(image, reference) < 0.002
    # looking down from above, each agent's shirt (its vertices skinned by core) is
    # drawn in its own palette colour
    pos = crowd.agents.position.astype(np.float64)
    top = Camera(pos.mean(0) + (0.0, -0.01, 16.0), pos.mean(0), aspect=SIZE[0] / SIZE[1])
    image, _ = render(renderer, crowd, top)
    vp = top.view_projection
    shirt_vertices = np.unique(body.triangles[upper])
    hue = np.sign(image[..., 0].astype(int) - image[..., 2].astype(int) - 40) \
        - np.sign(image[..., 2].astype(int) - image[..., 0].astype(int) - 40)   # +2 red, -2 blue
    for a in range(15):
        world = h.world_reference(crowd, [a], body)[0][shirt_vertices]
        p = np.c_[world, np.ones(len(world))] @ vp.T
        x = ((p[:, 0] / p[:, 3] + 1) / 2 * SIZE[0]).astype(int)
        y = ((1 - (p[:, 1] / p[:, 3] + 1) / 2) * SIZE[1]).astype(int)
        seen = hue[np.clip(y, 0, SIZE[1] - 1), np.clip(x, 0, SIZE[0] - 1)]
        own, other = ((seen == 2).sum(), (seen == -2).sum()) if team[a] == 0 else \
            ((seen == -2).sum(), (seen == 2).sum())
        assert own >= 5 and own > 3 * other, (a, own, other)


def test_a_renderer_refuses_to_sync_after_another_took_the_crowds_changes(h, renderer):
    """A crowd's pose changes go to the renderer that takes them: a second renderer of
    the same crowd that syncs too takes some of them, and the first would draw stale
    poses (1,077 of 38,400 pixels off after one step, before this was refused). So the
    first one's next sync is an error; the one that took them draws the crowd as core
    skins it."""
    from crowd_addon.core.base.errors import CrowdError
    cfg = h.make_config(M=8, agents=12, lod_distances=(1e3, 2e3, 3e3))
    crowd = h.Crowd(cfg)
    first, second = renderer(crowd), renderer(crowd)
    for r in (first, second):          # made at the same frame: both have everything
        r.sync()
    crowd.step()
    second.sync()
    crowd.step()
    with pytest.raises(CrowdError, match="took its pose changes since this renderer last"):
        first.sync()
    second.sync()
    everyone = np.arange(crowd.agents.count)
    h.assert_close_relative(second.skinned_positions(everyone),
                            h.world_reference(crowd, everyone, cfg.meshes["fan"][0]),
                            rtol=1e-5)
