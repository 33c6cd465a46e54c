"""Meshes whose vertices belong to more than four bones' vertex groups.

Oracle: the Armature modifier's depsgraph-evaluated mesh, which blends every group of a
vertex. Up to eight influences core must match it exactly; past eight the proxy keeps
the eight strongest and the bake says which mesh and how many vertices.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview  # noqa: E402
from crowd_addon.blender.armature import object_to_armature, proxy_mesh_from_object  # noqa: E402
from crowd_addon.blender.bake import bake_actions  # noqa: E402
from crowd_addon.core.anim.clip import ClipBank  # noqa: E402
from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices  # noqa: E402

#: ten bones: root, four spine bones, two arms of two and a head, so a vertex can lie in ten groups
TEN = [("root", (0.0, 0.0, 0.0), (0.0, 0.1, 0.5), 0.2, None, False)] + [
    (f"spine{i}", (0.0, 0.1 * i, 0.5 * i), (0.0, 0.1 * (i + 1), 0.5 * (i + 1)), 0.3 * i,
     "root" if i == 1 else f"spine{i - 1}", True) for i in range(1, 5)] + [
    (f"{part}.{side}", (s * 0.3 * i, 0.2, 1.6), (s * 0.3 * (i + 1), 0.25, 1.55), 0.5 * i,
     "spine3" if i == 1 else f"arm.{side}", i > 1)
    for s, side in ((1, "L"), (-1, "R")) for i, part in ((1, "arm"), (2, "hand"))] + [
    ("head", (0.0, 0.5, 2.5), (0.0, 0.55, 2.9), -0.4, "spine4", True)]


def many_groups(scene, rig, k, seed=0, name="Body"):
    """Points around the bones, each vertex in ``k`` groups (the ``k`` bones whose heads
    are nearest, random unnormalised weights), moved apart from the armature."""
    rng = np.random.default_rng(seed)
    bones = list(rig.data.bones)
    heads = np.array([b.head_local for b in bones])
    verts = []
    for b in bones:
        h, t = np.array(b.head_local), np.array(b.tail_local)
        for s in np.linspace(0, 1, 5):
            verts.append(h + s * (t - h) + rng.normal(0, 0.08, 3))
    faces = [(i, i + 1, i + 2) for i in range(0, len(verts) - 2, 2)]
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], faces)
    obj = bpy.data.objects.new(name, me)
    scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler = (0.2, -0.1, 0.05), (0.1, -0.3, 0.2)
    groups = {b.name: obj.vertex_groups.new(name=b.name) for b in bones}
    for v, p in enumerate(verts):
        near = np.argsort(np.linalg.norm(heads - p, axis=1), kind="stable")[:k]
        for j in near:
            groups[bones[j].name].add([v], float(rng.uniform(0.2, 1.0)), "REPLACE")
    obj.modifiers.new("Armature", "ARMATURE").object = rig
    bpy.context.view_layer.update()
    return obj


def test_six_groups_a_vertex_skin_like_the_armature_modifier(scene, blend):
    rig = blend.build_rig(scene, location=(1, 2, 0), rotation=(0, 0, 0.8))
    action, _, _ = blend.rig_action(rig)
    body = many_groups(scene, rig, 6)
    assert {len(v.groups) for v in body.data.vertices} == {6}
    result = bake_actions(rig, [action], fps=scene.render.fps * 2)
    proxy = proxy_mesh_from_object(body, rig, result.skeleton)
    bank = ClipBank(result.clips)
    to_armature = object_to_armature(body, rig)
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
    assert proxy.bone_indices.shape[1] == 8 and proxy.notes == ()


def test_more_than_eight_groups_keep_eight_and_say_so(scene, blend):
    rig = blend.build_rig(scene, TEN)
    body = many_groups(scene, rig, 10, name="Crowd Guy")
    for v in range(0, len(body.data.vertices), 4):     # every fourth keeps only eight
        for g in list(body.data.vertices[v].groups)[8:]:
            body.vertex_groups[g.group].remove([v])
    cut = sum(len(v.groups) > 8 for v in body.data.vertices)
    proxy = proxy_mesh_from_object(body, rig)
    assert proxy.bone_indices.shape[1] == 8 and 0 < cut < len(body.data.vertices)
    assert proxy.notes == (f"mesh 'Crowd Guy': {cut} of {len(body.data.vertices)} vertices "
                           "have more than 8 bone influences (up to 10); each keeps its 8 "
                           "strongest, renormalised, so they deform slightly differently",)




def test_the_bake_reports_the_mesh_and_how_many_vertices_lost_influences():
    with cs.registered():
        preview.stop_all()
        scene = cs.reset()
        rig = cs.make_armature(bones=[(n, p, h, t) for n, h, t, _, p, _ in TEN])
        walk = cs.make_action(rig, "walk", seed=1)
        body = many_groups(scene, rig, 9, name="Crowd Guy")
        cs.add_character(scene.crowd, rig, body)
        cs.add_stream(scene.crowd, "walk", walk)
        scene.crowd.max_offset = 8
        op = cs.FakeBakeOperator(scene)
        timer = type("Event", (), {"type": "TIMER"})()
        try:
            while op.modal(bpy.context, timer) == {"RUNNING_MODAL"}:
                pass
        finally:
            preview.stop_all()
    # the mesh's note (the test's random walk may also miss between frames: its own note)
    warnings = [m for kind, m in op.reports if kind == {"WARNING"} and m.startswith("mesh")]
    n = len(body.data.vertices)
    assert warnings == [f"mesh 'Crowd Guy': {n} of {n} vertices have more than 8 bone "
                        "influences (up to 9); each keeps its 8 strongest, "
                        "renormalised, so they deform slightly differently"]
    assert op.reports[-1][0] == {"INFO"}
