"""Several characters in one scene (``scene.crowd.characters``): each its own armature,
body, LOD meshes, streams and uniques, built into one crowd.

Oracles: Blender's own pose evaluation (``pose.bones[].matrix`` of each armature
playing the action at the agent's delayed frame) for what every agent of every
character shows; the mesh data of the LOD objects; a saved and reopened .blend; the
operators run through ``bpy.ops``; and pxr reading back ``crowd export --blend``.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview, scene_config  # noqa: E402
from crowd_addon.blender.agents import agents_from_scene  # noqa: E402
from crowd_addon.blender.props import settings_fingerprint  # noqa: E402
from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.core.base.skinning import model_matrices  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SEATS = (6, 5)


extension = cs.extension_fixture()


def _seats(name="Seats", character=None, stream=None, nx=SEATS[0], ny=SEATS[1]):
    """A seat grid with INT point attributes ``character`` and ``stream`` when given
    (functions of the vertex index)."""
    obj = cs.make_seats(nx, ny, name=name)
    n = nx * ny
    for attr, fn in (("character", character), ("stream", stream)):
        if fn is not None:
            values = np.array([fn(i) for i in range(n)], np.int32)
            obj.data.attributes.new(attr, "INT", "POINT").data.foreach_set("value", values)
    return obj


def build_two_characters():
    """A 5-bone "Rig" (streams walk, wave_fan; unique idle) and a 7-bone "Kid"
    (streams jump, wave_kid): both play the action "wave"; 30 seats, even ones the
    rig's, odd ones the kid's, the stream index among the character's streams from the
    ``stream`` attribute."""
    preview.stop_all()
    scene = cs.reset()
    rig = cs.make_armature("Rig")
    kid = cs.make_armature("Kid", bones=cs.KID_BONES)
    kid.location = (3.0, 0.0, 0.0)
    acts = {"walk": cs.make_action(rig, "walk", seed=1, markers=[("step", 7)]),
            "idle": cs.make_action(rig, "idle", seed=3, frames=(1, 9, 17)),
            "wave": cs.make_action(rig, "wave", seed=2, bones=["arm.L", "arm.R"],
                                   amplitude=1.2),
            "jump": cs.make_action(kid, "jump", seed=4, frames=(1, 7, 13), amplitude=0.9)}
    s = scene.crowd
    s.max_offset, s.seed = 8, 2
    fan = cs.add_character(s, rig, cs.make_proxy(rig))
    child = cs.add_character(s, kid, cs.make_proxy(kid, "KidBody", width=0.04))
    cs.add_stream(fan, "walk", acts["walk"])
    cs.add_stream(fan, "wave_fan", acts["wave"])
    cs.add_stream(fan, "idle", acts["idle"], pool="uniques")
    cs.add_stream(child, "jump", acts["jump"])
    cs.add_stream(child, "wave_kid", acts["wave"])
    src = s.agent_sources.add()
    src.name, src.object = "seats", _seats(character=lambda i: i % 2,
                                           stream=lambda i: (i // 2) % 2)
    src.character_mode, src.stream_mode = "ATTRIBUTE", "ATTRIBUTE"
    return scene, {"Rig": rig, "Kid": kid}, acts


@pytest.fixture
def two():
    return build_two_characters()


def _blender_pose(scene, rig, action, frame, names):
    """``pose.bones[].matrix`` (B, 4, 4) of ``rig`` playing ``action`` at ``frame``
    (bones the action does not key in their rest pose)."""
    from mathutils import Matrix
    for pb in rig.pose.bones:
        pb.matrix_basis = Matrix.Identity(4)
    from crowd_addon.blender import compat
    ad = rig.animation_data or rig.animation_data_create()
    slots = compat.action_slots(action)
    compat.play(ad, action, slots[0] if slots else None)
    scene.frame_set(int(frame))
    out = np.array([np.array(rig.pose.bones[n].matrix) for n in names])
    ad.action = None
    return out


def test_each_character_plays_its_own_streams_as_blender_poses_its_armature(two):
    scene, rigs, acts = two
    cfg = scene_config.config_from_scene(scene)
    assert {k: sk.bone_count for k, sk in cfg.skeletons.items()} == {"Rig": 5, "Kid": 7}
    # "wave" is used by both characters: baked once per armature, the nodes follow
    assert sorted(cfg.clips) == ["Kid/wave", "Rig/wave", "idle", "jump", "walk"]
    assert [(d.name, d.skeleton) for d in cfg.streams] == [
        ("walk", "Rig"), ("wave_fan", "Rig"), ("jump", "Kid"), ("wave_kid", "Kid")]
    assert [(d.name, d.skeleton) for d in cfg.uniques] == [("idle", "Rig")]
    assert cfg.streams[1].root.clip == "Rig/wave" and cfg.streams[3].root.clip == "Kid/wave"
    assert cfg.clips["walk"].events == (("step", 6.0),)
    assert sorted(cfg.meshes) == ["Kid", "Rig"]
    assert cfg.meshes["Kid"][0].positions.shape == (7 * 8, 3)
    # seat i: character i % 2, stream (i // 2) % 2 among that character's streams
    seat = np.arange(30)
    np.testing.assert_array_equal(cfg.agent_stream, 2 * (seat % 2) + (seat // 2) % 2)
    crowd = Crowd(cfg)
    names = list(cfg.skeletons)
    np.testing.assert_array_equal(crowd.view.agent_skeleton, [names.index(n) for n in
                                                              ("Rig", "Kid") * 15])
    action_of = {"walk": acts["walk"], "wave_fan": acts["wave"], "jump": acts["jump"],
                 "wave_kid": acts["wave"]}
    for frame in (1, 6, 17):
        crowd.advance_to(frame)
        poses = crowd.agent_poses()
        for agent in range(30):
            stream = cfg.streams[cfg.agent_stream[agent]]
            sk = cfg.skeletons[stream.skeleton]
            act = action_of[stream.name]
            period = act.frame_range[1] - act.frame_range[0]
            t = (frame - cfg.agent_offset[agent] - scene.frame_start) % period
            want = _blender_pose(scene, rigs[stream.skeleton], act, 1 + t, sk.bone_names)
            got = model_matrices(poses[agent:agent + 1], sk)[0]
            np.testing.assert_allclose(got, want, atol=2e-5,
                                       err_msg=f"agent {agent} at frame {frame}")


def test_progress_names_each_action_and_character(two):
    scene, *_ = two
    steps = []
    scene_config.config_from_scene(scene, progress=lambda *a: steps.append(a))
    assert [m for _, _, m in steps] == [
        "baking action 'walk' for character 'Rig'", "baking action 'wave' for character 'Rig'",
        "baking action 'idle' for character 'Rig'", "baking action 'jump' for character 'Kid'",
        "baking action 'wave' for character 'Kid'",
        "reading the proxy mesh of character 'Rig'", "reading the proxy mesh of character 'Kid'",
        "placing agents"]
    assert [a[:2] for a in steps] == [(k, 8) for k in range(8)]


def test_sources_choose_characters_by_weight_deterministically(two):
    scene, *_ = two
    s = scene.crowd
    s.agent_sources[0].object = _seats("Stand", nx=40, ny=40)
    s.agent_sources[0].character_mode = "WEIGHTS"
    s.agent_sources[0].stream_mode = "RANDOM"
    s.characters["Rig"].weight, s.characters["Kid"].weight = 3.0, 1.0
    s.characters["Kid"].streams["wave_kid"].weight = 3.0
    dg = bpy.context.evaluated_depsgraph_get()
    a, placed = agents_from_scene(scene, dg)
    b, _ = agents_from_scene(scene, dg)
    np.testing.assert_array_equal(a.characters, b.characters)
    np.testing.assert_array_equal(a.streams, b.streams)
    assert 0.72 < (a.characters == 0).mean() < 0.78
    # each agent on a stream of its own character: the rig's are 0, 1, the kid's 2, 3
    assert set(a.streams[a.characters == 0].tolist()) == {0, 1}
    assert set(a.streams[a.characters == 1].tolist()) == {2, 3}
    assert 0.7 < (a.streams[a.characters == 1] == 3).mean() < 0.8
    s.seed = 3
    c, _ = agents_from_scene(scene, dg)
    assert (c.characters != a.characters).any()
    # the built crowd: an agent's character is its stream's skeleton
    s.seed = 2
    cfg = scene_config.config_from_scene(scene)
    skeleton = np.array([d.skeleton for d in cfg.streams])[cfg.agent_stream]
    np.testing.assert_array_equal(skeleton == "Rig", a.characters == 0)
    assert placed[0].count == 1600 and placed[0].first == 0


def test_sources_choose_characters_by_attribute_or_by_name(two):
    scene, *_ = two
    src = scene.crowd.agent_sources[0]
    dg = bpy.context.evaluated_depsgraph_get()
    a, _ = agents_from_scene(scene, dg)
    np.testing.assert_array_equal(a.characters, np.arange(30) % 2)
    src.character_mode, src.character_name = "FIXED", "Kid"
    src.stream_mode, src.stream_name = "FIXED", "wave_kid"
    a, _ = agents_from_scene(scene, dg)
    assert (a.characters == 1).all() and (a.streams == 3).all()


@pytest.mark.parametrize("change, message", [
    (lambda s: setattr(s.characters["Kid"].streams["jump"], "name", "walk"),
     r"^stream 'walk' of character 'Kid' has the name of stream 'walk' of character 'Rig'"),
    (lambda s: setattr(s.characters["Kid"].streams["jump"], "name", "idle"),
     r"^stream 'idle' of character 'Kid' has the name of unique 'idle' of character 'Rig'"),
    (lambda s: (setattr(s.agent_sources[0], "character_mode", "FIXED"),
                setattr(s.agent_sources[0], "character_name", "Kid"),
                setattr(s.agent_sources[0], "stream_mode", "FIXED"),
                setattr(s.agent_sources[0], "stream_name", "walk")),
     r"^agent source 'seats' \(object 'Seats'\): stream 'walk' is not a stream of character "
     r"'Kid' \(it is a stream of 'Rig'; 'Kid' has \['jump', 'wave_kid'\]\)"),
    (lambda s: setattr(s.agent_sources[0], "character_attribute", "team"),
     r"^agent source 'seats' \(object 'Seats'\): mesh of 'Seats' has no attribute 'team'"),
    (lambda s: setattr(s.characters["Kid"], "name", "Rig"),
     r"two characters are named 'Rig'"),
    (lambda s: setattr(s.characters["Kid"], "armature", None),
     r"^character 'Kid': no armature chosen"),
    (lambda s: s.characters["Kid"].streams.clear(),
     r"^agent source 'seats' \(object 'Seats'\): character 'Kid' has no streams"),
])
def test_bad_casts_name_the_characters_and_change_nothing(two, change, message):
    scene, *_ = two
    change(scene.crowd)
    before = settings_fingerprint(scene.crowd)
    with pytest.raises(CrowdError, match=message):
        scene_config.config_from_scene(scene)
    assert settings_fingerprint(scene.crowd) == before


def test_user_lod_meshes_replace_the_automatic_levels(two):
    scene, rigs, _ = two
    rig = rigs["Rig"]
    fan = scene.crowd.characters["Rig"]
    near, far = cs.make_proxy(rig, "Near", width=0.04), cs.make_proxy(rig, "Far", width=0.02)
    cs.add_lod(fan, near)
    cs.add_lod(fan, far)

    def co(obj):
        out = np.empty(len(obj.data.vertices) * 3, np.float32)
        obj.data.vertices.foreach_get("co", out)
        return out.reshape(-1, 3)

    cfg = scene_config.config_from_scene(scene)
    levels = cfg.meshes["Rig"]
    assert [lv.name for lv in levels[:3]] == ["Body", "Near", "Far"]
    # the far level: a card per body part (8 vertices each), bound to that part's bone
    card = levels[3]
    assert card.name.endswith(".card") and card.vertex_count % 8 == 0
    assert card.vertex_count // 8 == len(np.unique(card.bone_indices[:, 0])) > 1
    for level, obj in zip(levels, (fan.body, near, far)):
        np.testing.assert_allclose(level.positions, co(obj), atol=1e-6)
    # the kid keeps the automatic levels: its light body (84 triangles) is not
    # decimated below MIN_LOD_TRIANGLES
    from crowd_addon.core.meshes.levels import MIN_LOD_TRIANGLES
    kid = cfg.meshes["Kid"]
    assert [lv.name for lv in kid[1:3]] == ["KidBody.lod1", "KidBody.lod2"] and len(kid) == 5
    assert kid[0].triangle_count >= kid[1].triangle_count >= kid[2].triangle_count
    assert kid[2].triangle_count >= MIN_LOD_TRIANGLES
    # one LOD mesh serves both levels; cards off leaves them out
    fan.lods.remove(1)
    scene.crowd.lod_cards = False
    levels = scene_config.config_from_scene(scene).meshes["Rig"]
    assert [lv.name for lv in levels] == ["Body", "Near", "Near"]


@pytest.mark.parametrize("change, message", [
    (lambda s, o: cs.add_lod(s.characters["Rig"], None), r"^character 'Rig': LOD 1 has no mesh"),
    (lambda s, o: cs.add_lod(s.characters["Rig"], o["Kid"]),
     r"^character 'Rig': LOD 1: mesh 'KidBody' has no Armature modifier deforming 'Rig'"),
    (lambda s, o: [cs.add_lod(s.characters["Rig"], o["Body"]) for _ in range(3)],
     r"^character 'Rig': 3 LOD meshes; there are 2 levels"),
    (lambda s, o: (cs.add_lod(s.characters["Rig"], o["Body"]),
                   setattr(s.characters["Rig"], "body", None)),
     r"^character 'Rig': LOD meshes, mesh variants and props need a body"),
])
def test_bad_lod_meshes_are_named(two, change, message):
    scene, *_ = two
    objects = {"Kid": bpy.data.objects["KidBody"], "Body": bpy.data.objects["Body"]}
    change(scene.crowd, objects)
    with pytest.raises(CrowdError, match=message):
        scene_config.config_from_scene(scene)


def test_list_operators_add_remove_and_move_characters_lods_and_streams():
    preview.stop_all()
    scene = cs.reset()
    s = scene.crowd
    rig, kid = cs.make_armature("Rig"), cs.make_armature("Kid", bones=cs.KID_BONES)
    jump = cs.make_action(kid, "jump", seed=4)
    kid.animation_data.action = jump
    body = cs.make_proxy(kid, "KidBody")
    ops = bpy.ops.crowd
    with pytest.raises(RuntimeError, match="no active character"):
        ops.item_add(collection="streams")
    for active in (rig, kid, body):
        bpy.context.view_layer.objects.active = active
        assert ops.item_add(collection="characters") == {"FINISHED"}
    chars = s.characters
    assert [c.name for c in chars] == ["Character", "Character.001", "Character.002"]
    assert [(c.armature, c.body) for c in chars] == [(rig, None), (kid, None), (kid, body)]
    assert s.active_character_index == 2
    assert ops.item_move(collection="characters", step=-1) == {"FINISHED"}
    assert [c.name for c in chars] == ["Character", "Character.002", "Character.001"]
    assert s.active_character_index == 1
    assert ops.item_remove(collection="characters") == {"FINISHED"}
    assert [c.name for c in chars] == ["Character", "Character.001"]
    # streams, uniques and LODs go to the active character
    assert ops.item_add(collection="streams") == {"FINISHED"}
    assert ops.item_add(collection="lods") == {"FINISHED"}
    kid_char = chars["Character.001"]
    assert kid_char.streams[0].name == "Stream" and kid_char.streams[0].nodes[0].action == jump
    assert [lod.name for lod in kid_char.lods] == ["LOD 1"]
    s.active_character_index = 0
    assert ops.item_add(collection="streams") == {"FINISHED"}      # names are scene-wide
    assert chars[0].streams[0].name == "Stream.001"
    assert chars[0].streams[0].nodes[0].action is None               # the rig plays nothing
    assert ops.item_add(collection="uniques") == {"FINISHED"}
    assert ops.item_add(collection="nodes", pool="UNIQUES", kind="BLEND2") == {"FINISHED"}
    assert [n.kind for n in chars[0].uniques[0].nodes] == ["CLIP", "BLEND2"]
    with pytest.raises(RuntimeError, match="nothing selected in lods"):
        ops.item_remove(collection="lods")
    s.active_character_index = 1
    assert ops.item_remove(collection="lods") == {"FINISHED"} and not kid_char.lods


def test_save_and_reload_gives_the_same_crowd(two, tmp_path):
    scene, *_ = two
    cs.add_lod(scene.crowd.characters["Rig"], cs.make_proxy(bpy.data.objects["Rig"], "Near",
                                                             width=0.04))
    before = settings_fingerprint(scene.crowd)
    scene.crowd.active_character_index = 1                    # the UI's, not the crowd's
    assert settings_fingerprint(scene.crowd) == before
    cfg = scene_config.config_from_scene(scene)
    path = str(tmp_path / "cast.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert settings_fingerprint(scene.crowd) == before
    again = scene_config.config_from_scene(scene)
    assert list(again.clips) == list(cfg.clips) and list(again.meshes) == list(cfg.meshes)
    assert [lv.name for lv in again.meshes["Rig"]] == [lv.name for lv in cfg.meshes["Rig"]]
    for key in ("agent_stream", "agent_offset", "agent_position", "agent_color"):
        np.testing.assert_array_equal(getattr(again, key), getattr(cfg, key))
    a, b = Crowd(cfg), Crowd(again)
    for frame in (1, 5, 14):
        a.advance_to(frame)
        b.advance_to(frame)
        np.testing.assert_array_equal(a.agent_poses(), b.agent_poses())


def test_preview_pauses_when_a_characters_armature_goes(two):
    scene, rigs, _ = two
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    pv = preview.get(scene)
    assert pv.armatures == (("Rig", "Rig"), ("Kid", "Kid"))
    scene.frame_set(4)
    bpy.data.objects.remove(rigs["Kid"])
    scene.frame_set(5)
    assert pv.crowd.frame == 4
    assert "armature 'Kid' was deleted or unset (character 'Kid')" in pv.status()
    preview.stop(scene)


def test_crowd_export_blend_writes_both_characters(two, tmp_path):
    from pxr import Usd, UsdSkel
    blend, out = tmp_path / "cast.blend", tmp_path / "cast.usdc"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "export", "--blend", str(blend),
                          "--out", str(out), "--frames", "1-6"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    layers = sorted(p.stem for p in (tmp_path / "cast.layers" / "v1" / "characters").iterdir())
    assert layers == ["Kid", "Rig"]
    stage = Usd.Stage.Open(str(out))
    agents = [UsdSkel.Root(p) for p in stage.Traverse() if p.IsA(UsdSkel.Root)
              and p.IsInstance()]
    assert len(agents) == 30
    cache, pred = UsdSkel.Cache(), Usd.TraverseInstanceProxies()
    joints = []
    for agent in agents:
        cache.Populate(agent, pred)
        (binding,) = cache.ComputeSkelBindings(agent, pred)
        joints.append(len(cache.GetSkelQuery(binding.GetSkeleton()).GetJointOrder()))
    assert sorted(set(joints)) == [5, 7] and joints.count(5) == joints.count(7) == 15
