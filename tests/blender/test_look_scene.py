"""Look-at authored in the .blend (issue 34, item 2): a character's look rig, a look
target object sampled per frame when the crowd is built, a Look At cue.

Oracles: the target object's keyframes (linear, so its position at every frame is known
by hand) and Blender's own ``matrix_world`` after ``frame_set``; the heads' directions
measured from the skinning rows the crowd draws with (``Crowd.agent_rows``) with plain
vector maths, as tests/core/test_look_at.py does.
"""

import math
import os
import sys
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import scene_config  # noqa: E402
from crowd_addon.blender.show_data import object_positions  # noqa: E402
from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.core.runtime.look_at import LookChain, head_direction  # noqa: E402

extension = cs.extension_fixture()

#: the ball's keys (frame, x, y, z), linear: it runs along the front of the seats
KEYS = ((1, -8.0, -12.0, 1.5), (20, 6.0, -14.0, 3.0), (48, -2.0, -10.0, 0.5))


def ball_at(frames):
    """(n, 3) the ball where its linear keys put it."""
    f, x, y, z = np.array(KEYS, float).T
    frames = np.asarray(frames, float)
    return np.stack([np.interp(frames, f, x), np.interp(frames, f, y),
                     np.interp(frames, f, z)], 1)


def build(smoothing=0.0, lag="SEEDED", max_lag=0):
    """A kid rig (neck, head) with a head-moving idle, 12 agents facing -Y, a "Ball"
    keyed linearly in front of them, look target "ball" and a Look At cue at frame 4."""
    scene = cs.reset()
    rig = cs.make_armature("Kid", cs.KID_BONES)
    idle = cs.make_action(rig, "idle", seed=2, amplitude=0.35)
    s = scene.crowd
    s.max_offset, s.seed = 6, 1
    kid = cs.add_character(s, rig, cs.make_proxy(rig))
    cs.add_stream(kid, "idle", idle)
    kid.look_bones, kid.look_shares = "neck, head", "0.4, 0.6"
    kid.look_yaw_limit, kid.look_pitch_limit = math.radians(80), math.radians(45)
    src = s.agent_sources.add()
    src.name, src.object = "seats", cs.make_seats(4, 3, spacing=1.5)
    src.heading_mode, src.heading = "FIXED", 0.0
    me = bpy.data.meshes.new("Ball")
    ball = bpy.data.objects.new("Ball", me)
    scene.collection.objects.link(ball)
    for f, x, y, z in KEYS:
        ball.location = (x, y, z)
        ball.keyframe_insert("location", frame=f)
    for fc in cs_fcurves(ball):
        for k in fc.keyframe_points:
            k.interpolation = "LINEAR"
    t = s.show.look_targets.add()
    t.name, t.object, t.smoothing = "ball", ball, smoothing
    s.show.look_lag, s.show.look_max_lag = lag, max_lag
    c = s.show.cues.add()
    c.name, c.frame, c.action, c.target, c.duration = "watch", 4, "LOOK", "ball", 3
    return scene, kid, ball


def cs_fcurves(obj):
    from crowd_addon.blender.action_data import action_fcurves
    from crowd_addon.blender.compat import assigned_slot
    ad = obj.animation_data
    return action_fcurves(ad.action, assigned_slot(ad))


def world_heads(crowd, chain):
    """(pivot, forward) of every agent's head in world space, from agent_rows."""
    ids = np.arange(crowd.agents.count)
    pivot, f = head_direction(crowd.agent_rows(ids).astype(np.float64), chain)
    h = crowd.agents.heading[ids].astype(np.float64)
    c, s = np.cos(h), np.sin(h)

    def rot(v):
        return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], 1)

    return rot(pivot) * crowd.agents.scale[ids, None] + crowd.agents.position[ids], rot(f)


def angle(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


def test_the_heads_point_at_the_object_where_blender_puts_it_each_frame():
    scene, kid, ball = build()
    scene.frame_set(7)
    cfg = scene_config.config_from_scene(scene)
    assert scene.frame_current == 7                 # the sampling put the frame back
    rig = cfg.look_rigs["Kid"]
    assert rig.bones == ("neck", "head") and rig.shares == (0.4, 0.6)
    assert rig.forward == (0.0, -1.0, 0.0)          # the scene's Forward setting (-Y)
    assert math.isclose(rig.yaw_limit, math.radians(80), rel_tol=1e-6)
    target = cfg.look_targets["ball"]
    assert target.first == 1 and target.positions.shape == (48, 3)
    np.testing.assert_allclose(target.positions, ball_at(range(1, 49)), atol=1e-5)
    seen_by_blender = []
    for f in (5, 20, 33, 48):
        scene.frame_set(f)
        seen_by_blender.append(tuple(ball.matrix_world.translation))
    np.testing.assert_allclose(target.positions[[4, 19, 32, 47]], seen_by_blender, atol=1e-6)

    crowd = Crowd(cfg)
    chain = LookChain(rig, cfg.skeletons["Kid"])
    for f in range(2, 48):
        crowd.step()
        pivot, fwd = world_heads(crowd, chain)
        if f < 4:                                   # before the cue: the idle's heads
            assert angle(fwd, ball_at([f]) - pivot).max() > 5.0, f
        if f >= 4 + 3:                              # blended in: at the ball, this frame
            assert angle(fwd, ball_at([f]) - pivot).max() < 1.0, f
    assert crowd.show.stats["watch"]["agents"] == 12


def test_lag_smoothing_a_still_target_and_the_scene_frame():
    scene, kid, ball = build(smoothing=3.0, lag="SEEDED", max_lag=5)
    still = bpy.data.objects.new("Post", None)
    scene.collection.objects.link(still)
    still.location = (1.0, -20.0, 2.0)
    t = scene.crowd.show.look_targets.add()
    t.name, t.object = "post", still
    cfg = scene_config.config_from_scene(scene)
    assert (cfg.look_lag, cfg.look_max_lag) == ("seeded", 5)
    assert cfg.look_targets["ball"].smoothing == 3.0
    post = cfg.look_targets["post"]                 # nothing animates it: one sample
    np.testing.assert_allclose(post.positions, [[1.0, -20.0, 2.0]])
    crowd = Crowd(cfg)
    crowd.advance_to(30)
    lags = crowd.look.lags
    assert lags.min() >= 0 and lags.max() <= 5 and np.unique(lags).size > 1
    chain = LookChain(cfg.look_rigs["Kid"], cfg.skeletons["Kid"])
    pivot, fwd = world_heads(crowd, chain)          # each at the smoothed ball, lag late
    seen = cfg.look_targets["ball"].at(30 - lags)
    assert angle(fwd, seen - pivot).max() < 1.0


def test_sampling_240_frames_is_cheap():
    scene, _, ball = build()
    scene.frame_end = 240
    t0 = time.perf_counter()
    (path,) = object_positions(scene, [ball])
    took = time.perf_counter() - t0
    assert path.shape == (240, 3)
    np.testing.assert_allclose(path, ball_at(range(1, 241)), atol=1e-5)
    print(f"sampled 240 frames in {took * 1000:.1f} ms")
    assert took < 5.0


@pytest.mark.parametrize("change, match", [
    (lambda s: setattr(s.show.cues[0], "target", "moon"),
     r"cue 'watch': unknown look target 'moon'"),
    (lambda s: setattr(s.characters[0], "look_bones", "neck, skull"),
     r"character 'Kid': look bones: no bone named 'skull'"),
    (lambda s: setattr(s.characters[0], "look_bones", "head, neck"), "parent first"),
    (lambda s: setattr(s.characters[0], "look_shares", "0.5, 0.6"), "summing to 1"),
    (lambda s: setattr(s.characters[0], "look_shares", "half, half"), "numbers"),
    (lambda s: setattr(s.show.look_targets[0], "object", None), "look target 'ball': no object"),
])
def test_bad_look_settings_are_named(change, match):
    scene, _, _ = build()
    change(scene.crowd)
    with pytest.raises(CrowdError, match=match):
        scene_config.config_from_scene(scene)


def test_the_look_rig_and_targets_change_the_fingerprint():
    from crowd_addon.blender.props import settings_fingerprint
    scene, kid, ball = build()
    before = settings_fingerprint(scene.crowd)
    kid.look_yaw_limit = math.radians(60)
    assert settings_fingerprint(scene.crowd) != before
    before = settings_fingerprint(scene.crowd)
    fc = cs_fcurves(ball)[0]
    fc.keyframe_points[1].co.y += 1.0                # the ball's path moved
    assert settings_fingerprint(scene.crowd) != before


class _Layout:
    """Stands in for ``UILayout``: every property, list and operator the panels name
    must exist in Blender's RNA."""

    use_property_split = False

    def __init__(self, seen):
        self.seen = seen

    def _sub(self, *_a, **_k):
        return self

    row = column = box = separator = _sub

    def label(self, text="", **_k):
        self.seen.append(("label", text))

    def prop(self, data, name, **_k):
        assert name in data.bl_rna.properties, (data, name)
        self.seen.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **_k):
        assert name in data.bl_rna.properties and search_name in search_data.bl_rna.properties
        self.seen.append(("prop", name))

    def template_list(self, list_id, _uid, data, coll, active_data, active, **_k):
        assert hasattr(bpy.types, list_id) and coll in data.bl_rna.properties
        assert active in active_data.bl_rna.properties
        self.seen.append(("list", coll))

    def operator(self, idname, **_k):
        mod, name = idname.split(".")
        rna = getattr(getattr(bpy.ops, mod), name).get_rna_type()
        return type("Props", (), {"__setattr__": lambda self, k, v: None})() if rna else None


def test_the_panels_show_the_look_rig_targets_and_the_look_cue():
    from crowd_addon.blender import panels, show_panels
    scene, kid, _ = build()
    kid.look_bones = "neck, jaw"
    scene.crowd.show.look_lag = "SEEDED"
    ctx = type("Ctx", (), {"scene": scene})()
    seen = []
    for cls in (panels.CROWD_PT_look_rig, show_panels.CROWD_PT_show):
        cls.draw(type("P", (), {"layout": _Layout(seen)})(), ctx)
    show_panels.CROWD_UL_look_targets.draw_item(None, None, _Layout(seen), scene.crowd.show,
                                                scene.crowd.show.look_targets[0], 0, True, "")
    props = {n for k, n in seen if k == "prop"}
    assert {"look_bones", "look_shares", "look_yaw_limit", "look_pitch_limit", "object",
            "smoothing", "look_lag", "look_max_lag", "target", "duration", "hold"} <= props
    assert "switch_trigger" not in props and "offset_mode" not in props   # a look cue
    assert ("list", "look_targets") in seen
    labels = [t for k, t in seen if k == "label"]
    assert any("jaw" in t and "Kid" in t for t in labels)          # the missing bone named
    # the list's + adds the selected object as a target, named after it
    bpy.context.view_layer.objects.active = bpy.data.objects["Ball"]
    assert bpy.ops.crowd.item_add(collection="look_targets") == {"FINISHED"}
    t = scene.crowd.show.look_targets[-1]
    assert (t.name, t.object.name) == ("Ball", "Ball")
