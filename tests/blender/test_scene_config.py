"""Scene properties -> CrowdConfig (crowd_addon.blender.scene_config) and the bake
operator's error handling.

Oracles: Blender's own pose evaluation (``pose.bones[].matrix`` of the armature
playing the action) for action streams, and for every other node kind the core
controller tree written by hand on the same clips: the scene's tree must evaluate
to the same poses frame by frame.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview, scene_config  # noqa: E402
from crowd_addon.blender.operators import BakeJob  # noqa: E402
from crowd_addon.core import (Blend2, BlendSpace2D, ClipPlayer, Crowd, CrowdConfig, Layer,
                              StateMachine, StateTransition)
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.core.base.skinning import model_matrices  # noqa: E402


extension = cs.extension_fixture()


@pytest.fixture
def rig_scene():
    """Scene (24 fps, frames 1..48) with a rig, actions walk (markers), wave (arms
    only), idle; settings pointing at the rig."""
    preview.stop_all()
    scene = cs.reset()
    rig = cs.make_armature()
    acts = {"walk": cs.make_action(rig, "walk", seed=1, markers=[("step", 7)]),
            "wave": cs.make_action(rig, "wave", seed=2, bones=["arm.L", "arm.R"],
                                   amplitude=1.2),
            "idle": cs.make_action(rig, "idle", seed=3, frames=(1, 9, 17))}
    cs.add_character(scene.crowd, rig)
    scene.crowd.max_offset = 8
    return scene, rig, acts


def _blender_model(scene, rig, action, frame, skeleton):
    rig.animation_data.action = action
    scene.frame_set(int(np.floor(frame)), subframe=float(frame - np.floor(frame)))
    out = np.array([np.array(rig.pose.bones[n].matrix) for n in skeleton.bone_names])
    rig.animation_data.action = None
    return out


def test_action_streams_show_blenders_pose_at_each_frame(rig_scene):
    scene, rig, acts = rig_scene
    s = scene.crowd
    cs.add_stream(s, "walk", acts["walk"])
    fast = cs.add_stream(s, "fast", acts["walk"])
    fast.nodes[0].speed, fast.nodes[0].start = 2.0, 3.0
    cfg = scene_config.config_from_scene(scene)
    sk = cfg.skeletons["Rig"]
    crowd = Crowd(cfg)
    for frame in (1, 6, 13, 24, 31):
        crowd.advance_to(frame)
        got = model_matrices(np.stack([crowd.pose("walk"), crowd.pose("fast")]), sk)
        # walk loops with period 24 from its first frame 1; fast shows 3 + 2 (F - 1)
        for k, clip_t in enumerate((frame - 1, 3 + 2 * (frame - 1))):
            want = _blender_model(scene, rig, acts["walk"], 1 + clip_t % 24, sk)
            np.testing.assert_allclose(got[k], want, atol=2e-5, err_msg=f"frame {frame}")


def _same_poses(cfg, stream, root, frames, drive=lambda crowd, f: None):
    """The scene-built stream evaluates like the hand-built ``root`` on the same clips."""
    ref = CrowdConfig(max_offset=cfg.max_offset, fps=cfg.fps, start_frame=cfg.start_frame)
    ref.skeletons, ref.clips = cfg.skeletons, cfg.clips
    ref.add_stream(stream, "Rig", root)
    a, b = Crowd(cfg), Crowd(ref)
    for f in frames:
        for crowd in (a, b):
            drive(crowd, f)
            crowd.advance_to(f)
        np.testing.assert_allclose(a.pose(stream), b.pose(stream), atol=1e-6,
                                   err_msg=f"{stream} at frame {f}")
    return a, b


def clip(name, origin=1.0):
    return ClipPlayer(name, 1.0, -origin)


def test_blend_by_weight_and_by_parameter(rig_scene):
    scene, _rig, acts = rig_scene
    s = scene.crowd
    for name, props in (("fixed", {"weight": 0.3}), ("param", {"weight_parameter": "w"})):
        anim = cs.add_stream(s, name, acts["walk"])
        anim.nodes[0].name = "walk"
        cs.add_node(anim, "wave", "CLIP", action=acts["wave"])
        cs.add_node(anim, "mix", "BLEND2", ["walk", "wave"], **props)
        anim.root = "mix"
    cfg = scene_config.config_from_scene(scene)
    _same_poses(cfg, "fixed", Blend2(clip("walk"), clip("wave"), 0.3), range(1, 30, 4))

    def drive(crowd, f):
        crowd.set_parameter("param", "w", (f % 7) / 6)
    _same_poses(cfg, "param", Blend2(clip("walk"), clip("wave"), "w"), range(1, 30, 4),
                drive)


@pytest.mark.parametrize("mask", ["BONES", "COLLECTION"])
def test_override_layer_masked_by_bone_names_or_a_bone_collection(rig_scene, mask):
    scene, _rig, acts = rig_scene
    anim = cs.add_stream(scene.crowd, "layered", acts["walk"])
    anim.nodes[0].name = "walk"
    cs.add_node(anim, "wave", "CLIP", action=acts["wave"], speed=1.5)
    cs.add_node(anim, "top", "LAYER", ["walk", "wave"], weight=0.8, mask_source=mask,
                mask_bones="arm.L, arm.R", mask_collection="Arms")
    anim.root = "top"
    cfg = scene_config.config_from_scene(scene)
    want = Layer(clip("walk"), ClipPlayer("wave", 1.5, -1.5), "override",
                 {"arm.L": 1.0, "arm.R": 1.0}, 0.8)
    _same_poses(cfg, "layered", want, range(1, 40, 5))


def test_additive_layer_with_a_reference_pose(rig_scene):
    scene, _rig, acts = rig_scene
    anim = cs.add_stream(scene.crowd, "add", acts["walk"])
    anim.nodes[0].name = "walk"
    cs.add_node(anim, "idle", "CLIP", action=acts["idle"])
    cs.add_node(anim, "plus", "LAYER", ["walk", "idle"], layer_mode="ADDITIVE",
                reference_action=acts["idle"], reference_frame=4.0, weight=0.6)
    anim.root = "plus"
    cfg = scene_config.config_from_scene(scene)
    want = Layer(clip("walk"), clip("idle"), "additive", None, 0.6, ("idle", 4.0))
    _same_poses(cfg, "add", want, range(1, 40, 5))


def test_blend_space_places_inputs_at_their_points(rig_scene):
    scene, _rig, acts = rig_scene
    anim = cs.add_stream(scene.crowd, "space", acts["walk"])
    anim.nodes[0].name = "walk"
    cs.add_node(anim, "wave", "CLIP", action=acts["wave"])
    cs.add_node(anim, "idle", "CLIP", action=acts["idle"])
    bs = cs.add_node(anim, "bs", "BLEND_SPACE", ["walk", "wave", "idle"],
                     x_parameter="speed", y_parameter="mood")
    for inp, (x, y) in zip(bs.inputs, ((0, 0), (1, 0), (0, 2))):
        inp.x, inp.y = x, y
    anim.root = "bs"
    cfg = scene_config.config_from_scene(scene)
    want = BlendSpace2D([clip("walk"), clip("wave"), clip("idle")],
                        [(0, 0), (1, 0), (0, 2)], "speed", "mood")

    def drive(crowd, f):
        crowd.set_parameter("space", "speed", 0.1 * (f % 9))
        crowd.set_parameter("space", "mood", 0.3)
    _same_poses(cfg, "space", want, range(1, 30, 2), drive)


def test_state_machine_with_trigger_and_condition_transitions(rig_scene):
    scene, _rig, acts = rig_scene
    anim = cs.add_stream(scene.crowd, "fsm", acts["walk"])
    anim.nodes[0].name = "walk"
    cs.add_node(anim, "wave", "CLIP", action=acts["wave"])
    sm = cs.add_node(anim, "sm", "STATE_MACHINE", [("calm", "walk"), ("happy", "wave")],
                     initial_state="calm")
    t1 = sm.transitions.add()
    t1.source, t1.target, t1.duration, t1.trigger = "calm", "happy", 4.0, "hello"
    t2 = sm.transitions.add()
    t2.source, t2.target, t2.duration = "*", "calm", 2.0
    t2.condition_parameter, t2.condition_op, t2.condition_value = "energy", "<", 0.5
    anim.root = "sm"
    cfg = scene_config.config_from_scene(scene)
    want = StateMachine({"calm": ClipPlayer("walk"), "happy": ClipPlayer("wave")},
                        [StateTransition("calm", "happy", 4.0, trigger="hello"),
                         StateTransition("*", "calm", 2.0, condition=("energy", "<", 0.5))],
                        "calm")

    seen = []

    def drive(crowd, f):
        seen.append((f, crowd.state_of("fsm")[0]))
        crowd.set_parameter("fsm", "energy", 1.0 if f < 25 else 0.0)
        if f == 9:
            crowd.set_trigger("fsm", "hello")
    a, _ = _same_poses(cfg, "fsm", want, range(1, 40), drive)
    happy = sorted({f for f, state in seen if state == "happy"})
    assert happy == list(range(10, 26)) and a.state_of("fsm") == ["calm"]


def test_config_carries_settings_mesh_uniques_and_agents(rig_scene):
    scene, rig, acts = rig_scene
    s = scene.crowd
    s.max_offset, s.transition_slots, s.when_full, s.seed = 12, 5, "CUT", 7
    s.lod_near, s.lod_far = 10.0, 40.0
    s.characters[0].body = cs.make_proxy(rig)
    cs.add_stream(s, "walk", acts["walk"])
    cs.add_stream(s, "wave", acts["wave"], pool="uniques")
    src = s.agent_sources.add()
    src.name, src.object = "seats", cs.make_seats(5, 4)
    steps = []
    cfg = scene_config.config_from_scene(scene, progress=lambda *a: steps.append(a))
    assert (cfg.max_offset, cfg.transition_slots, cfg.when_full, cfg.seed) == (12, 5, "cut", 7)
    assert cfg.fps == 24.0 and cfg.start_frame == 1
    assert cfg.lod_distances == (10.0, 40.0, 90.0, 180.0)   # far cards on by default
    assert sorted(cfg.clips) == ["walk", "wave"]
    assert cfg.clips["walk"].events == (("step", 6.0),)       # marker at frame 7, clip 1..25
    assert [d.name for d in cfg.streams] == ["walk"] and [d.name for d in cfg.uniques] == ["wave"]
    assert list(cfg.meshes) == ["Rig"] and cfg.meshes["Rig"][0].positions.shape == (40, 3)
    assert cfg.meshes["Rig"][-1].name.endswith(".joined.card") and len(cfg.meshes["Rig"]) == 5
    assert cfg.agent_count == 20 and (cfg.agent_offset < 12).all()
    assert [a[:2] for a in steps] == [(0, 4), (1, 4), (2, 4), (3, 4)]
    # a unique's clip time starts at 0 when it starts, not at the scene start
    assert cfg.uniques[0].root.start == 0.0 and cfg.streams[0].root.start == -1.0
    Crowd(cfg)


def test_timing_variation_makes_speed_streams_that_play_as_blender_does(rig_scene):
    """A stream with a speed range becomes speed streams (and copies): the oracle for
    each is Blender's own pose of the action at the frame that speed reaches from the
    scene's start frame (copy c another c x speed x M frames in); every agent plays a
    variant of its template."""
    scene, rig, acts = rig_scene
    s = scene.crowd
    walk = cs.add_stream(s, "walk", acts["walk"])
    # speeds 1 and 2 (the centres of two halves of 0.5 .. 2.5): whole clip frames, where
    # the baked keys are Blender's own values
    walk.speed_min, walk.speed_max, walk.speed_streams, walk.copies = 0.5, 2.5, 2, 2
    cs.add_stream(s, "idle", acts["idle"])
    s.characters[0].body = cs.make_proxy(rig)
    src = s.agent_sources.add()
    src.name, src.object = "seats", cs.make_seats(10, 10)
    cfg = scene_config.config_from_scene(scene)
    assert [(d.name, round(d.speed, 6)) for d in cfg.streams] == [
        ("walk", 1.0), ("walk 1x #2", 1.0), ("walk 2x", 2.0), ("walk 2x #2", 2.0),
        ("idle", 1.0)]
    assert [d.template_name for d in cfg.streams] == ["walk"] * 4 + ["idle"]
    assert set(cfg.agent_stream.tolist()) == set(range(5))
    from crowd_addon.blender import panels
    assert panels.timing_line(walk) == "Makes 4 streams at 1x .. 2x in 2 copies"
    sk = cfg.skeletons["Rig"]
    crowd = Crowd(cfg)
    m = s.max_offset
    for frame in (1, 7, 20):
        crowd.advance_to(frame)
        got = model_matrices(np.stack([crowd.pose(d.name) for d in cfg.streams[:4]]), sk)
        for k, (v, c) in enumerate([(1, 0), (1, 1), (2, 0), (2, 1)]):
            clip_t = v * (frame - 1) + c * v * m            # walk loops every 24 frames
            want = _blender_model(scene, rig, acts["walk"], 1 + clip_t % 24, sk)
            np.testing.assert_allclose(got[k], want, atol=2e-5,
                                       err_msg=f"{cfg.streams[k].name} at frame {frame}")
    walk.speed_streams = 3
    walk.speed_min = walk.speed_max = 1.0
    with pytest.raises(CrowdError, match="stream 'walk': 3 speed streams need a speed range"):
        scene_config.config_from_scene(scene)


@pytest.mark.parametrize("setup, message", [
    (lambda s, a: setattr(s.characters[0], "armature", None),
     r"^character 'Rig': no armature chosen"),
    (lambda s, a: s.characters.clear(), r"scene '.*': no characters"),
    (lambda s, a: cs.add_stream(s, "walk", None), r"stream 'walk': node 'clip': no action"),
    (lambda s, a: _root(cs.add_stream(s, "w", a["walk"]), "l", cs.add_node, "LAYER",
                        ["clip", "clip"], mask_source="COLLECTION", mask_collection="Legs"),
     r"armature 'Rig' has no bone collection 'Legs'"),
    (lambda s, a: (cs.add_stream(s, "w", a["walk"]), cs.add_stream(s, "w", a["idle"])),
     r"stream names must be unique and not empty \('w'\)"),
    (lambda s, a: (cs.add_stream(s, "w", a["walk"]), setattr(s, "lod_far", 20.0)),
     r"Crowd settings: LOD 2 From \(20 m\) must be farther than LOD 1 From \(30 m\)"),
    (lambda s, a: (cs.add_stream(s, "w", a["walk"]), setattr(s, "lod_card", 60.0)),
     r"Crowd settings: Cards From \(60 m\) must be farther than LOD 2 From \(60 m\)"),
    (lambda s, a: (cs.add_stream(s, "w", a["walk"]), setattr(s, "lod_joined", 80.0)),
     r"Crowd settings: Joined Boxes From \(80 m\) must be farther than Cards From \(90 m\)"),
])
def test_bad_scenes_name_what_is_at_fault(rig_scene, setup, message):
    """Scene-level faults; the graph's own (unknown inputs, input counts, cycles, masks
    of unknown bones, state names) are tested in tests/core/test_controller_graph.py."""
    scene, _rig, acts = rig_scene
    setup(scene.crowd, acts)
    with pytest.raises(CrowdError, match=message):
        scene_config.config_from_scene(scene)


def test_far_cards_can_be_turned_off(rig_scene):
    scene, rig, acts = rig_scene
    s = scene.crowd
    s.characters[0].body = cs.make_proxy(rig)
    cs.add_stream(s, "walk", acts["walk"])
    s.lod_cards, s.lod_card, s.lod_joined = False, 10.0, 5.0    # ignored when off
    cfg = scene_config.config_from_scene(scene)
    assert cfg.lod_distances == (30.0, 60.0) and len(cfg.meshes["Rig"]) == 3
    assert not any(lv.name.endswith(".card") for lv in cfg.meshes["Rig"])


def _root(anim, name, add, kind, inputs, **props):
    add(anim, name, kind, inputs, **props)
    anim.root = name
    return anim


def test_samples_per_frame_setting_keys_the_clips_between_frames(rig_scene):
    """Settings > Samples per Frame 4: the clips keep 4 keys per scene frame and play
    at the same speed, so a stream at half speed shows Blender's pose at half frames
    (1 sample per frame interpolates there)."""
    scene, rig, acts = rig_scene
    s = scene.crowd
    assert s.samples_per_frame == 1
    cs.add_stream(s, "walk", acts["walk"])
    cs.add_stream(s, "slow", acts["walk"]).nodes[0].speed = 0.5
    misses = {}
    for samples in (1, 4):
        s.samples_per_frame = samples
        cfg = scene_config.config_from_scene(scene)
        sk = cfg.skeletons["Rig"]
        assert cfg.fps == 24 and cfg.clips["walk"].fps == 24 * samples
        crowd = Crowd(cfg)
        misses[samples] = 0.0
        for frame in (2, 7, 12, 29, 40):
            crowd.advance_to(frame)
            got = model_matrices(np.stack([crowd.pose("walk"), crowd.pose("slow")]), sk)
            for k, clip_t in enumerate((frame - 1, (frame - 1) / 2)):
                want = _blender_model(scene, rig, acts["walk"], 1 + clip_t % 24, sk)
                miss = np.abs(got[k] - want).max()
                if k == 0:
                    assert miss < 2e-5, f"frame {frame}"        # whole frames: keys
                misses[samples] = max(misses[samples], miss)
    assert misses[4] < 2e-5 < 1e-3 < misses[1], misses


def test_the_bake_reports_keys_too_far_apart(rig_scene):
    """An Euler curve wrapping from 179 to -179 degrees between two frames: the bake
    reports it (a warning of the operator) with its frames and size and what the most
    samples per frame leave (a 358-degree Bezier turn in one frame is still 0.017 rad
    off between keys 16 a frame apart); with those the long way round is gone."""
    scene, rig, _acts = rig_scene
    pb = rig.pose.bones["head"]
    pb.rotation_mode = "XYZ"
    spin = bpy.data.actions.new("spin")
    rig.animation_data_create()
    rig.animation_data.action = spin
    for frame, degrees in ((1, 0), (5, 179), (6, -179), (9, -90)):
        pb.rotation_euler = (0, 0, np.radians(degrees))
        pb.keyframe_insert("rotation_euler", index=2, frame=frame)
    rig.animation_data.action = None
    cs.add_stream(scene.crowd, "spin", spin)
    timer = type("Event", (), {"type": "TIMER"})()
    op = cs.FakeBakeOperator(scene)
    while op.modal(bpy.context, timer) == {"RUNNING_MODAL"}:
        pass
    warnings = [m for kind, m in op.reports if kind == {"WARNING"}]
    assert len(warnings) == 1 and op.reports[-1][0] == {"INFO"}
    assert warnings[0].startswith("action 'spin': between frames the crowd's pose misses "
                                  "the action's: halfway between the keys at frames 5 and 6 "
                                  "bone 'head' is turned 3.14 rad off (the long way round")
    assert "16 samples per frame still miss by" in warnings[0]
    assert op._job.notes == warnings
    scene.crowd.samples_per_frame = 16
    job = BakeJob(scene)
    while job.step():
        pass
    note, = job.notes
    worst = float(note.split("is turned ")[1].split()[0])
    assert 1e-3 < worst < 0.05 and "long way" not in note, note


def test_bake_operator_reports_bad_actions_and_keeps_the_running_crowd(rig_scene):
    scene, rig, acts = rig_scene
    s = scene.crowd
    cs.add_stream(s, "walk", acts["walk"])
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    running = preview.get(scene).crowd
    # an action for bones the armature lacks, then an empty action
    alien = bpy.data.actions.new("alien")
    other = cs.make_armature("Other")
    with bpy.context.temp_override(active_object=other):
        other.data.bones["arm.L"].name = "wing"
    bad = cs.make_action(other, "flap", bones=["wing"])
    for action, message in ((bad, r"action 'flap' animates bones .* lacks: \['wing'\]"),
                            (alien, r"action 'alien'")):
        s.characters[0].streams[0].nodes[0].action = action
        with pytest.raises(RuntimeError, match=message):
            bpy.ops.crowd.bake()
        assert preview.get(scene).crowd is running
    assert rig.animation_data.action is None


def test_a_cancelled_bake_changes_nothing(rig_scene):
    scene, _rig, acts = rig_scene
    cs.add_stream(scene.crowd, "walk", acts["walk"])
    cs.add_stream(scene.crowd, "idle", acts["idle"])
    job = BakeJob(scene)
    assert job.step() and job.message == "baking action 'walk'"
    assert job.step() and job.message == "baking action 'idle'"
    job.cancel()
    assert job.config is None and preview.get(scene) is None
    job = BakeJob(scene)
    while job.step():
        pass
    assert sorted(job.config.clips) == ["idle", "walk"]




def test_the_modal_bake_steps_on_timer_events_and_cancels_on_esc(rig_scene):
    scene, _rig, acts = rig_scene
    cs.add_stream(scene.crowd, "walk", acts["walk"])
    cs.add_stream(scene.crowd, "idle", acts["idle"])
    timer, esc, mouse = (type("Event", (), {"type": t})() for t in ("TIMER", "ESC", "MOUSEMOVE"))
    op = cs.FakeBakeOperator(scene)
    assert op.modal(bpy.context, mouse) == {"PASS_THROUGH"}
    assert op.modal(bpy.context, timer) == {"RUNNING_MODAL"}
    assert op.modal(bpy.context, esc) == {"CANCELLED"}
    assert preview.get(scene) is None and "cancelled" in op.reports[-1][1]
    op = cs.FakeBakeOperator(scene)
    results = [op.modal(bpy.context, timer) for _ in range(5)]
    assert results == [{"RUNNING_MODAL"}] * 4 + [{"FINISHED"}]
    assert preview.get(scene).crowd.streams.count == 2 and "2 clips" in op.reports[-1][1]
    scene.crowd.characters[0].streams[1].nodes[0].action = None
    op = cs.FakeBakeOperator(scene)
    assert op.modal(bpy.context, timer) == {"CANCELLED"}
    assert op.reports[-1] == ({"ERROR"}, "stream 'idle': node 'clip': no action chosen")


def test_palettes_and_scales_from_the_scene(rig_scene):
    """A palette on the body's "shirt" material (two colours by an INT point attribute
    "team") and a scale range on the source: the bake gives every agent its team's
    colour on that column and a scale in range, the same on every bake (seeded), and a
    palette for a material the body does not have is named."""
    scene, rig, acts = rig_scene
    s = scene.crowd
    body = cs.make_proxy(rig)
    for name in ("shirt", "skin"):
        body.data.materials.append(bpy.data.materials.new(name))
    s.characters[0].body = body
    cs.add_stream(s, "walk", acts["walk"])
    seats = cs.make_seats(6, 5)
    team = (np.arange(30) // 15).astype(np.int32)
    seats.data.attributes.new("team", "INT", "POINT").data.foreach_set("value", team)
    src = s.agent_sources.add()
    src.name, src.object = "seats", seats
    src.scale_min, src.scale_max = 0.9, 1.3
    pal = s.characters[0].palettes.add()
    pal.material, pal.mode, pal.attribute, pal.count = "shirt", "ATTRIBUTE", "team", 2
    pal.color_0, pal.color_1 = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    cfg = scene_config.config_from_scene(scene)
    assert cfg.palette_materials == {"Rig": ("shirt",)}
    np.testing.assert_allclose(cfg.palette[:, 0], np.where(team[:, None] == 0,
                                                           (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)))
    assert (cfg.palette[:, 1:] == -1).all()
    assert 0.9 <= cfg.scales.min() < cfg.scales.max() <= 1.3
    again = scene_config.config_from_scene(scene)
    np.testing.assert_array_equal(again.scales, cfg.scales)
    crowd = Crowd(cfg)
    np.testing.assert_array_equal(crowd.agents.palette, cfg.palette)
    pal.mode = "RANDOM"                                   # seeded: both colours, stable
    rnd = scene_config.config_from_scene(scene).palette[:, 0]
    np.testing.assert_array_equal(rnd, scene_config.config_from_scene(scene).palette[:, 0])
    assert len({tuple(c) for c in rnd.tolist()}) == 2
    pal.material = "hat"
    with pytest.raises(CrowdError, match="palette material 'hat' is not a material of its "
                                         r"body, mesh variants or props \(their materials: "
                                         r"\['shirt', 'skin'\]\)"):
        scene_config.config_from_scene(scene)
