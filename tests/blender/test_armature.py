"""Armature -> Skeleton and skinned mesh -> ProxyMesh against Blender's rest pose and
the Armature modifier's depsgraph-evaluated mesh."""

import numpy as np
import pytest

from crowd_addon.blender.armature import (check_skeleton, object_to_armature,
                                          proxy_mesh_from_object, skeleton_from_armature)
from crowd_addon.blender.bake import bake_actions
from crowd_addon.core.anim.clip import ClipBank
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices

CHILD_FIRST = [  # children listed before their parents: the skeleton reorders them
    ("hand", (0.9, 0.6, 1.2), (1.2, 0.5, 1.0), 2.0, "arm", True),
    ("arm", (0.3, 0.8, 1.0), (0.9, 0.6, 1.2), 1.1, "root", False),
    ("root", (0.0, 0.0, 0.0), (0.0, 0.5, 0.2), 0.3, None, False),
]


def test_skeleton_is_the_rest_pose_parents_first(scene, blend):
    obj = blend.build_rig(scene, CHILD_FIRST, location=(3, 0, 1), rotation=(0.5, 0, 0))
    sk = skeleton_from_armature(obj)
    assert sk.name == "Rig" and sk.bone_names == ("root", "arm", "hand")
    assert all(p < i for i, p in enumerate(sk.parents))
    rest = np.array([np.array(obj.data.bones[n].matrix_local) for n in sk.bone_names])
    np.testing.assert_allclose(sk.bind_model, rest, atol=1e-6)
    np.testing.assert_allclose(sk.inverse_bind @ rest, np.broadcast_to(np.eye(4), rest.shape),
                               atol=1e-6)
    check_skeleton(obj, sk)
    other = blend.build_rig(scene, name="Other")
    with pytest.raises(CrowdError, match="does not match armature 'Other'"):
        check_skeleton(other, sk)


def skinned_body(blend, scene, rig, seed=0):
    """A mesh of points around the bones with 1-3 unnormalised weights per vertex, a
    group for a non-deform bone and one matching no bone (both ignored by Blender),
    transformed differently from the armature."""
    bpy = blend.bpy
    rng = np.random.default_rng(seed)
    names = [b.name for b in rig.data.bones]
    verts = []
    for b in rig.data.bones:
        h, t = np.array(b.head_local), np.array(b.tail_local)
        for s in np.linspace(0, 1, 6):
            verts.append(h + s * (t - h) + rng.normal(0, 0.05, 3))
    faces = [(i, i + 1, i + 2) for i in range(0, len(verts) - 2, 2)]
    me = bpy.data.meshes.new("Body")
    me.from_pydata([tuple(v) for v in verts], [], faces)
    obj = bpy.data.objects.new("Body", me)
    scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler, obj.scale = (0.3, -0.2, 0.1), (0.1, 0.4, -0.2), (1.2,) * 3
    groups = {n: obj.vertex_groups.new(name=n) for n in names}
    stray = obj.vertex_groups.new(name="not_a_bone")
    rig.data.bones["foot"].use_deform = False
    deform = [n for n in names if n != "foot"]
    for v in range(len(verts)):
        for n in rng.choice(deform, int(rng.integers(1, 4)), replace=False):
            groups[n].add([v], float(rng.uniform(0.1, 1.0)), "REPLACE")
        groups["foot"].add([v], 0.7, "REPLACE")
        stray.add([v], 0.5, "REPLACE")
    obj.modifiers.new("Armature", "ARMATURE").object = rig
    bpy.context.view_layer.update()                          # matrix_world
    return obj


def test_skinned_vertices_match_the_armature_modifier(scene, blend):
    rig = blend.build_rig(scene, location=(1, 2, 0), rotation=(0, 0, 0.8))
    action, _, _ = blend.rig_action(rig)
    body = skinned_body(blend, scene, rig)
    result = bake_actions(rig, [action], fps=scene.render.fps * 2)
    proxy = proxy_mesh_from_object(body, rig, result.skeleton)
    assert proxy.vertex_count == len(body.data.vertices) and proxy.skeleton == "Rig"
    bank = ClipBank(result.clips)
    to_armature = object_to_armature(body, rig)
    bpy = blend.bpy
    for frame in (1, 4.5, 9, 13.5, 20):
        scene.frame_set(int(frame), subframe=frame % 1)
        evaluated = body.evaluated_get(bpy.context.evaluated_depsgraph_get())
        mesh = evaluated.to_mesh()
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        evaluated.to_mesh_clear()
        want = co.reshape(-1, 3) @ to_armature[:3, :3].T + to_armature[:3, 3]
        local = bank.sample(np.array([0]), np.array([(frame - 1) * 2]))
        rows = skinning_matrices(local, result.skeleton)
        got = skin_vertices(proxy.positions, proxy.bone_indices, proxy.bone_weights, rows)[0]
        assert np.abs(got - want).max() < 1e-4, frame
    rest = np.empty(len(body.data.vertices) * 3, np.float32)
    body.data.vertices.foreach_get("co", rest)
    moved = np.abs(want - (rest.reshape(-1, 3) @ to_armature[:3, :3].T + to_armature[:3, 3]))
    assert moved.max() > 0.1                              # the pose really deforms it


def drop_modifier(body):
    body.modifiers.clear()


def preserve_volume(body):
    body.modifiers[0].use_deform_preserve_volume = True


def modifier_first(body):
    body.modifiers.new("Bend", "SIMPLE_DEFORM")
    body.modifiers.move(1, 0)


def unweighted_vertex(body):
    """Vertex 0 keeps only its weights to the non-deform bone and the stray group."""
    for group in body.vertex_groups:
        if group.name not in ("foot", "not_a_bone"):
            group.remove([0])


@pytest.mark.parametrize("change, message", [
    (drop_modifier, "no Armature modifier deforming 'Rig'"),
    (preserve_volume, "preserves volume"),
    (modifier_first, r"modifiers \['Bend'\] run before"),
    (unweighted_vertex, "1 vertices have no bone weight"),
])
def test_unsupported_meshes_name_the_fault(scene, blend, change, message):
    rig = blend.build_rig(scene)
    body = skinned_body(blend, scene, rig)
    change(body)
    with pytest.raises(CrowdError, match=message):
        proxy_mesh_from_object(body, rig)


def test_not_an_armature(scene, blend):
    empty = blend.bpy.data.objects.new("Empty", None)
    with pytest.raises(CrowdError, match="'Empty' is not an armature"):
        skeleton_from_armature(empty)
