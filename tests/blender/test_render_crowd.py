"""Render Crowd: the previewed crowd as Blender data that Blender's own renders show.

Oracles: core's CPU skinning of every agent (``skin_vertices`` on the crowd's own rows,
turned and placed) against the instances Blender's depsgraph evaluates from the
Geometry Nodes points object; the preview's own drawing (the ``gpu``-module renderer
through the scene camera) against a Workbench F12 render of the same frame, still and
in an animation render.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview, render_crowd  # noqa: E402
from crowd_addon.blender.cameras import camera_from_object  # noqa: E402
from crowd_addon.blender.looks import plain_material, principled  # noqa: E402
from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.base.skinning import skin_vertices  # noqa: E402
from crowd_addon.gpu.backends import make_renderer  # noqa: E402

SIZE = (160, 120)


extension = cs.extension_fixture()


@pytest.fixture
def crowd_scene():
    """Six by five agents of one walking stream (M = 8: eight shared poses), scaled
    0.8 .. 1.2 by their source, a camera over them, the templates hidden from renders,
    Render Crowd on at frame 9."""
    preview.stop_all()
    scene, rig, body, _ = cs.walking_crowd()
    s = scene.crowd
    s.agent_sources[0].scale_min, s.agent_sources[0].scale_max = 0.8, 1.2
    for obj in (rig, body):
        obj.hide_render = True
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.location = (3.75, -8.0, 6.0)
    cam.rotation_euler = (np.radians(55), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = *SIZE, 100
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    scene.frame_set(9)
    s.render_crowd = True
    pv = preview.get(scene)
    assert pv.render_error == "" and pv.render_frame == 9
    return scene, pv


def _instances(scene):
    """{agent: world vertices (V, 3)} of the evaluated Render Crowd instances (an
    instance's id counts the instanced points: agents whose ``crowd_drawn`` is set)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    points_obj = render_crowd.points_object()
    points = points_obj.data
    drawn = np.zeros(len(points.vertices), bool)
    points.attributes["crowd_drawn"].data.foreach_get("value", drawn)
    agent_of = np.flatnonzero(drawn)
    out = {}
    for inst in depsgraph.object_instances:
        if inst.is_instance and inst.parent is not None and \
                inst.parent.original == points_obj:
            mesh = inst.object.data
            co = np.empty(3 * len(mesh.vertices), np.float32)
            mesh.vertices.foreach_get("co", co)
            m = np.array(inst.matrix_world, np.float64)
            out[int(agent_of[inst.persistent_id[0]])] = co.reshape(-1, 3) @ m[:3, :3].T + \
                m[:3, 3]
    return out


def _core_world(crowd, agents=None):
    """The agents' (default: all) proxy skinned by core on the CPU, turned and placed:
    (n, V, 3)."""
    agents = np.arange(crowd.agents.count) if agents is None else np.asarray(agents)
    mesh = crowd.config.meshes["Rig"][0]
    local = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                          crowd.agent_rows(agents))
    local = local * crowd.agents.scale[agents].astype(np.float64)[:, None, None]
    h = crowd.agents.heading[agents].astype(np.float64)[:, None]
    c, s = np.cos(h), np.sin(h)
    x, y = local[..., 0], local[..., 1]
    return np.stack([c * x - s * y, s * x + c * y, local[..., 2]], -1) + \
        crowd.agents.position[agents].astype(np.float64)[:, None]


def _check_instances(scene, crowd):
    got = _instances(scene)
    assert sorted(got) == list(range(crowd.agents.count))
    expected = _core_world(crowd)
    err = max(float(np.abs(got[i] - expected[i]).max()) for i in got)
    assert err < 1e-5, f"instances differ from core's skinning by {err:.3g} m"


def test_instances_are_cores_skinning_with_one_mesh_per_shared_pose(crowd_scene):
    scene, pv = crowd_scene
    scales = pv.crowd.agents.scale
    assert 0.8 <= scales.min() < scales.max() <= 1.2 and len(set(scales.tolist())) == 30
    _check_instances(scene, pv.crowd)
    points = bpy.data.objects[render_crowd.POINTS].data
    got = np.empty(30, np.float32)
    points.attributes["crowd_scale"].data.foreach_get("value", got)
    np.testing.assert_array_equal(got, scales)
    rgba = np.empty(30 * 4, np.float32)
    points.attributes["crowd_palette0"].data.foreach_get("color", rgba)
    assert (rgba.reshape(30, 4)[:, 3] == 0).all()                  # no palettes here
    rows = pv.crowd.view.agent_rows_index()
    assert pv.render_stats.poses == len(np.unique(rows)) == 8       # shared, not 30
    assert len(bpy.data.collections[render_crowd.POSES].objects) == 8
    scene.frame_set(10)                                             # follows the frame
    assert pv.render_frame == 10
    _check_instances(scene, pv.crowd)
    # an agent in a transition has a pose of its own
    pv.crowd.transition_to_streamed([4], "walk", 6, offset=3)
    scene.frame_set(11)
    assert pv.render_stats.poses == len(np.unique(pv.crowd.view.agent_rows_index())) == 9
    _check_instances(scene, pv.crowd)


def test_a_frame_skins_again_only_the_pose_meshes_whose_pose_changed(crowd_scene):
    """The stream writes one history slice a frame, so of its eight shared poses only
    the one on that slice is skinned again (the others keep their pose meshes, their
    agents moved on to them); a transition's pose is skinned every frame it blends, and
    a jump back re-simulates, writing every row again. The instances stay core's
    skinning throughout."""
    scene, pv = crowd_scene
    for f in (10, 11, 12):
        scene.frame_set(f)
        assert (pv.render_stats.poses, pv.render_stats.skinned) == (8, 1)
        _check_instances(scene, pv.crowd)
    pv.crowd.transition_to_streamed([4], "walk", 6, offset=3)
    scene.frame_set(13)
    assert (pv.render_stats.poses, pv.render_stats.skinned) == (9, 2)   # the slot too
    _check_instances(scene, pv.crowd)
    scene.frame_set(14)
    assert (pv.render_stats.poses, pv.render_stats.skinned) == (9, 2)
    _check_instances(scene, pv.crowd)
    scene.frame_set(5)
    assert pv.render_stats.skinned == pv.render_stats.poses == 8
    _check_instances(scene, pv.crowd)
    # an undo may bring the pose meshes back as they were: the next frame skins all
    pose = bpy.data.objects[render_crowd.POINTS].data.attributes["crowd_pose"]
    mesh = bpy.data.meshes[f"CrowdPoseMesh.{pose.data[0].value:06d}"]
    mesh.vertices.foreach_set("co", np.zeros(3 * len(mesh.vertices), np.float32))
    preview.on_undo()
    scene.frame_set(6)
    assert pv.render_stats.skinned == pv.render_stats.poses == 8
    _check_instances(scene, pv.crowd)


def test_switching_off_removes_the_render_data(crowd_scene):
    scene, pv = crowd_scene
    scene.crowd.render_crowd = False
    assert bpy.data.objects.get(render_crowd.POINTS) is None
    assert bpy.data.collections.get(render_crowd.POSES) is None
    assert not [m for m in bpy.data.meshes if m.name.startswith("CrowdPoseMesh.")]
    assert not [o for o in bpy.data.objects if o.name.startswith("CrowdPose.")]
    scene.crowd.render_crowd = True                       # and back, at once
    _check_instances(scene, pv.crowd)


def test_the_users_data_bearing_render_crowds_names_is_left_alone():
    """Render Crowd makes, reuses and removes only its own data: the user's mesh
    object "Crowd Render", collection "Crowd Poses", node group "Crowd Render
    Instances" and material "CrowdMaterial.mine" come through switching on, frames and
    switching off as they were (before, the object was taken over as the points
    object, its mesh emptied, and deleted with the rest), while the crowd is made
    beside them and made again each frame."""
    preview.stop_all()
    scene, _, _, _ = cs.walking_crowd()
    me = bpy.data.meshes.new("UserMesh")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
    mine = bpy.data.objects.new(render_crowd.POINTS, me)
    scene.collection.objects.link(mine)
    coll = bpy.data.collections.new(render_crowd.POSES)
    scene.collection.children.link(coll)
    group = bpy.data.node_groups.new(render_crowd.NODE_GROUP, "GeometryNodeTree")
    group.use_fake_user = True
    material = bpy.data.materials.new("CrowdMaterial.mine")
    material.use_fake_user = True

    def intact():
        assert bpy.data.objects[render_crowd.POINTS] == mine and mine.data == me
        assert len(me.vertices) == 3 and len(me.polygons) == 1 and not mine.modifiers
        assert not me.attributes.get("crowd_pose")
        assert bpy.data.collections[render_crowd.POSES] == coll and not coll.objects
        assert bpy.data.node_groups[render_crowd.NODE_GROUP] == group and not group.nodes
        assert bpy.data.materials["CrowdMaterial.mine"] == material

    assert bpy.ops.crowd.bake() == {"FINISHED"}
    scene.crowd.render_crowd = True
    pv = preview.get(scene)
    assert pv.render_error == ""
    intact()
    points = render_crowd.points_object()
    assert points != mine and points.name == f"{render_crowd.POINTS}.001"
    _check_instances(scene, pv.crowd)
    scene.frame_set(10)
    assert pv.render_frame == 10 and render_crowd.points_object() == points
    intact()
    _check_instances(scene, pv.crowd)
    scene.crowd.render_crowd = False
    assert render_crowd.points_object() is None
    assert not [o for o in bpy.data.objects if o.name.startswith("CrowdPose.")]
    intact()


def test_a_users_object_bearing_a_pose_objects_name_stops_render_crowd(crowd_scene):
    """Render Crowd refuses to take over an object of the user's named as a pose object
    (the pose objects' names give the instances' order): the error names it, and the
    object stays, through switching off too."""
    scene, pv = crowd_scene
    scene.crowd.render_crowd = False
    mine = bpy.data.objects.new("CrowdPose.000003", None)
    scene.collection.objects.link(mine)
    scene.crowd.render_crowd = True
    assert pv.render_error == ("Render Crowd: 'CrowdPose.000003' is not Render Crowd's; "
                               "rename it to use Render Crowd")
    scene.crowd.render_crowd = False
    assert bpy.data.objects["CrowdPose.000003"] == mine and mine.type == "EMPTY"
    mine.name = "Mine"
    scene.crowd.render_crowd = True
    assert pv.render_error == ""
    _check_instances(scene, pv.crowd)


def _preview_alpha(scene, crowd, frame=None):
    """Coverage of the preview's own drawing of ``crowd``'s state at ``frame`` (default:
    its own; drawn from a crowd of its own) through the scene camera, rows top-down."""
    cs.init_gpu()
    twin = Crowd(crowd.config, skinning="gpu")
    twin.reset(crowd.frame if frame is None else frame)
    r = make_renderer(twin.view, "blender", SIZE)
    try:
        r.sync()
        r.render(camera_from_object(scene.camera, SIZE[0] / SIZE[1]),
                 clear=(0.0, 0.0, 0.0, 0.0))
        return r.read_image()[..., 3] > 0
    finally:
        r.release()


def _load_alpha(path):
    return cs.image_pixels(path)[::-1, :, 3] > 0.5                  # rows top-down


def _eevee():
    """EEVEE's engine name in this Blender (4.2-4.5: BLENDER_EEVEE_NEXT)."""
    engines = {e.identifier for e in
               bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"


def _workbench(scene, path, animation=False, engine="BLENDER_WORKBENCH"):
    r = scene.render
    r.engine, r.film_transparent = engine, True
    if engine == "BLENDER_WORKBENCH":       # no anti-aliasing: the preview has none here
        scene.display.render_aa = "OFF"
    if engine == "CYCLES":                  # one sharp sample: silhouettes, not light
        scene.cycles.samples, scene.cycles.device = 1, "CPU"
        scene.cycles.filter_width = 0.01
    r.image_settings.file_format, r.image_settings.color_mode = "PNG", "RGBA"
    r.filepath = str(path)
    bpy.ops.render.render(write_still=not animation, animation=animation)


def _overlap(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


@pytest.mark.parametrize("engine", ["BLENDER_WORKBENCH", "EEVEE", "CYCLES"])
def test_f12_shows_the_crowd_where_the_preview_draws_it(crowd_scene, tmp_path, engine):
    scene, pv = crowd_scene
    _workbench(scene, tmp_path / "still.png", engine=_eevee() if engine == "EEVEE" else engine)
    rendered = _load_alpha(tmp_path / "still.png")
    drawn = _preview_alpha(scene, pv.crowd)
    assert drawn.sum() > 300
    assert _overlap(rendered, drawn) > 0.9, _overlap(rendered, drawn)


def test_an_animation_render_follows_the_crowd_frame_by_frame(crowd_scene, tmp_path):
    scene, pv = crowd_scene
    scene.frame_start, scene.frame_end = 12, 13
    _workbench(scene, tmp_path / "anim_", animation=True)
    assert pv.crowd.frame == scene.frame_current == 9     # the render puts the frame back
    for frame in (12, 13):
        img = _load_alpha(tmp_path / f"anim_{frame:04d}.png")
        assert _overlap(img, _preview_alpha(scene, pv.crowd, frame)) > 0.9, frame
    first, last = (_load_alpha(tmp_path / f"anim_{f:04d}.png") for f in (12, 13))
    assert (first != last).sum() > 20                    # the render moved with the crowd
    _check_instances(scene, pv.crowd)



def test_a_saved_file_renders_its_crowd_after_loading(crowd_scene, tmp_path):
    """What a command-line render (``blender -b shot.blend -a``) relies on: the file
    comes back with its crowd following the frame."""
    scene, _ = crowd_scene
    path = str(tmp_path / "shot.blend")
    scene.crowd.preview_enabled = False          # only the render switch is saved on
    bpy.ops.wm.save_as_mainfile(filepath=path)
    preview.stop_all()
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    _follows_the_frame(scene)


def _follows_the_frame(scene):
    """The scene's crowd runs and its render data follows the frame."""
    pv = preview.get(scene)
    assert pv is not None and scene.crowd.render_crowd
    scene.frame_set(12)
    assert pv.render_frame == 12
    _check_instances(scene, pv.crowd)


def test_stopping_the_preview_switches_render_crowd_off(crowd_scene):
    """A stopped preview no longer moves the render data: F12 would show a frozen
    crowd, so the data goes with it."""
    scene, _ = crowd_scene
    preview.stop(scene)
    assert not scene.crowd.render_crowd
    assert bpy.data.objects.get(render_crowd.POINTS) is None


def test_switching_on_without_a_preview_starts_it(crowd_scene):
    scene, _ = crowd_scene
    preview.stop(scene)
    scene.crowd.render_crowd = True
    pv = preview.get(scene)
    assert pv is not None and pv.render_frame == scene.frame_current
    _check_instances(scene, pv.crowd)


def test_the_scene_pass_leaves_the_render_crowd_out(crowd_scene):
    """The headless preview draws the crowd itself: Render Crowd's instances are not
    scene geometry (they would draw every fan twice)."""
    from crowd_addon.blender.scene_geometry import scene_geometry
    scene, _ = crowd_scene
    assert _instances(scene)                          # the render data is there
    geo = scene_geometry(scene)
    assert geo.triangle_count == 0 and render_crowd.POINTS not in geo.objects


def test_agents_of_a_character_without_a_body_are_not_instanced(crowd_scene):
    scene, _ = crowd_scene
    s = scene.crowd
    ghost_rig = cs.make_armature("Ghost")
    cs.add_stream(cs.add_character(s, ghost_rig, None), "glide",
                  cs.make_action(ghost_rig, "glide", seed=4))
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    pv = preview.get(scene)
    skel = pv.crowd.view.agent_skeleton
    bodied = [k for k, sk in enumerate(pv.crowd.view.skeletons) if sk.name == "Rig"][0]
    assert 0 < (skel == bodied).sum() < skel.size          # both characters have agents
    got = _instances(scene)
    assert sorted(got) == sorted(np.flatnonzero(skel == bodied).tolist())
    expected = _core_world(pv.crowd, np.flatnonzero(skel == bodied))
    for row, agent in enumerate(np.flatnonzero(skel == bodied)):
        assert np.abs(got[agent] - expected[row]).max() < 1e-5


def _dress_in_colours(scene):
    """The fixture's crowd in colours: the body's upper boxes in a white "shirt" that
    takes each agent's colour (red for the first three rows of seats, blue for the
    others, by a colour attribute), the lower boxes in "trousers" that a palette
    colours green or yellow by an INT attribute "team" (alternate columns of seats);
    a sun to see them by."""
    s = scene.crowd
    ch, src = s.characters[0], s.agent_sources[0]
    body, seats = ch.body, src.object
    shirt = plain_material("shirt", (1.0, 1.0, 1.0, 1.0))
    trousers = plain_material("trousers", (0.5, 0.5, 0.5, 1.0))
    body.data.materials.append(shirt)
    body.data.materials.append(trousers)
    # one material a box (six faces a bone, cs.make_proxy): the preview colours a vertex
    # by one of its faces' materials, so a box of two materials would differ in F12
    z = np.array([min(body.data.vertices[v].co.z for v in p.vertices)
                  for p in body.data.polygons]).reshape(-1, 6).min(1)
    lower = np.repeat(z < np.median(z), 6)
    body.data.polygons.foreach_set("material_index", lower.astype(np.int32))
    n = len(seats.data.vertices)
    red = np.arange(n) < n // 2
    col = np.where(red[:, None], (1.0, 0.05, 0.05, 1.0), (0.05, 0.05, 1.0, 1.0))
    seats.data.attributes.new("Col", "FLOAT_COLOR", "POINT").data.foreach_set(
        "color", col.astype(np.float32).ravel())
    team = (np.arange(n) % 2).astype(np.int32)
    seats.data.attributes.new("team", "INT", "POINT").data.foreach_set("value", team)
    src.color_mode = "ATTRIBUTE"
    pal = ch.palettes.add()
    pal.material, pal.mode, pal.attribute, pal.count = "trousers", "ATTRIBUTE", "team", 2
    pal.color_0, pal.color_1 = (0.05, 0.9, 0.05), (0.9, 0.9, 0.05)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.rotation_euler = 3.0, (np.radians(30), 0.0, 0.0)
    scene.collection.objects.link(sun)
    assert bpy.ops.crowd.bake() == {"FINISHED"}


def _hues(rgba, covered):
    """Per pixel: 0 red, 1 green, 2 blue, 3 yellow (red and green), -1 grey or not
    ``covered``."""
    rgb = rgba[..., :3]
    hi, lo = rgb.max(-1), rgb.min(-1)
    strong = rgb > lo[..., None] + 0.5 * (hi - lo)[..., None]
    kind = np.where(strong[..., 0] & strong[..., 1] & ~strong[..., 2], 3,
                    np.argmax(rgb, -1))
    return np.where(covered & (hi - lo > 0.25 * np.maximum(hi, 1e-6)), kind, -1)


@pytest.mark.parametrize("engine", ["CYCLES", "EEVEE"])
def test_f12_colours_each_agent_as_the_preview_does(crowd_scene, tmp_path, engine):
    """Team colours on white shirts and palette colours on trousers: in an F12 render
    (EEVEE, Cycles) each agent's pixels have the hues the preview draws them in. Before
    the crowd's material copies, F12 showed every shirt white and every pair of
    trousers grey."""
    scene, pv = crowd_scene
    _dress_in_colours(scene)
    pv = preview.get(scene)
    assert scene.crowd.render_crowd and pv.render_error == ""
    names = {m.name for o in bpy.data.meshes if o.name.startswith("CrowdPoseMesh.")
             for m in o.materials}
    assert names == {"CrowdMaterial.shirt", "CrowdMaterial.trousers.0"}
    _workbench(scene, tmp_path / "f12.png", engine=_eevee() if engine == "EEVEE" else engine)
    rendered = cs.image_pixels(tmp_path / "f12.png")[::-1]
    cs.init_gpu()
    twin = Crowd(pv.crowd.config, skinning="gpu")
    twin.reset(pv.crowd.frame)
    r = make_renderer(twin.view, "blender", SIZE)
    try:
        r.sync()
        r.render(camera_from_object(scene.camera, SIZE[0] / SIZE[1]),
                 clear=(0.0, 0.0, 0.0, 0.0))
        drawn = r.read_image().astype(np.float32) / 255.0
    finally:
        r.release()
    covered = (rendered[..., 3] > 0.5) & (drawn[..., 3] > 0.5)
    want, got = _hues(drawn, covered), _hues(rendered, covered)
    counts = {k: int((want == k).sum()) for k in range(4)}
    assert min(counts.values()) > 20, counts
    inner = want >= 0            # pixels inside one colour in the preview: not its edges
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        inner &= want == np.roll(want, (dy, dx), (0, 1))
    judged = inner & (got >= 0)
    agree = float((want[judged] == got[judged]).mean())
    assert judged.sum() > 0.5 * inner.sum() and agree > 0.9, (agree, judged.sum(), counts)


def test_the_crowd_materials_follow_their_source(crowd_scene):
    """A material edited while Render Crowd is on: the next frame's pose meshes wear a
    copy made from the edited material, and switching off removes the copies."""
    scene, pv = crowd_scene
    _dress_in_colours(scene)
    copy = bpy.data.materials["CrowdMaterial.trousers.0"]
    bsdf = principled(bpy.data.materials["trousers"])
    bsdf.inputs["Roughness"].default_value = 0.123
    scene.frame_set(scene.frame_current + 1)
    copy = bpy.data.materials["CrowdMaterial.trousers.0"]
    assert abs(principled(copy).inputs["Roughness"].default_value - 0.123) < 1e-6
    users = [m for m in bpy.data.meshes if m.name.startswith("CrowdPoseMesh.")
             and copy.name in m.materials]
    assert users and all(m.materials[1] == copy for m in users)
    scene.crowd.render_crowd = False
    assert not [m for m in bpy.data.materials if m.name.startswith("CrowdMaterial.")]
    assert {"shirt", "trousers"} <= set(bpy.data.materials.keys())


def _count_bakes(monkeypatch) -> list:
    """A list that gets an item each time a crowd is baked from a scene."""
    from crowd_addon.blender import scene_config
    bakes, real = [], scene_config.config_steps
    monkeypatch.setattr(scene_config, "config_steps",
                        lambda *a, **k: bakes.append(1) or real(*a, **k))
    return bakes


def test_an_undo_that_brings_the_switch_back_brings_its_crowd_back(crowd_scene):
    """Stopping the preview removes the render data; undoing an edit made before
    restores the switch and the data as they were: the crowd runs again, so the data
    follows the frame instead of rendering frozen."""
    scene, _ = crowd_scene
    bpy.ops.ed.undo_push(message="Render Crowd on")
    scene.objects["Rig"].location.x = 3.0
    bpy.ops.ed.undo_push(message="move the rig")
    assert bpy.ops.crowd.preview_toggle() == {"FINISHED"}
    assert bpy.data.objects.get(render_crowd.POINTS) is None
    bpy.ops.ed.undo()
    scene = bpy.context.scene
    assert scene.crowd.render_crowd and bpy.data.objects.get(render_crowd.POINTS)
    assert scene.crowd.preview_enabled
    _follows_the_frame(scene)


def test_enabling_the_extension_again_brings_the_render_crowd_back(crowd_scene):
    """Disabling leaves the switch and the render data in the file as they are;
    enabling again restarts the crowd they follow, as opening the file does."""
    import crowd_addon
    scene, _ = crowd_scene
    crowd_addon.unregister()
    try:
        assert bpy.data.objects.get(render_crowd.POINTS) is not None
    finally:
        crowd_addon.register()
    _follows_the_frame(scene)


def test_a_switch_that_cannot_start_goes_back_off_and_the_file_opens_without_a_bake(
        crowd_scene, tmp_path, monkeypatch):
    scene, _ = crowd_scene
    path = str(tmp_path / "shot.blend")
    bpy.data.objects.remove(scene.crowd.characters[0].armature)     # nothing can be built
    bpy.ops.wm.save_as_mainfile(filepath=path)                      # saved with it on
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert not scene.crowd.render_crowd and not scene.crowd.preview_enabled
    assert "no armature chosen" in preview.last_error(scene)
    assert bpy.data.objects.get(render_crowd.POINTS) is None        # no frozen crowd left
    scene.crowd.render_crowd = True                                 # the switch, by hand
    assert not scene.crowd.render_crowd and preview.get(scene) is None
    assert "Render Crowd needs the preview, which cannot start" in preview.last_error(scene)
    bpy.ops.wm.save_mainfile()
    bakes = _count_bakes(monkeypatch)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert bakes == [] and not bpy.context.scene.crowd.render_crowd
