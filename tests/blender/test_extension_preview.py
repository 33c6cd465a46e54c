"""The viewport preview and the extension's registration, in this process.

Oracles: Blender's own bookkeeping (``draw_handler_remove`` refuses a handler that
is gone, ``bpy.types`` and ``bpy.app.handlers`` list what is registered, a saved and
reopened .blend), a fresh core ``Crowd`` for determinism, and core's CPU skinning of
every agent, projected with the same camera, for the pixels the viewport draw path
writes into an offscreen buffer.
"""

import os
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

import crowd_addon  # noqa: E402
from crowd_addon.blender import preview, registration  # noqa: E402
from crowd_addon.blender.props import settings_fingerprint  # noqa: E402
from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.base.skinning import skin_vertices  # noqa: E402
from crowd_addon.core.base.camera import look_at, perspective  # noqa: E402


extension = cs.extension_fixture()


def _build_scene():
    preview.stop_all()
    scene, rig, _, walk = cs.walking_crowd(markers=[("step", 7)])
    return scene, rig, walk


@pytest.fixture
def running():
    scene, rig, walk = _build_scene()
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    return scene, rig, walk, preview.get(scene)


def _handlers_from(prefix):
    """Every app handler defined in a module under ``prefix``."""
    lists = [getattr(bpy.app.handlers, n) for n in dir(bpy.app.handlers)]
    return [h for lst in lists if isinstance(lst, list) for h in lst
            if getattr(h, "__module__", "").startswith(prefix)]


def _handler_is_gone(handle):
    with pytest.raises(ValueError, match="already removed"):
        bpy.types.SpaceView3D.draw_handler_remove(handle, "WINDOW")
    return True


def test_register_unregister_twice_leaves_nothing_behind():
    mine = hasattr(bpy.types.Scene, "crowd")
    if mine:
        crowd_addon.unregister()
    try:
        for _ in range(2):
            crowd_addon.register()
            assert hasattr(bpy.types, "CROWD_OT_bake") and hasattr(bpy.types, "CROWD_PT_main")
            assert preview.on_frame_change in bpy.app.handlers.frame_change_post
            scene, _rig, _walk = _build_scene()
            bpy.ops.crowd.bake()
            handle = preview.draw_handle()
            assert handle is not None
            crowd_addon.unregister()
            assert registration.leftovers() == []
            assert not [n for n in dir(bpy.types) if n.startswith("CROWD_")]
            assert not hasattr(bpy.types.Scene, "crowd")
            assert _handlers_from("crowd_addon") == []
            assert _handler_is_gone(handle)
    finally:
        crowd_addon.register()


def test_preview_adds_and_removes_its_draw_handler(running):
    scene, *_ = running
    handle = preview.draw_handle()
    assert handle is not None and scene.crowd.preview_enabled
    assert bpy.ops.crowd.preview_toggle() == {"FINISHED"}
    assert preview.get(scene) is None and preview.draw_handle() is None
    assert not scene.crowd.preview_enabled
    assert _handler_is_gone(handle)
    assert bpy.ops.crowd.preview_toggle() == {"FINISHED"}            # bakes and starts
    assert preview.get(scene) is not None and preview.draw_handle() is not None


def test_frame_changes_drive_the_crowd_and_scrubbing_back_is_deterministic(running):
    scene, _rig, _walk, pv = running
    crowd = pv.crowd
    for f in range(2, 31):
        scene.frame_set(f)
    assert crowd.frame == 30
    scene.frame_set(17)
    fresh = Crowd(crowd.config)
    fresh.advance_to(17)
    assert crowd.frame == 17
    np.testing.assert_array_equal(crowd.agent_poses(), fresh.agent_poses())
    assert pv.step_ms > 0 and not pv.paused


def test_scrubbing_a_long_shot_jumps_from_the_nearest_snapshot(running):
    """The preview keeps snapshots (the preferences' defaults here: every 30 frames):
    a jump back, or forward past frames seen before, steps 1 to 30 frames and
    shows what a fresh crowd stepped there shows; the panel says what is kept."""
    from crowd_addon.blender import panels, prefs
    scene, _rig, _walk, pv = running
    crowd = pv.crowd
    assert (crowd.snapshots.requested, crowd.snapshots.max_bytes) == \
        prefs.snapshot_settings() == (30, 2048 << 20)
    scene.frame_set(100)
    assert crowd.snapshots.frames == [1, 31, 61, 91]
    steps = []
    inner = crowd.frame_tasks.step
    crowd.frame_tasks.step = lambda: steps.append(1) or inner()
    for target in (47, 95, 12, 88, 61, 31):
        steps.clear()
        scene.frame_set(target)
        assert crowd.frame == target and 1 <= len(steps) <= 30, (target, len(steps))
        fresh = Crowd(crowd.config)
        fresh.advance_to(target)
        np.testing.assert_array_equal(crowd.agent_poses(), fresh.agent_poses())
    line = panels.snapshot_line(crowd.snapshots)
    assert line.startswith("Scrubbing: a snapshot every 30 frames, 4 kept,"), line
    assert prefs.CROWD_AP_preferences.is_registered


def _skinned_boxes(crowd, vp, size):
    """Pixel bounding boxes (n, 4) of every agent's proxy skinned on the CPU."""
    mesh = crowd.config.meshes["Rig"][0]
    verts = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                          crowd.agent_rows())                           # (N, V, 3)
    c, s = np.cos(crowd.agents.heading), np.sin(crowd.agents.heading)
    x, y = verts[..., 0], verts[..., 1]
    world = np.stack([c[:, None] * x - s[:, None] * y, s[:, None] * x + c[:, None] * y,
                      verts[..., 2]], -1) + crowd.agents.position[:, None]
    clip = np.einsum("ij,nvj->nvi", vp, np.concatenate([world, np.ones_like(x)[..., None]],
                                                       -1))
    ndc = clip[..., :2] / clip[..., 3:4]
    px = (ndc + 1) / 2 * np.array(size)
    return np.concatenate([px.min(1), px.max(1)], 1)                    # x0 y0 x1 y1


def _draw(scene, view, proj, size, after=None):
    import gpu
    off = gpu.types.GPUOffScreen(*size)
    with off.bind():
        gpu.state.active_framebuffer_get().clear(color=(0, 0, 0, 0), depth=1.0)
        if after is not None:
            after()                          # Blender draws first, caching its state
        drawn = preview.draw_scene(scene, view, proj)
        if after is not None:
            after()                          # and must still draw right after the crowd
    buf = off.texture_color.read()
    buf.dimensions = size[0] * size[1] * 4
    img = np.array(buf, np.float32).reshape(size[1], size[0], 4)
    off.free()
    return drawn, img


def _check_against_core(img, crowd, vp, size):
    covered = img[..., 3] > 0                                   # rows bottom-up, like GL
    inside = np.zeros_like(covered)
    ys, xs = np.mgrid[0:size[1], 0:size[0]] + 0.5
    for x0, y0, x1, y1 in _skinned_boxes(crowd, vp, size):
        box = (xs >= x0 - 1.5) & (xs <= x1 + 1.5) & (ys >= y0 - 1.5) & (ys <= y1 + 1.5)
        assert covered[box].any()                               # every agent shows
        inside |= box
    assert covered.sum() > 500
    assert covered[~inside].sum() <= 0.005 * covered.sum()     # and nothing else does
    assert img[covered][:, :3].std(0).max() > 5                 # lit, varied colours


def test_offscreen_draw_puts_every_agent_where_core_skins_it(running):
    scene, _rig, _walk, pv = running
    cs.init_gpu()
    size = (240, 160)
    view = look_at((3.75, -9.0, 6.0), (3.75, 3.0, 0.8))
    proj = perspective(np.radians(55), size[0] / size[1], 0.1, 100.0)
    images = []
    for frame in (9, 14):                 # the second draw reuses the renderer
        scene.frame_set(frame)
        drawn, img = _draw(scene, view, proj, size)
        assert drawn, pv.draw_error
        _check_against_core(img, pv.crowd, proj @ view, size)
        images.append(img)
    assert (np.abs(images[1] - images[0]) > 0).any()            # the crowd moved


def test_deleting_the_armature_or_an_action_pauses_with_a_message(running):
    scene, rig, walk, pv = running
    scene.frame_set(5)
    bpy.data.objects.remove(rig)
    scene.frame_set(6)
    assert pv.crowd.frame == 5
    assert "armature 'Rig' was deleted" in pv.status()
    # the undo handler resumes once the scene has what the crowd was built from
    new_rig = cs.make_armature("Rig")
    scene.crowd.characters["Rig"].armature = new_rig
    preview.on_undo(scene)
    assert not pv.paused and pv.crowd.frame == 6
    bpy.data.actions.remove(walk)
    scene.frame_set(7)
    assert pv.crowd.frame == 6 and "action 'walk' was deleted" in pv.status()
    cs.init_gpu()
    drawn, _ = _draw(scene, look_at((0, -9, 5), (0, 0, 1)), perspective(1.0, 1.0, 0.1, 50),
                     (32, 32))
    assert drawn                                                # frozen, still drawn


def test_deleting_with_the_delete_operator_pauses_too(running):
    scene, rig, _walk, pv = running
    bpy.ops.object.select_all(action="DESELECT")
    rig.select_set(True)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.delete()
    bpy.context.view_layer.update()
    assert pv.paused
    scene.frame_set(12)
    assert pv.crowd.frame == 1


def test_changed_settings_mark_the_crowd_stale(running):
    scene, _rig, _walk, pv = running
    scene.crowd.max_offset = 9
    scene.frame_set(2)
    assert preview.check(scene) is pv                           # as the panel does
    assert pv.stale and "Bake" in pv.status() and pv.crowd.frame == 2   # still runs
    scene.crowd.max_offset = 8
    assert not preview.check(scene).stale


def test_generate_agents_updates_the_running_crowd_without_a_bake(running):
    scene, _rig, _walk, pv = running
    clips = pv.crowd.config.clips
    scene.crowd.agent_sources[0].object = cs.make_seats(3, 3, name="Few")
    assert bpy.ops.crowd.generate_agents() == {"FINISHED"}
    now = preview.get(scene)
    assert now.crowd.agents.count == 9 and now.crowd.config.clips is clips


def test_settings_survive_save_and_reload_and_the_preview_restarts(running, tmp_path,
                                                                  monkeypatch):
    monkeypatch.setattr(preview, "_has_viewport", lambda: True)    # opened in Blender's UI
    scene, _rig, _walk, pv = running
    s = scene.crowd
    anim = s.characters[0].streams[0]
    cs.add_node(anim, "sm", "STATE_MACHINE", [("calm", "clip")], initial_state="calm")
    tr = anim.nodes["sm"].transitions.add()
    tr.target, tr.trigger = "calm", "reset"
    s.when_full, s.lod_far = "CUT", 650.0
    before = settings_fingerprint(s)
    agents = pv.crowd.agents.count
    path = str(tmp_path / "crowd.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert preview.get(bpy.context.scene) is None and preview.draw_handle() is None
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert settings_fingerprint(scene.crowd) == before
    assert scene.crowd.characters[0].streams[0].nodes["sm"].transitions[0].trigger == "reset"
    again = preview.get(scene)                                  # load_post rebuilt it
    assert again is not None and again.crowd.agents.count == agents and preview.draw_handle()
    # a file whose armature is gone loads with the preview stopped and the reason
    bpy.data.objects.remove(scene.crowd.characters[0].armature)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert preview.get(scene) is None and not scene.crowd.preview_enabled
    assert "no armature chosen" in preview.last_error(scene)


class _Layout:
    """Stands in for ``UILayout`` and checks that every property, list and operator
    the panels name exists in Blender's RNA (a UI typo would only show in the UI)."""

    use_property_split = False

    def __init__(self, seen):
        self.seen = seen

    def _sub(self, *_a, **_k):
        return self

    row = column = box = _sub

    def label(self, text="", **_k):
        self.seen.append(("label", text))

    def prop(self, data, name, **_k):
        assert name in data.bl_rna.properties, (data, name)
        self.seen.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **_k):
        assert name in data.bl_rna.properties and search_name in search_data.bl_rna.properties

    def template_list(self, list_id, _uid, data, coll, active_data, active, **_k):
        assert hasattr(bpy.types, list_id) and coll in data.bl_rna.properties
        assert active in active_data.bl_rna.properties

    def operator(self, idname, **_k):
        mod, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, mod), name), idname
        rna = getattr(getattr(bpy.ops, mod), name).get_rna_type()
        self.seen.append(("operator", idname))
        return _OpProps(rna)


class _OpProps:
    def __init__(self, rna):
        object.__setattr__(self, "rna", rna)

    def __setattr__(self, key, value):
        assert key in self.rna.properties, key


def test_panels_draw_existing_properties_and_operators(running):
    from crowd_addon.blender import panels
    scene, rig, _walk, pv = running
    anim = scene.crowd.characters[0].streams[0]
    cs.add_node(anim, "sm", "STATE_MACHINE", [("calm", "clip")])
    anim.nodes["sm"].transitions.add()
    cs.add_node(anim, "bs", "BLEND_SPACE", ["clip"])
    cs.add_node(anim, "lay", "LAYER", ["clip", "clip"], layer_mode="ADDITIVE",
                mask_source="COLLECTION")
    cs.add_lod(scene.crowd.characters[0], None)
    char = scene.crowd.characters[0]
    char.variants.add().object = char.body
    char.props.add().object = char.body
    char.variant_mode = "ATTRIBUTE"
    src = scene.crowd.agent_sources[0]
    ctx = type("Ctx", (), {"scene": scene})()
    seen = []
    for ul, items in ((panels.CROWD_UL_variants, char.variants),
                      (panels.CROWD_UL_props, char.props)):
        ul.draw_item(None, None, _Layout(seen), char, items[0], 0, True, "")
    for kind, character, stream in (("sm", "FIXED", "FIXED"), ("bs", "ATTRIBUTE", "ATTRIBUTE"),
                                    ("lay", "WEIGHTS", "FIXED"), ("clip", "FIXED", "RANDOM")):
        src.character_mode, src.stream_mode = character, stream
        anim.active_node_index = anim.nodes.find(kind)
        for cls in panels.CLASSES:
            if issubclass(cls, bpy.types.Panel):
                cls.draw(type("P", (), {"layout": _Layout(seen)})(), ctx)
    labels = [t for k, t in seen if k == "label"]
    assert any("30 agents, 1 streams" in t for t in labels)
    assert ("operator", "crowd.bake") in seen and ("prop", "transition_slots") in seen
    assert ("prop", "body") in seen and ("prop", "character_attribute") in seen
    assert {("prop", "body_weight"), ("prop", "variant_attribute"), ("prop", "share"),
            ("prop", "weight"), ("prop", "plan_motion_only")} <= set(seen)


def test_blender_still_draws_right_after_the_crowd(running):
    """moderngl shares Blender's GL context; Blender's state cache must not be left
    stale (a textured quad drawn by Blender after the crowd shows its texture)."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    from mathutils import Matrix
    scene, *_ = running
    cs.init_gpu()
    red = gpu.types.GPUTexture((2, 2), format="RGBA8", data=gpu.types.Buffer(
        "FLOAT", 16, [1.0, 0.0, 0.0, 1.0] * 4))
    shader = gpu.shader.from_builtin("IMAGE")
    quad = batch_for_shader(shader, "TRIS", {
        "pos": ((-1, -1), (0, -1), (0, 1), (-1, -1), (0, 1), (-1, 1)),
        "texCoord": ((0, 0), (1, 0), (1, 1), (0, 0), (1, 1), (0, 1))})

    def left_half_red():
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_identity()
            gpu.matrix.load_projection_matrix(Matrix.Identity(4))
            gpu.state.depth_test_set("NONE")
            shader.bind()
            shader.uniform_sampler("image", red)
            quad.draw(shader)
            gpu.state.depth_test_set("LESS_EQUAL")
    size = (64, 48)
    drawn, img = _draw(scene, look_at((3.75, -9.0, 6.0), (3.75, 3.0, 0.8)),
                       perspective(1.0, 64 / 48, 0.1, 100.0), size, after=left_half_red)
    assert drawn
    assert (img[:, :32] == [255, 0, 0, 255]).all()
    assert (img[:, 32:, 3] > 0).any()                       # the crowd on the right


def test_measure_repetition_sees_through_the_scene_camera(running):
    """The panel's measurement at the current frame, through the scene camera: the
    oracle is Blender's own projection of that camera (``calc_matrix_camera`` at the
    render size, times the inverse world matrix) fed to the metric's definition."""
    from crowd_addon.blender import panels
    from crowd_addon.core.variety.repetition import RepetitionSettings, frame_repetition
    scene, _rig, _walk, pv = running
    assert pv.repetition is None
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (4.0, -14.0, 9.0), (0.95, 0.0, 0.2)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 640, 400
    scene.render.resolution_percentage = 100
    scene.crowd.repetition_neighbours = 3
    scene.frame_set(4)
    assert bpy.ops.crowd.measure_repetition() == {"FINISHED"}
    got = pv.repetition
    dg = bpy.context.evaluated_depsgraph_get()
    proj = np.array(cam.calc_matrix_camera(dg, x=640, y=400), np.float64)
    vp = proj @ np.array(cam.matrix_world.inverted(), np.float64)
    a = pv.crowd.view.agents
    want = frame_repetition(a.position, a.kind, a.ref, a.offset,
                            pv.crowd.view.agent_skeleton, a.color, vp,
                            RepetitionSettings(k=3, width=640, height=400))
    assert got.frames == (4,) and got.settings.k == 3
    assert (got.per_frame[0], got.visible[0], got.pairs[0]) == pytest.approx(want)
    assert 0 < got.visible[0] <= 30 and pv.repetition_seen == "scene camera 'Cam'"
    assert "Repetition" in panels.repetition_line(got, pv.repetition_seen)
    scene.camera = None                           # no camera and no viewport: named
    with pytest.raises(RuntimeError, match="no camera"):
        bpy.ops.crowd.measure_repetition()


def test_plan_variety_and_apply_it(running):
    """The panel's planner on the previewed crowd through the scene camera, then
    Apply: the Crowd settings take the plan's M, copies and Spread offsets, and the
    bake that follows builds the plan's streams."""
    from crowd_addon.blender import panels
    from crowd_addon.core.variety.repetition import RepetitionSettings, crowd_repetition
    scene, _rig, _walk, pv = running
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (4.0, -14.0, 9.0), (0.95, 0.0, 0.2)
    scene.camera = cam
    s = scene.crowd
    s.plan_budget_mb, s.plan_max_streams = 1.0, 4
    assert bpy.ops.crowd.apply_plan.poll() is False          # nothing planned yet
    assert bpy.ops.crowd.plan_variety() == {"FINISHED"}
    plan = pv.plan
    assert plan.templates == ("walk",) and plan.default.max_offset == 8
    assert plan.planned.fits and plan.planned.streams <= 4 and plan.planned.bytes <= 1e6
    assert plan.planned.repetition <= plan.default.repetition
    assert plan.settings.appearance
    s.plan_motion_only = True                               # motion alone: looks left out
    assert bpy.ops.crowd.plan_variety() == {"FINISHED"}
    assert not pv.plan.settings.appearance
    assert pv.plan.default.repetition >= plan.default.repetition
    assert pv.plan.planned.repetition <= pv.plan.default.repetition
    plan = pv.plan
    seen = []
    ctx = type("Ctx", (), {"scene": scene})()
    panels.CROWD_PT_main.draw(type("P", (), {"layout": _Layout(seen)})(), ctx)
    assert ("operator", "crowd.apply_plan") in seen
    assert any(t.startswith("planned: M") for k, t in seen if k == "label")
    p = plan.planned
    assert bpy.ops.crowd.apply_plan() == {"FINISHED"}
    assert s.max_offset == p.max_offset and s.characters[0].streams[0].copies == \
        p.template_copies[0]
    assert s.agent_sources[0].offset_mode == ("SPREAD" if p.offset_mode == "SPREAD"
                                              else "UNIFORM")
    baked = preview.get(scene)
    assert baked.crowd.config.max_offset == p.max_offset
    assert len(baked.crowd.config.streams) == p.streams
    assert crowd_repetition(baked.crowd.view, np.eye(4),
                            settings=RepetitionSettings()).frames == (scene.frame_current,)


def test_a_renamed_scene_keeps_its_one_preview_and_its_api_handle(running):
    """Previews follow their scene, not its name: a rename keeps the one preview (and
    the API callbacks registered for it); a new scene given the old name has none."""
    from crowd_addon import api
    scene, _rig, _walk, pv = running
    got = []
    api.on_event("step", lambda n, f, ids: got.append(f))         # for scene 'Scene'
    scene.name = "Shot010"
    assert api.scene_crowd().crowd is pv.crowd                      # asked before the preview
    assert preview.get(scene) is pv and len(preview._PREVIEWS) == 1
    for f in range(2, 15):
        scene.frame_set(f)
    assert pv.crowd.frame == 14 and got
    new = bpy.data.scenes.new("Scene")
    assert preview.get(new) is None and api.scene_crowd(new).crowd is None
    handle = preview.draw_handle()
    assert bpy.ops.crowd.preview_toggle() == {"FINISHED"}         # the panel's toggle: off
    assert not preview._PREVIEWS and preview.draw_handle() is None
    assert _handler_is_gone(handle) and not scene.crowd.preview_enabled


def test_a_background_open_bakes_nothing_and_keeps_the_preview_flag(running, tmp_path,
                                                                    monkeypatch):
    """``blender -b shot.blend -c crowd export``: no viewport to show a preview, so
    opening the file bakes nothing for one; the flag stays, so the file still opens
    with its preview in Blender's UI."""
    from crowd_addon.blender import scene_config
    path = str(tmp_path / "shot.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bakes, real = [], scene_config.config_steps
    monkeypatch.setattr(scene_config, "config_steps",
                        lambda *a, **k: bakes.append(1) or real(*a, **k))
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert bpy.app.background and bakes == [] and preview.get(scene) is None
    assert scene.crowd.preview_enabled
    monkeypatch.setattr(preview, "_has_viewport", lambda: True)    # the same file in the UI
    bpy.ops.wm.open_mainfile(filepath=path)
    assert len(bakes) == 1 and preview.get(bpy.context.scene) is not None


OPEN_FOR_A_COMMAND = """
import sys
import bpy
from crowd_addon.blender import blend_shot, scene_config
bakes, real = [], scene_config.config_steps
scene_config.config_steps = lambda *a, **k: bakes.append(1) or real(*a, **k)
scene = blend_shot.open_scene(sys.argv[1], None)
print(len(bakes), scene.crowd.render_crowd)
"""


def test_a_command_opening_a_render_crowd_file_bakes_it_only_itself(running, tmp_path):
    """``crowd export --blend`` of a file with Render Crowd on: the command opens the
    file with the bpy module, registers the extension and bakes the crowd it exports.
    Registering also restarted the file's crowds (for Render Crowd), a bake nobody
    used (and a crowd script run before the command could check its trust)."""
    import subprocess
    import sys
    scene = running[0]
    scene.crowd.render_crowd = True
    path = str(tmp_path / "shot.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    run = subprocess.run([sys.executable, "-c", OPEN_FOR_A_COMMAND, path],
                         cwd=str(Path(__file__).resolve().parents[2]), capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split()[-2:] == ["0", "True"]


def test_a_failed_bake_is_reported_by_apply_plan_and_preview_without_a_traceback(running):
    """Apply Plan and Preview bake in one go: the bake's own error, no Python
    traceback, and nothing changed (Apply Plan puts the plan's settings back)."""
    scene, _rig, _walk, pv = running
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (4.0, -14.0, 9.0), (0.95, 0.0, 0.2)
    scene.camera = cam
    scene.crowd.plan_budget_mb, scene.crowd.plan_max_streams = 1.0, 4
    scene.crowd.max_offset = 3                          # the plan's M is another
    assert bpy.ops.crowd.plan_variety() == {"FINISHED"}
    assert pv.plan.planned.max_offset != 3
    before = settings_fingerprint(scene.crowd)
    scene.crowd.agent_sources[0].object.data.clear_geometry()       # no agents to place

    def fails(op):
        with pytest.raises(RuntimeError) as err:
            op()
        assert "mesh 'Seats' has no vertices" in str(err.value)
        return "Traceback" not in str(err.value)
    assert fails(bpy.ops.crowd.apply_plan)
    assert settings_fingerprint(scene.crowd) == before and preview.get(scene) is pv
    preview.stop(scene)
    assert fails(bpy.ops.crowd.preview_toggle) and preview.get(scene) is None
