"""The crowd in its scene: a wall in front of part of the crowd hides exactly the
agents behind it, in the headless renderers (moderngl and Blender's gpu module, the
preview's scene pass) and in the viewport draw path (into an offscreen whose depth
holds the scene, as Blender's viewport leaves it).

Oracles: Blender's own ray cast of the scene (``Scene.ray_cast``) for the scene's depth
at every pixel and, from the floor towards the sun, for the wall's shadow; Blender's
Workbench render of the scene alone for the pixels the scene covers; the crowd drawn
without its scene for where the agents are.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview  # noqa: E402
from crowd_addon.blender.cameras import camera_from_object  # noqa: E402
from crowd_addon.blender.scene_geometry import scene_geometry, scene_light  # noqa: E402
from crowd_addon.gpu.backends import make_renderer  # noqa: E402
from crowd_addon.core import Crowd  # noqa: E402

SIZE = (240, 160)
WALL_Y = 2.25                       # between the second and third rows of agents
FRAME = 9


extension = cs.extension_fixture()


def _box(name, centre, size, color):
    bpy.ops.mesh.primitive_cube_add(location=centre)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = [s / 2 for s in size]
    mat = bpy.data.materials.new(name)
    mat.diffuse_color = (*color, 1.0)
    obj.data.materials.append(mat)
    return obj


@pytest.fixture(scope="module")
def walled():
    """Six by five agents 1.5 m apart, a wall across the left half between the second
    and third rows, a floor, a sun and a low camera looking over the wall."""
    preview.stop_all()
    scene, *_ = cs.walking_crowd()
    _box("Wall", (1.5, WALL_Y, 0.9), (5.0, 0.2, 1.8), (0.3, 0.5, 0.3))
    _box("Floor", (3.75, 3.0, -0.06), (30.0, 30.0, 0.1), (0.5, 0.45, 0.4))
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.rotation_euler = (-0.45, 0.0, 0.4)    # from behind the wall: its shadow faces us
    scene.collection.objects.link(sun)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.location = (3.75, -7.0, 1.6)
    cam.rotation_euler = (np.radians(84), 0.0, 0.0)
    cam.data.clip_start, cam.data.clip_end = 0.5, 60.0
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    scene.frame_set(FRAME)
    bpy.context.view_layer.update()
    cs.init_gpu()
    return scene, cam, preview.get(scene)


def _pixel_rays(camera, size):
    """World origin and unit directions ``(H, W, 3)`` through every pixel centre (row 0
    at the bottom, as GL reads), from the camera's own inverse view-projection."""
    w, h = size
    xs = (np.arange(w) + 0.5) / w * 2 - 1
    ys = (np.arange(h) + 0.5) / h * 2 - 1
    ndc = np.stack(np.meshgrid(xs, ys), -1)
    inv = np.linalg.inv(camera.view_projection)

    def unproject(z):
        p = np.concatenate([ndc, np.full(ndc.shape[:2] + (1,), z), np.ones(ndc.shape[:2] +
                                                                             (1,))], -1)
        q = p @ inv.T
        return q[..., :3] / q[..., 3:]
    near, far = unproject(-1.0), unproject(1.0)
    d = far - near
    return np.asarray(camera.eye), d / np.linalg.norm(d, axis=-1, keepdims=True)


def _camera_hits(scene, camera, size):
    """Blender's own ray cast of the scene (without the crowd's templates, as the scene
    pass sees it) through every pixel (rows bottom-up): the depth along the camera's
    -Z (inf where nothing is hit), the world point hit and the object's name."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    eye, dirs = _pixel_rays(camera, size)
    forward = -camera.view[2, :3]
    hide = [o for o in scene.objects if o.name in ("Body", "Seats")]
    for o in hide:
        o.hide_set(True)
    depsgraph.update()
    depth = np.full(dirs.shape[:2], np.inf)
    points = np.full(dirs.shape, np.nan)
    names = np.full(dirs.shape[:2], "", object)
    try:
        for (y, x), _ in np.ndenumerate(depth):
            hit, loc, _, _, obj, _ = scene.ray_cast(depsgraph, eye, dirs[y, x])
            if hit:
                points[y, x] = loc
                depth[y, x] = float(np.dot(np.asarray(loc) - eye, forward))
                names[y, x] = obj.original.name
    finally:
        for o in hide:
            o.hide_set(False)
    return depth, points, names


def _linear_depth(window_z, camera):
    """Window depth (0..1) to distance along the camera's -Z."""
    n, f = camera.near, camera.far
    ndc = 2.0 * np.asarray(window_z, np.float64) - 1.0
    return 2.0 * f * n / ((f + n) - ndc * (f - n))


def _render(preview_crowd, backend, camera, light, scene=None, shadows=False):
    """(RGBA image rows bottom-up, window depth rows bottom-up) of the preview's crowd
    at :data:`FRAME` (a crowd of its own: a renderer consumes its crowd's uploads),
    over ``scene`` when given. Both backends draw in Blender's GL context (a second,
    standalone context would take it from Blender's ``gpu`` module in this process):
    ``"moderngl"`` attached to it as the viewport preview does, ``"blender"`` with
    the ``gpu`` module."""
    crowd = Crowd(preview_crowd.config, skinning="gpu")
    crowd.reset(FRAME)
    if backend == "moderngl":
        from crowd_addon.blender.shared_gl import shared_context
        from crowd_addon.gpu.moderngl_backend import ModernGLRenderer
        shared = shared_context()
        r = ModernGLRenderer.attach(crowd.view, SIZE, light=light, shadows=shadows)
        shared.before(r.ctx)
    else:
        r = make_renderer(crowd.view, backend, SIZE, light=light, shadows=shadows)
    try:
        r.set_scene(scene)
        r.sync()
        r.render(camera, clear=(0.0, 0.0, 0.0, 0.0))
        image = r.read_image()[::-1]
        if backend == "moderngl":
            depth = np.frombuffer(r.fbo.read(components=1, attachment=-1, dtype="f4"),
                                  np.float32)
        else:
            buf = r.depth_tex.read()
            buf.dimensions = SIZE[0] * SIZE[1]
            depth = np.array(buf, np.float32)
        return image, depth.reshape(SIZE[1], SIZE[0])
    finally:
        r.release()
        if backend == "moderngl":
            shared.after()


def _crowd_pixels(composite, crowd_only):
    """Pixels where the composite shows the crowd: the crowd covers them alone and the
    composite has exactly the crowd's colour there."""
    return (crowd_only[..., 3] > 0) & (composite == crowd_only).all(-1)


def _depth_edges(depth):
    """Pixels next to a jump of the scene's depth (silhouettes: a ray cast and a
    rasteriser may round them either way)."""
    d = np.where(np.isfinite(depth), depth, 1e6)
    edge = np.zeros(d.shape, bool)
    for axis in (0, 1):
        jump = np.abs(np.diff(d, axis=axis)) > 0.2
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 0)
        edge |= np.pad(jump, pad)
        pad[axis] = (0, 1)
        edge |= np.pad(jump, pad)
    return edge


def test_scene_geometry_takes_the_scene_and_leaves_the_crowd_templates(walled):
    scene, _, _ = walled
    geo = scene_geometry(scene)
    assert set(geo.objects) == {"Wall", "Floor"}
    assert geo.triangle_count == 24                    # two boxes of 12 triangles
    lo, hi = geo.bounds()
    np.testing.assert_allclose(lo, [-11.25, -12.0, -0.11], atol=1e-5)
    np.testing.assert_allclose(hi, [18.75, 18.0, 1.8], atol=1e-5)
    wall = np.isclose(geo.colors, [0.3, 0.5, 0.3]).all(1)
    assert wall.sum() == 36
    light = scene_light(scene)
    sun = np.asarray(scene.objects["Sun"].matrix_world)
    np.testing.assert_allclose(light[:3], sun[:3, 2], atol=1e-6)   # towards the sun


def _walled_view(walled):
    """``(scene, camera, sun, scene geometry, preview)`` of the walled scene."""
    scene, cam_obj, pv = walled
    return (scene, camera_from_object(cam_obj, SIZE[0] / SIZE[1]), scene_light(scene),
            scene_geometry(scene), pv)


@pytest.mark.parametrize("backend", ["moderngl", "blender"])
def test_a_wall_hides_exactly_the_agents_behind_it(walled, backend):
    scene, camera, light, geo, pv = _walled_view(walled)
    crowd_only, crowd_depth = _render(pv.crowd, backend, camera, light)
    composite, _ = _render(pv.crowd, backend, camera, light, geo)
    scene_depth, _, _ = _camera_hits(scene, camera, SIZE)

    agent = crowd_only[..., 3] > 0
    agent_z = _linear_depth(crowd_depth, camera)
    expected = agent & (agent_z < scene_depth)
    shown = _crowd_pixels(composite, crowd_only)
    assert agent.sum() > 800 and expected.sum() > 400
    assert (agent & ~expected).sum() > 200                # the wall really hides some
    wrong = shown != expected
    clear = ~_depth_edges(scene_depth) & (np.abs(agent_z - scene_depth) > 0.05)
    assert not (wrong & clear).any(), f"{(wrong & clear).sum()} pixels disagree"
    assert wrong.sum() <= 0.02 * agent.sum()
    # where no agent is, the composite is the scene: lit wall and floor, nothing else
    assert (composite[~agent][:, 3] > 0).mean() > 0.99 * np.isfinite(scene_depth[~agent]).mean()


def _workbench_alpha(scene, path):
    """Coverage (0..1, rows bottom-up) of a Workbench render of the scene alone."""
    hide = [o for o in scene.objects if o.name in ("Body", "Seats")]
    r = scene.render
    saved = (r.engine, r.film_transparent, r.filepath)
    for o in hide:
        o.hide_render = True
    try:
        r.engine, r.film_transparent, r.filepath = "BLENDER_WORKBENCH", True, str(path)
        r.image_settings.file_format = "PNG"
        r.image_settings.color_mode = "RGBA"
        bpy.ops.render.render(write_still=True)
    finally:
        for o in hide:
            o.hide_render = False
        r.engine, r.film_transparent, r.filepath = saved
    return cs.image_pixels(path)[..., 3]


def test_scene_pass_covers_what_workbench_renders(walled, tmp_path):
    scene, cam_obj, pv = walled
    camera = camera_from_object(cam_obj, SIZE[0] / SIZE[1])
    geo = scene_geometry(scene)
    crowd_only, _ = _render(pv.crowd, "blender", camera, scene_light(scene))
    composite, _ = _render(pv.crowd, "blender", camera, scene_light(scene), geo)
    ours = (composite[..., 3] > 0) & ~(crowd_only[..., 3] > 0)
    theirs = _workbench_alpha(scene, tmp_path / "workbench.png") > 0.5
    theirs &= ~(crowd_only[..., 3] > 0)
    assert theirs.sum() > 0.3 * theirs.size
    assert (ours != theirs).mean() < 0.01, f"{(ours != theirs).sum()} pixels differ"


def _viewport_scene_depth(geo, view, proj):
    """What Blender's viewport leaves before its draw handlers run: the scene drawn
    with a built-in shader, writing depth."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    batch = batch_for_shader(shader, "TRIS", {"pos": geo.positions.tolist()})
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(True)
    with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
        gpu.matrix.load_matrix(view)
        gpu.matrix.load_projection_matrix(proj)
        shader.uniform_float("color", (0.2, 0.2, 0.2, 1.0))
        batch.draw(shader)
    gpu.state.depth_test_set("NONE")


def _viewport_draw(scene, view, proj, geo=None):
    import gpu
    from mathutils import Matrix
    view_m, proj_m = Matrix(view.tolist()), Matrix(proj.tolist())
    off = gpu.types.GPUOffScreen(*SIZE)
    with off.bind():
        gpu.state.active_framebuffer_get().clear(color=(0, 0, 0, 0), depth=1.0)
        if geo is not None:
            _viewport_scene_depth(geo, view_m, proj_m)
        drawn = preview.draw_scene(scene, view_m, proj_m)
    buf = off.texture_color.read()
    buf.dimensions = SIZE[0] * SIZE[1] * 4
    img = np.array(buf, np.float32).reshape(SIZE[1], SIZE[0], 4)
    off.free()
    assert drawn, preview.get(scene).draw_error
    return img


def test_viewport_draw_is_hidden_by_the_viewport_scene_depth(walled):
    """The draw handler's own code, into a target whose depth holds the scene, shows
    the crowd where the headless scene pass shows it."""
    scene, cam_obj, pv = walled
    camera = camera_from_object(cam_obj, SIZE[0] / SIZE[1])
    geo = scene_geometry(scene)
    alone = _viewport_draw(scene, camera.view, camera.projection)
    behind_wall = _viewport_draw(scene, camera.view, camera.projection, geo)
    crowd = alone[..., 3] > 0
    shown = crowd & (np.abs(behind_wall - alone) < 1e-6).all(-1)
    light = scene_light(scene)
    crowd_only, _ = _render(pv.crowd, "blender", camera, light)
    composite, _ = _render(pv.crowd, "blender", camera, light, geo)
    headless = _crowd_pixels(composite, crowd_only)
    assert crowd.sum() > 800 and (crowd & ~shown).sum() > 200
    assert (shown != headless).sum() <= 0.03 * crowd.sum()


def _sun_blocked(scene, points, light):
    """Whether Blender's ray cast from each point towards the sun meets the wall."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    blocked = np.zeros(points.shape[:2], bool)
    for (y, x), _ in np.ndenumerate(blocked):
        if np.isfinite(points[y, x, 0]):
            hit, *_, obj, _ = scene.ray_cast(depsgraph, points[y, x] + (0, 0, 1e-3), light)
            blocked[y, x] = hit and obj.original.name == "Wall"
    return blocked


def _near_agent_shadow(points, light, positions, reach):
    """Whether the ray from each point towards the sun passes within ``reach`` metres
    of an agent's body (a vertical segment 0..2 m over its position)."""
    d = np.asarray(light, np.float64)
    near = np.zeros(points.shape[:2], bool)
    dxy = d[:2] / max(np.dot(d[:2], d[:2]), 1e-12)
    for a in positions:
        rel = a[:2] - points[..., :2]
        t = np.clip(rel @ dxy, 0.0, None)
        along = points + t[..., None] * d
        dist = np.linalg.norm(along[..., :2] - a[:2], axis=-1)
        height = along[..., 2] - a[2]
        near |= (dist < reach) & (height > -0.2) & (height < 2.2)
    return near


def _erode(mask, steps=2):
    out = mask.copy()
    for _ in range(steps):
        inner = out.copy()
        inner[1:] &= out[:-1]
        inner[:-1] &= out[1:]
        inner[:, 1:] &= out[:, :-1]
        inner[:, :-1] &= out[:, 1:]
        out = inner
    return out


@pytest.mark.parametrize("backend", ["moderngl", "blender"])
def test_the_sun_casts_the_walls_and_the_agents_shadows(walled, backend):
    scene, camera, light, geo, pv = _walled_view(walled)
    crowd_only, _ = _render(pv.crowd, backend, camera, light)
    lit, _ = _render(pv.crowd, backend, camera, light, geo)
    shaded, _ = _render(pv.crowd, backend, camera, light, geo, shadows=True)
    _, points, names = _camera_hits(scene, camera, SIZE)
    points[names != "Floor"] = np.nan
    pos = pv.crowd.agents.position.astype(np.float64)
    inside = (points[..., 0] > pos[:, 0].min()) & (points[..., 0] < pos[:, 0].max()) & \
        (points[..., 1] > pos[:, 1].min()) & (points[..., 1] < pos[:, 1].max())
    floor = np.isfinite(points[..., 0]) & (crowd_only[..., 3] == 0) & inside
    ratio = shaded[..., :3].astype(float).sum(-1) / np.maximum(
        lit[..., :3].astype(float).sum(-1), 1)
    dark = ratio < 0.8
    wall = _sun_blocked(scene, points, light[:3]) & floor
    agents = _near_agent_shadow(points, light[:3], pos, 0.45) & floor
    sure_wall = _erode(wall) & ~agents
    sure_lit = _erode(floor & ~wall) & ~_near_agent_shadow(points, light[:3], pos, 0.9)
    assert sure_wall.sum() > 100 and sure_lit.sum() > 30
    assert dark[sure_wall].mean() > 0.97, dark[sure_wall].mean()
    assert (~dark[sure_lit]).mean() > 0.97, (~dark[sure_lit]).mean()
    # the agents' own shadows: dark floor where only an agent stands in the sun's way
    assert (dark & agents & ~wall).sum() > 30
