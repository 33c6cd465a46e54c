"""Mesh variants and props authored in Blender (Characters panel), baked into the crowd.

Oracles: Blender's own evaluation of an object parented to a bone (where Blender puts
the prop, frame by frame, while the rig plays the action) against core's skinning of
the baked prop; the Armature modifier's evaluated mesh of a variant against core's
skinning; the evaluated *Render Crowd* instances against core's skinning of each
agent's body; and the same choices for the same seed, in a fresh bake.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

import bpy
from mathutils import Matrix

sys.path.insert(0, str(Path(__file__).parent))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview, render_crowd, scene_config  # noqa: E402
from crowd_addon.core.shots.crowd import Crowd  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.core.base.skinning import skin_vertices  # noqa: E402

extension = cs.extension_fixture()


def _box(name, centre, half=(0.05, 0.05, 0.15)):
    """A box mesh object ``half`` metres half-wide around ``centre`` (world)."""
    c = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3))
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in c * half], [], quads)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = centre
    return obj


def _parent_to_bone(obj, rig, bone):
    """Parent ``obj`` to ``bone`` keeping where it is (as Ctrl P > Bone does): the
    parent inverse undoes the bone's tail at rest."""
    b = rig.data.bones[bone]
    tail = rig.matrix_world @ b.matrix_local @ Matrix.Translation((0.0, b.length, 0.0))
    world = obj.matrix_world.copy()
    obj.parent, obj.parent_type, obj.parent_bone = rig, "BONE", bone
    obj.matrix_parent_inverse = tail.inverted()
    obj.matrix_basis = world


def _world(obj):
    me = obj.data
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    m = np.array(obj.matrix_world, np.float64)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


@pytest.fixture
def dressed():
    """The walking crowd with a slimmer second body (weight 1 : 1) and a flag on the
    left arm carried by 40 % of the agents, baked while the rig stands posed at frame
    7 (the flag keeps where it sits on its bone)."""
    preview.stop_all()
    scene, rig, body, walk = cs.walking_crowd()
    s = scene.crowd
    slim = cs.make_proxy(rig, "Slim", width=0.03)
    char = s.characters[0]
    v = char.variants.add()
    v.object, v.weight = slim, 1.0
    flag = _box("Flag", (0.6, 0.0, 1.5))
    _parent_to_bone(flag, rig, "arm.L")
    p = char.props.add()
    p.object, p.share = flag, 0.4
    rig.animation_data.action = walk
    scene.frame_set(7)
    return scene, rig, walk, slim, flag


def test_a_prop_moves_as_blender_moves_an_object_parented_to_its_bone(dressed):
    scene, rig, walk, _slim, flag = dressed
    cfg = scene_config.config_from_scene(scene)
    (prop,) = cfg.props["Rig"]
    assert prop.name == "Flag" and cfg.skeletons["Rig"].bone_names[prop.bone] == "arm.L"
    crowd = Crowd(cfg)
    carriers = np.flatnonzero(cfg.prop_masks & 1)
    assert 0 < carriers.size < cfg.agent_count
    rig_inv = np.linalg.inv(np.array(rig.matrix_world, np.float64))
    worst = 0.0
    for frame in (2, 9, 17):
        crowd.advance_to(frame)
        rows = crowd.view.agent_rows(carriers)
        got = skin_vertices(prop.mesh.positions, prop.mesh.bone_indices,
                            prop.mesh.bone_weights, rows)
        for a, verts in zip(carriers, got):
            o = int(crowd.agents.offset[a])
            scene.frame_set(1 + (frame - 1 - o) % 24)          # walk loops every 24
            want = _world(flag) @ rig_inv[:3, :3].T + rig_inv[:3, 3]
            worst = max(worst, float(np.abs(verts - want).max()))
    assert worst < 2e-5, f"the prop is {worst:.3g} m from Blender's child-of-bone object"


def test_a_prop_not_parented_follows_the_bone_it_names_from_where_it_is(dressed):
    """An object only placed near the bone (not parented), with *Bone* set: it keeps
    where it is relative to the bone's current pose, as parenting it now would."""
    scene, rig, walk, _slim, flag = dressed
    parented = scene_config.config_from_scene(scene).props["Rig"][0].mesh.positions
    world = flag.matrix_world.copy()
    flag.parent = None
    flag.matrix_world = world
    bpy.context.view_layer.update()
    scene.crowd.characters[0].props[0].bone = "arm.L"
    loose = scene_config.config_from_scene(scene).props["Rig"][0].mesh.positions
    np.testing.assert_allclose(loose, parented, atol=1e-5)


def test_variants_and_props_are_seeded_and_drawn_on_their_agents(dressed):
    scene, rig, walk, slim, flag = dressed
    cfg = scene_config.config_from_scene(scene)
    again = scene_config.config_from_scene(scene)
    np.testing.assert_array_equal(cfg.variant_ids, again.variant_ids)
    np.testing.assert_array_equal(cfg.prop_masks, again.prop_masks)
    assert set(cfg.variant_ids.tolist()) == {0, 1}
    assert [lv[0].name for lv in cfg.mesh_variants("Rig")] == ["Body", "Slim"]
    scene.crowd.seed = 4
    other = scene_config.config_from_scene(scene)
    assert (other.variant_ids != cfg.variant_ids).any() or \
        (other.prop_masks != cfg.prop_masks).any()
    # the slim variant as core skins it is the Armature modifier's evaluated mesh
    rig.animation_data.action = walk
    scene.frame_set(5)
    sk = cfg.skeletons["Rig"]
    mesh = cfg.mesh_variants("Rig")[1][0]
    pose = np.array([np.array(rig.pose.bones[n].matrix) for n in sk.bone_names])
    rows = (pose @ sk.inverse_bind)[None]
    dg = bpy.context.evaluated_depsgraph_get()
    ev = slim.evaluated_get(dg).to_mesh()
    co = np.empty(3 * len(ev.vertices), np.float32)
    ev.vertices.foreach_get("co", co)
    slim.evaluated_get(dg).to_mesh_clear()
    got = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights, rows)[0]
    np.testing.assert_allclose(got, co.reshape(-1, 3), atol=2e-5)


def test_render_crowd_instances_each_agents_variant_and_its_props(dressed):
    """*Render Crowd* instances every agent's mesh variant and, as pieces of their own,
    the props it carries: each instance is core's skinning of that mesh for its agent;
    a prop's pose mesh is shared by all agents whose bone is in the same pose."""
    scene, rig, walk, slim, flag = dressed
    rig.animation_data.action = None
    for obj in (rig, slim, flag, bpy.data.objects["Body"]):
        obj.hide_render = True
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    scene.frame_set(9)
    scene.crowd.render_crowd = True
    pv = preview.get(scene)
    assert pv.render_error == ""
    crowd, cfg = pv.crowd, pv.crowd.config
    carriers = np.flatnonzero(cfg.prop_masks & 1)
    points = bpy.data.objects[render_crowd.POINTS].data
    n = crowd.agents.count
    assert len(points.vertices) == n + carriers.size
    agent, prop = np.empty(len(points.vertices), np.int32), np.empty(len(points.vertices),
                                                                     np.int32)
    points.attributes["crowd_agent"].data.foreach_get("value", agent)
    points.attributes["crowd_prop"].data.foreach_get("value", prop)
    np.testing.assert_array_equal(agent, np.r_[np.arange(n), carriers])
    np.testing.assert_array_equal(prop, np.r_[np.full(n, -1), np.zeros(carriers.size)])
    rows = crowd.view.agent_rows_index()
    bodies = len(np.unique(rows * 2 + cfg.variant_ids))
    assert pv.render_stats.poses == bodies + len(np.unique(rows[carriers]))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    seen = {}
    for inst in depsgraph.object_instances:
        if not (inst.is_instance and inst.parent is not None
                and inst.parent.original.name == render_crowd.POINTS):
            continue
        i = int(inst.persistent_id[0])              # every point is drawn here
        a = int(agent[i])
        mesh = cfg.props["Rig"][0].mesh if prop[i] >= 0 else \
            cfg.mesh_variants("Rig")[int(cfg.variant_ids[a])][0]
        assert len(inst.object.data.vertices) == mesh.vertex_count
        local = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                              crowd.view.agent_rows([a]))[0] * float(crowd.agents.scale[a])
        h = float(crowd.agents.heading[a])
        c, s_ = np.cos(h), np.sin(h)
        want = np.stack([c * local[:, 0] - s_ * local[:, 1],
                         s_ * local[:, 0] + c * local[:, 1], local[:, 2]], 1) + \
            crowd.agents.position[a]
        m = np.array(inst.matrix_world, np.float64)
        co = np.empty(3 * mesh.vertex_count, np.float32)
        inst.object.data.vertices.foreach_get("co", co)
        got = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        np.testing.assert_allclose(got, want, atol=1e-5)
        seen[i] = True
    assert len(seen) == len(points.vertices)


def test_a_prop_without_a_bone_or_a_variant_without_a_mesh_is_named(dressed):
    scene, rig, walk, slim, flag = dressed
    char = scene.crowd.characters[0]
    flag.parent = None
    with pytest.raises(CrowdError, match=r"character 'Rig': prop 1: object 'Flag': choose "
                                         r"its bone"):
        scene_config.config_from_scene(scene)
    char.props[0].bone = "nose"
    with pytest.raises(CrowdError, match=r"prop 1: object 'Flag': armature 'Rig' has no "
                                         r"bone 'nose'"):
        scene_config.config_from_scene(scene)
    char.props[0].bone = "head"
    char.variants[0].object = None
    with pytest.raises(CrowdError, match=r"character 'Rig': mesh variant 1 has no mesh"):
        scene_config.config_from_scene(scene)


def test_generate_agents_on_a_running_preview_redraws_bodies_and_palettes(dressed):
    """*Generate Agents* with the preview running replaces every per-agent array (it
    once kept the old agents' variants, props and palette colours beside the new
    agents', and the crowd refused the mismatch)."""
    scene, rig, walk, slim, flag = dressed
    rig.animation_data.action = None
    assert bpy.ops.crowd.bake() == {"FINISHED"}
    before = preview.get(scene).crowd
    assert before.agents.count == 30 and before.config.prop_masks.any()
    scene.crowd.agent_sources[0].object = cs.make_seats(3, 4, name="Few")
    assert bpy.ops.crowd.generate_agents() == {"FINISHED"}
    now = preview.get(scene).crowd
    assert now.agents.count == 12 and now.config.clips is before.config.clips
    assert now.config.variant_ids.shape == now.config.prop_masks.shape == (12,)
    assert now.view.agent_body.shape == (12,)


def test_picking_a_variant_or_prop_in_its_list_is_no_change_to_bake(dressed):
    """The lists' active rows are UI state: the preview's settings fingerprint (what
    asks for a new bake) ignores them, and sees a prop's share."""
    from crowd_addon.blender.props import settings_fingerprint
    scene, *_ = dressed
    char = scene.crowd.characters[0]
    char.variants.add()
    char.props.add()
    before = settings_fingerprint(scene.crowd)
    char.active_variant_index, char.active_prop_index = 1, 1
    assert settings_fingerprint(scene.crowd) == before
    char.props[0].share = 0.9
    assert settings_fingerprint(scene.crowd) != before


def test_a_palette_may_colour_a_props_material(dressed):
    """A palette naming the flag's material gives every agent a colour for it, which
    the GPU vertex colours of the bodies with the flag take (the palette column on the
    flag's triangles), as they would on the body."""
    from crowd_addon.gpu.proxies import vertex_colors
    scene, rig, walk, slim, flag = dressed
    cloth = bpy.data.materials.new("cloth")
    flag.data.materials.append(cloth)
    pal = scene.crowd.characters[0].palettes.add()
    pal.material, pal.count = "cloth", 2
    cfg = scene_config.config_from_scene(scene)
    assert cfg.palette_materials["Rig"] == ("cloth",)
    assert (cfg.palette[:, 0] >= 0).all()
    crowd = Crowd(cfg)
    flagged = [b for b in crowd.view.bodies if b.props]
    assert flagged
    for body in flagged:
        mesh = body.levels[0]
        alpha = vertex_colors(mesh, cfg.palette_materials["Rig"])[:, 3]
        names = [k.name for k in mesh.looks]
        cloth_tris = mesh.material == names.index("cloth")
        assert (alpha[mesh.triangles[cloth_tris].ravel()] == 0).all()
        assert (alpha[mesh.triangles[~cloth_tris].ravel()] == 255).all()
