"""Baked clips against Blender's own pose evaluation (``pose.bones[].matrix``).

Tolerance: 2e-6 per matrix element on rigs of about a metre (both sides are float32).

Fractional frames: core samples a clip by lerp/nlerp between its integer keys, while
Blender evaluates the F-curves exactly at a subframe, so the two differ between keys
by the curvature of the motion (up to 0.24 on this rig at half frames). Fractional
Blender frames are therefore compared where the clip has keys: baking at 4x the scene
fps (or 4 samples per frame) puts keys at quarter frames, and a 30 fps crowd over a
24 fps scene puts keys every 0.8 frames.
Comparisons go through ``ClipBank`` sampling and core's ``model_matrices``.
"""

import numpy as np
import pytest

from crowd_addon.blender.bake import bake_actions
from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig
from crowd_addon.core.anim.clip import ClipBank
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.base.skinning import model_matrices

TOL = 2e-6


def core_pose(result, clip_index, clip_times):
    """Model matrices (n, B, 4, 4) of a baked clip sampled by the clip bank."""
    bank = ClipBank(result.clips)
    t = np.asarray(clip_times, np.float64)
    local = bank.sample(np.full(t.size, clip_index), t)
    return model_matrices(local, result.skeleton)


def assert_matches_blender(blend, scene, obj, result, clip_index, blender_frames, start, step):
    names = result.skeleton.bone_names
    want = np.stack([blend.pose_at(scene, obj, names, f) for f in blender_frames])
    got = core_pose(result, clip_index, (np.asarray(blender_frames) - start) / step)
    err = np.abs(got - want).max()
    assert err < TOL, f"max error {err}"


def worst_misses(note) -> tuple:
    """``(scene units, rad)`` of a between-frames note's largest misses (0 where under
    the tolerance, so not named)."""
    units = note.split(" scene units off")[0].rsplit(" ", 1)[1] if "head is" in note else 0
    rad = note.split(" rad off")[0].rsplit(" ", 1)[1] if "is turned" in note else 0
    return float(units), float(rad)


def test_integer_frames_match_blender(scene, blend):
    obj = blend.build_rig(scene, location=(1, 2, 3), rotation=(0.3, 0.2, 0.1))
    blend.rig_action(obj)
    action = obj.animation_data.action
    result = bake_actions(obj, [action], fps=scene.render.fps)
    assert result.methods == {"Wave": "fcurves"}
    # this rig turns fast: the report warns that its in-between poses miss, with sizes
    note, = result.notes
    assert note.kind == "between_frames" and note.severity == "warning"
    assert note.startswith("action 'Wave': between frames the crowd's pose misses the "
                           "action's: halfway between the keys at frames ")
    two, = bake_actions(obj, [action], fps=scene.render.fps, samples_per_frame=2).notes
    assert worst_misses(two) < worst_misses(note)     # closer keys miss less
    clip = result.clips[0]
    assert clip.frame_count == 20 and clip.fps == scene.render.fps
    assert result.skeleton.bone_names[0] == "root"
    assert_matches_blender(blend, scene, obj, result, 0, np.arange(1, 21), 1.0, 1.0)


def test_subframes_match_blender_at_4x_fps(scene, blend):
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    result = bake_actions(obj, [action], fps=scene.render.fps * 4)
    assert result.clips[0].frame_count == 77
    frames = [1.25, 2.5, 4.75, 8.0, 9.25, 13.5, 19.75]
    assert_matches_blender(blend, scene, obj, result, 0, frames, 1.0, 0.25)


def test_crowd_fps_differs_from_scene_fps(scene, blend):
    scene.render.fps = 24
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj, frames=(1, 5, 9, 14, 21))
    result = bake_actions(obj, [action], fps=30)
    clip = result.clips[0]
    assert clip.frame_count == 26 and clip.fps == 30      # 20 frames at 24 fps = 25 steps
    keys = np.arange(26)
    assert_matches_blender(blend, scene, obj, result, 0, 1 + keys * 0.8, 1.0, 0.8)


def test_samples_per_frame_follow_blender_between_crowd_frames(scene, blend):
    """4 keys per crowd frame: the clip plays at the crowd's speed (its fps is 4x, and a
    crowd plays a clip at its own rate) and its half-frame poses are Blender's, in a
    crowd at speed 0.5 too; 1 key per frame interpolates there and misses."""
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    fps = scene.render.fps
    one = bake_actions(obj, [action], fps=fps)
    four = bake_actions(obj, [action], fps=fps, samples_per_frame=4)
    assert worst_misses(four.notes[0]) < worst_misses(one.notes[0])
    assert four.clips[0].fps == 4 * fps and four.clips[0].frame_count == 77
    assert one.clips[0].fps == fps and one.clips[0].frame_count == 20
    names = four.skeleton.bone_names
    frames = np.arange(1.5, 20, 1.0)                          # half crowd frames
    want = np.stack([blend.pose_at(scene, obj, names, f) for f in frames])

    def clip_pose(result, t):
        """Model matrices of the clip at crowd time ``t`` (frames since its start)."""
        bank = ClipBank(result.clips, fps=fps)
        local = bank.sample(np.zeros(t.size, np.int64), bank.rate[0] * t)
        return model_matrices(local, result.skeleton)

    err4 = np.abs(clip_pose(four, frames - 1) - want).max()
    err1 = np.abs(clip_pose(one, frames - 1) - want).max()
    assert err4 < TOL and err1 > 0.05, (err4, err1)
    # the same through a crowd playing the clip at half speed: frame f shows 1 + f / 2
    for result, ok in ((four, True), (one, False)):
        cfg = CrowdConfig(max_offset=1, transition_slots=0, fps=fps)
        cfg.add_skeleton(result.skeleton)
        cfg.add_clip(result.clips[0])
        cfg.add_stream("half", result.skeleton.name, ClipPlayer("Wave", speed=0.5))
        cfg.add_agents(1)
        crowd = Crowd(cfg)
        worst = 0.0
        for f in range(1, 38):
            crowd.advance_to(f)
            got = model_matrices(crowd.pose("half")[None], result.skeleton)[0]
            worst = max(worst, np.abs(got - blend.pose_at(scene, obj, names, 1 + f / 2)).max())
        assert (worst < TOL) == ok, worst


def test_euler_curve_wrapping_between_keys_is_reported(scene, blend):
    """An Euler curve keyed 179 then -179 degrees on consecutive frames turns the bone a
    full turn in Blender; one key a frame interpolates the short way (a half turn off
    halfway). The report names the action, bone and frames and 2 samples per frame,
    which follow it."""
    obj = blend.build_rig(scene)
    action, slot, bag = blend.new_action("Spin")
    obj.pose.bones["arm.L"].rotation_mode = "XYZ"
    blend.add_curve(bag, 'pose.bones["arm.L"].rotation_euler', 2, np.array([1.0, 5, 6, 9]),
                    np.radians([0.0, 179, -179, -90]), "LINEAR")
    blend.play(obj, action, slot)
    one = bake_actions(obj, [action], fps=scene.render.fps)
    note, = one.notes
    assert note.startswith("action 'Spin': between frames the crowd's pose misses the "
                           "action's: halfway between the keys at frames 5 and 6 bone ")
    assert ("halfway between the keys at frames 5 and 6 bone 'arm.L' is turned 3.14 rad off "
            "(the long way round") in note
    assert note.endswith("; bake with 2 samples per frame (Crowd > Settings > Samples per "
                         "Frame) to follow it")
    two = bake_actions(obj, [action], fps=scene.render.fps, samples_per_frame=2)
    assert two.notes == ()
    names = one.skeleton.bone_names
    want = blend.pose_at(scene, obj, names, 5.5)
    arm = names.index("arm.L")
    assert np.abs(core_pose(one, 0, [4.5])[0, arm] - want[arm]).max() > 1.0
    np.testing.assert_allclose(core_pose(two, 0, [9.0])[0], want, atol=TOL)


@pytest.mark.parametrize("samples", [0, 17, 2.0, True])
def test_samples_per_frame_must_be_1_to_16(scene, blend, samples):
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    with pytest.raises(CrowdError, match=r"bake samples per frame must be a whole number in "
                                         r"1\.\.16, got"):
        bake_actions(obj, [action], fps=24, samples_per_frame=samples)


def test_frame_set_path_gives_the_same_clip(scene, blend):
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    fast = bake_actions(obj, [action], fps=48)
    slow = bake_actions(obj, [action], fps=48, method="frame_set")
    assert slow.methods == {"Wave": "frame_set"}
    t = np.linspace(0, 38, 77)
    np.testing.assert_allclose(core_pose(fast, 0, t), core_pose(slow, 0, t), atol=TOL)


def test_extrapolation_cycles_and_easing(scene, blend):
    """A manual frame range past the keys (linear and constant extrapolation), a
    Cycles modifier cycling beyond the keys, an easing curve and a noise modifier
    (both left to FCurve.evaluate) all still match Blender."""
    obj = blend.build_rig(scene)
    action, _, bag = blend.rig_action(obj)
    bag.fcurves.find('pose.bones["root"].location', index=0).extrapolation = "LINEAR"
    bag.fcurves.find('pose.bones["arm.L"].rotation_euler', index=2).extrapolation = "LINEAR"
    fc = bag.fcurves.find('pose.bones["spine"].rotation_quaternion', index=1)
    fc.modifiers.new("CYCLES")
    fc = bag.fcurves.find('pose.bones["hand.L"].rotation_quaternion', index=2)
    for k in fc.keyframe_points:
        k.interpolation = "ELASTIC"
    bag.fcurves.find('pose.bones["leg"].scale', index=1).modifiers.new("NOISE")
    action.use_frame_range = True
    action.frame_start, action.frame_end = -3, 27
    result = bake_actions(obj, [action], fps=scene.render.fps)
    assert result.methods == {"Wave": "fcurves"}
    assert_matches_blender(blend, scene, obj, result, 0, np.arange(-3, 28, 3), -3.0, 1.0)


def test_constraints_fall_back_to_frame_set_and_restore_the_scene(scene, blend):
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    target = blend.bpy.data.objects.new("Target", None)
    scene.collection.objects.link(target)
    target.location = (0.5, 1.0, 2.0)
    con = obj.pose.bones["hand.L"].constraints.new("DAMPED_TRACK")
    con.target = target
    scene.frame_set(7)
    obj.pose.bones["arm.L"].rotation_euler = (0.1, 0.2, 0.3)     # keyed: the action's at 7
    before = blend.pose_at(scene, obj, [b.name for b in obj.pose.bones], 7)
    result = bake_actions(obj, [action], fps=scene.render.fps)
    assert result.methods == {"Wave": "frame_set"}
    assert "constraints" in result.notes[0] and "hand.L" in result.notes[0]
    assert scene.frame_current == 7 and obj.animation_data.action == action
    after = np.array([np.array(pb.matrix) for pb in obj.pose.bones])
    np.testing.assert_allclose(after, before, atol=1e-6)
    assert_matches_blender(blend, scene, obj, result, 0, np.arange(1, 21, 2), 1.0, 1.0)


def test_a_frame_set_bake_keeps_a_pose_the_user_has_not_keyed_yet(scene, blend):
    """The animator posed keyed bones at frame 7 without keying them yet; the bake
    samples with frame_set (a constraint). Before: going back to frame 7 played the
    action over the restored pose, and the posing was lost (as a failed bake did too);
    the fast path already kept it."""
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    obj.pose.bones["hand.L"].constraints.new("LIMIT_ROTATION")
    scene.frame_set(7)
    posed = {"root": ("rotation_quaternion", (0.9, 0.1, 0.2, 0.3)),
             "arm.L": ("rotation_euler", (0.1, 0.2, 0.3)),
             "spine": ("location", (0.05, -0.02, 0.01))}
    for bone, (prop, value) in posed.items():
        setattr(obj.pose.bones[bone], prop, value)

    def kept():
        for bone, (prop, value) in posed.items():
            np.testing.assert_allclose(tuple(getattr(obj.pose.bones[bone], prop)), value,
                                       atol=1e-6, err_msg=f"{bone} {prop}")
    result = bake_actions(obj, [action], fps=scene.render.fps)
    assert result.methods == {"Wave": "frame_set"}
    kept()
    assert scene.frame_current == 7 and obj.animation_data.action == action
    before = np.array([np.array(pb.matrix) for pb in obj.pose.bones])
    blend.bpy.context.view_layer.update()                 # what Blender shows: the posing
    np.testing.assert_allclose([np.array(pb.matrix) for pb in obj.pose.bones], before,
                               atol=1e-6)


def test_unkeyed_channels_keep_the_current_pose(scene, blend):
    obj = blend.build_rig(scene)
    action, slot, bag = blend.new_action("Partial")
    blend.add_curve(bag, 'pose.bones["spine"].rotation_quaternion', 1, np.array([1.0, 10.0]),
                    np.array([0.0, 0.6]))
    blend.play(obj, action, slot)
    obj.pose.bones["leg"].location = (0.2, -0.1, 0.05)
    obj.pose.bones["foot"].scale = (1.0, 2.0, 0.5)
    result = bake_actions(obj, [action], fps=scene.render.fps)
    assert_matches_blender(blend, scene, obj, result, 0, [1, 4, 10], 1.0, 1.0)


def test_markers_become_events_and_loop_flag(scene, blend):
    scene.render.fps = 24
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    action.pose_markers.new("step").frame = 9
    action.pose_markers.new("clap").frame = 1
    plain = bake_actions(obj, [action], fps=48).clips[0]
    assert plain.events == (("clap", 0.0), ("step", 16.0)) and not plain.loop
    assert bake_actions(obj, [action], fps=24, loop=True).clips[0].loop
    assert bake_actions(obj, [action], fps=24, loop={"Wave": True}).clips[0].loop
    action.use_frame_range = True
    action.frame_start, action.frame_end, action.use_cyclic = 1, 20, True
    assert bake_actions(obj, [action], fps=24).clips[0].loop


def test_cycles_modifiers_make_a_loop(scene, blend):
    obj = blend.build_rig(scene)
    action, _, bag = blend.rig_action(obj)
    for fc in bag.fcurves:
        fc.modifiers.new("CYCLES")
    assert bake_actions(obj, [action], fps=scene.render.fps).clips[0].loop


def test_loop_not_a_whole_number_of_frames_is_resampled(scene, blend):
    scene.render.fps = 24
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj, frames=(1, 5, 9, 14, 20))     # 19 frames at 24
    result = bake_actions(obj, [action], fps=30, loop=True)              # 23.75 steps
    clip = result.clips[0]
    assert clip.frame_count == 25 and "resampled" in result.notes[0]
    np.testing.assert_allclose(core_pose(result, 0, [0.0]), core_pose(result, 0, [24.0]),
                               atol=TOL)
    clamped = bake_actions(obj, [action], fps=30, loop=False)
    assert clamped.clips[0].frame_count == 25 and "after the end" in clamped.notes[0]


def test_slot_selection(scene, blend):
    """A two-slot action: the armature's assigned slot is baked by default, another
    slot by identifier, and without an assignment the choice must be explicit. On
    Blender 4.2-4.3 (no slots) asking for a slot is the error."""
    from crowd_addon.blender.compat import SLOTTED_ACTIONS
    obj = blend.build_rig(scene)
    action, slot_a, bag_a = blend.new_action("Two")
    if not SLOTTED_ACTIONS:
        blend.add_curve(bag_a, 'pose.bones["leg"].location', 2, np.array([1.0, 10.0]),
                        np.array([0.0, 1.0]))
        with pytest.raises(CrowdError, match=r"action 'Two' has no slots \(legacy action\); "
                                             "cannot pick slot 'OBNope'"):
            bake_actions(obj, [(action, "OBNope")], fps=24)
        return
    slot_b = action.slots.new("OBJECT", "Other")
    bag_b = action.layers[0].strips[0].channelbag(slot_b, ensure=True)
    frames = np.array([1.0, 10.0])
    blend.add_curve(bag_a, 'pose.bones["leg"].location', 2, frames, np.array([0.0, 1.0]))
    blend.add_curve(bag_b, 'pose.bones["leg"].location', 2, frames, np.array([0.0, -1.0]))
    blend.play(obj, action, slot_b)
    got_b = bake_actions(obj, [action], fps=24).clips[0].keys
    got_a = bake_actions(obj, [(action, slot_a.identifier)], fps=24).clips[0].keys
    assert got_b[-1, 4, 7:].sum() < 0 < got_a[-1, 4, 7:].sum()
    obj.animation_data.action = None
    with pytest.raises(CrowdError, match="several object slots"):
        bake_actions(obj, [action], fps=24)
    with pytest.raises(CrowdError, match="no slot 'OBNope'"):
        bake_actions(obj, [(action, "OBNope")], fps=24)


@pytest.mark.parametrize("case, message", [
    ("missing_bone", r"action 'Bad' animates bones that armature 'Rig' lacks: \['ghost'\]"),
    ("empty", r"action 'Bad' is empty"),
    ("one_frame", r"action 'Bad' is one frame long"),
    ("nan", r"action 'Bad', bone 'leg', location\[1\]: key 1 is not finite"),
    ("marker", r"pose marker 'late' at frame 40 is outside"),
])
def test_bad_actions_name_the_fault_and_bake_nothing(scene, blend, case, message):
    obj = blend.build_rig(scene)
    good, _, _ = blend.rig_action(obj, name="Good")
    action, slot, bag = blend.new_action("Bad")
    frames = np.array([1.0, 5.0, 9.0])
    if case == "missing_bone":
        blend.add_curve(bag, 'pose.bones["ghost"].location', 0, frames, np.zeros(3))
    elif case == "one_frame":
        blend.add_curve(bag, 'pose.bones["leg"].location', 0, frames[:1], np.zeros(1))
    elif case == "nan":
        blend.add_curve(bag, 'pose.bones["leg"].location', 1, frames, np.array([0, np.nan, 1]),
                        "LINEAR")
    elif case == "marker":
        blend.add_curve(bag, 'pose.bones["leg"].location', 0, frames, np.zeros(3))
        action.pose_markers.new("late").frame = 40
    calls = []
    with pytest.raises(CrowdError, match=message):
        bake_actions(obj, [good, (action, slot)], fps=24, progress=lambda *a: calls.append(a))
    assert calls == []                      # validated before anything was baked


@pytest.mark.parametrize("method", ["auto", "frame_set"])
def test_cancel_returns_nothing_and_changes_nothing(scene, blend, method):
    obj = blend.build_rig(scene)
    first, slot, _ = blend.rig_action(obj, name="First")
    second, _, _ = blend.rig_action(obj, name="Second", seed=1)
    blend.play(obj, first, slot)
    scene.frame_set(3)
    pose = np.array([np.array(pb.matrix_basis) for pb in obj.pose.bones])
    seen = []

    def progress(done, total):
        seen.append((done, total))
        return done < 25

    assert bake_actions(obj, [first, second], fps=24, progress=progress, method=method) is None
    assert seen[-1][0] >= 20 and all(t == 40 for _, t in seen)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)
    assert scene.frame_current == 3 and obj.animation_data.action == first
    np.testing.assert_allclose([np.array(pb.matrix_basis) for pb in obj.pose.bones], pose)
    done = []
    assert bake_actions(obj, [first, second], fps=24, progress=lambda d, t: done.append(d))
    assert done[-1] == 40


def test_deleted_objects_and_non_actions_are_named(scene, blend):
    bpy = blend.bpy
    obj = blend.build_rig(scene)
    action, _, _ = blend.rig_action(obj)
    with pytest.raises(CrowdError, match="not an action"):
        bake_actions(obj, [obj], fps=24)
    gone = bpy.data.actions.new("Gone")
    bpy.data.actions.remove(gone)
    with pytest.raises(CrowdError, match="no longer exists"):
        bake_actions(obj, [action, gone], fps=24)
    bpy.data.objects.remove(obj)
    with pytest.raises(CrowdError, match="armature no longer exists"):
        bake_actions(obj, [action], fps=24)
