"""Blender's own USD importer on our export: with ``layout="blender"`` every agent plays
its animation in Blender, vertex for vertex what core computes.

The shot is the USD tests' (tests/usd/conftest.py: two characters, streams, a unique,
blends, a queued request, a cut, moving agents; M = 8, NT = 3). It is exported with the
Blender layout, imported with ``bpy.ops.wm.usd_import`` into an empty scene, and at
every shot frame (so on both sides of every clip switch) each agent's evaluated mesh in
world space is compared with core's skinning of the same agent at the same frame, with
its transform. Control: the instanced layout imports in bind pose, as the docs say.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from usd.conftest import (DYNAMIC, FAN_AGENTS, FIRST, KID_AGENTS, LAST, MOVING,  # noqa: E402
                          core_truth, make_config, recording)

from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices  # noqa: E402

TOLERANCE = 1e-4          # metres
N = FAN_AGENTS + KID_AGENTS


def import_agents(path, instancing=False) -> dict:
    """Import ``path`` into an empty scene: agent id -> its mesh object."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=str(path), support_scene_instancing=instancing)
    return imported_agents()


def imported_agents() -> dict:
    """agent id -> its imported mesh object, for every mesh of the scene."""
    out = {}
    for obj in bpy.data.objects:
        if obj.type != "MESH":
            continue
        holder = obj
        while holder is not None and not holder.name.startswith("agent_"):
            holder = holder.parent
        assert holder is not None, f"{obj.name} is not under an agent"
        out[int(holder.name.split("_")[1].split(".")[0])] = obj
    return out


def world_vertices(obj) -> np.ndarray:
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ev.to_mesh()
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    m = np.array(ev.matrix_world, np.float64)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def core_vertices(truth, frame, agent) -> np.ndarray:
    cfg = make_config()
    s, u = cfg.agent_stream[agent], cfg.agent_unique[agent]
    name = cfg.streams[s].skeleton if s >= 0 else cfg.uniques[u].skeleton
    skeleton, mesh = cfg.skeletons[name], cfg.meshes[name][0]
    pose = truth["poses"][frame][agent:agent + 1]
    v = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                      skinning_matrices(pose, skeleton))[0].astype(np.float64)
    v *= float(cfg.scales[agent])                 # the agent's body scale (xformOp:scale)
    c, s_ = np.cos(truth["heading"][frame][agent]), np.sin(truth["heading"][frame][agent])
    rot = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
    return v @ rot.T + truth["position"][frame][agent]


def assert_plays_as_core(agents, truth) -> float:
    """Every imported agent (id -> mesh object) at every shot frame where core's
    skinning puts it, within TOLERANCE; returns the worst vertex error."""
    scene = bpy.context.scene
    worst = 0.0
    for frame in range(FIRST, LAST + 1):
        scene.frame_set(frame)
        for a, obj in agents.items():
            err = float(np.abs(world_vertices(obj) - core_vertices(truth, frame, a)).max())
            assert err < TOLERANCE, (a, frame, err)
            worst = max(worst, err)
    return worst


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from crowd_addon.usd import export_crowd

    folder = tmp_path_factory.mktemp("blender_layout")
    rec = recording()
    return {layout: export_crowd(rec, folder / f"{layout}.usdc", layout=layout).path
            for layout in ("blender", "instanced")}


@pytest.fixture(scope="module")
def truth():
    return core_truth()


def test_blender_layout_imports_every_agent_animated_as_core(exported, truth):
    agents = import_agents(exported["blender"])
    assert sorted(agents) == list(range(N))
    worst = assert_plays_as_core(agents, truth)
    print(f"worst vertex error {worst:.2e} m over {LAST - FIRST + 1} frames x {N} agents")
    scene = bpy.context.scene
    # the shot really moves them: agents that change and agents that stand still differ
    scene.frame_set(FIRST)
    before = {a: world_vertices(agents[a]) for a in sorted(DYNAMIC | MOVING)}
    scene.frame_set(LAST)
    assert all(np.abs(world_vertices(agents[a]) - before[a]).max() > 1e-3 for a in before)


def test_a_stitched_shot_imports_every_agent_animated_as_core(tmp_path, truth):
    """A farm's output: the shot in three chunks (the first whole, the others
    animation-only), stitched, with the Blender layout. Blender's importer reads the
    first chunk's agents through the stitched stage, the shared agents' streams through
    value clips over the chunks' layers under a layer offset, and every other agent's
    clips across the chunk boundaries: every agent at every frame is core's."""
    from usd.test_stitch import export_chunks

    from crowd_addon.usd.stitch import stitch

    _, chunks = export_chunks(tmp_path, layout="blender")
    agents = import_agents(stitch(chunks, tmp_path / "stitched.usdc").path)
    assert sorted(agents) == list(range(N))
    worst = assert_plays_as_core(agents, truth)
    print(f"worst vertex error {worst:.2e} m over {LAST - FIRST + 1} frames x {N} agents")


def test_samples_between_frames_import_as_core_between_frames(tmp_path):
    """``--substeps 4``: Blender's importer keys the sub-frame samples, and the mesh it
    evaluates at ``F + k / 4`` (``frame_set(F, subframe=k / 4)``) is core's pose at that
    time, across the shot's clip switches. Agents that stand still: a moving agent's
    transform has whole-frame samples, which Blender interpolates (docs/usd_export.md)."""
    from crowd_addon.core import Crowd
    from crowd_addon.core.shots.recorder import record
    from crowd_addon.usd import export_crowd
    from usd.conftest import core_samples, simulate

    n = 4
    path = export_crowd(record(Crowd(make_config(), skinning="gpu", substeps=n), FIRST,
                               LAST, before_step=simulate), tmp_path / "blur.usdc",
                        layout="blender").path
    truth = {key: {"poses": {0: p}, "position": {0: pos}, "heading": {0: head}}
             for key, (p, pos, head) in core_samples(n).items()}
    agents = import_agents(path)
    scene = bpy.context.scene
    worst, moved = 0.0, 0.0
    for frame in range(FIRST, LAST):
        for k in range(1, n):
            scene.frame_set(frame, subframe=k / n)
            for a in sorted(set(agents) - MOVING):
                got = world_vertices(agents[a])
                err = float(np.abs(got - core_vertices(truth[frame, k], 0, a)).max())
                assert err < TOLERANCE, (a, frame, k, err)
                worst = max(worst, err)
                whole = core_vertices(truth[frame, 0], 0, a)
                moved = max(moved, float(np.abs(got - whole).max()))
    assert moved > 1e-2          # between frames they are not their frames' poses
    print(f"worst vertex error between frames {worst:.2e} m")


def test_instanced_layout_is_what_blender_does_not_animate(exported, truth):
    """The control: Blender imports instanceable agents without their skeletons' motion
    (why the Blender layout exists); if a Blender release fixes this, this test says so."""
    agents = import_agents(exported["instanced"])
    scene = bpy.context.scene
    still = []
    for a in sorted(set(range(N)) - MOVING)[:6]:
        scene.frame_set(FIRST)
        v0 = world_vertices(agents[a])
        scene.frame_set(LAST)
        still.append(np.abs(world_vertices(agents[a]) - v0).max() < 1e-6)
    assert all(still)


def test_variants_and_props_import_as_core_skins_them(tmp_path, truth):
    """Mesh variants and props (:mod:`crowd_addon.core.meshes.bodies`) through Blender's USD
    importer: each agent imports its own body -- its variant's mesh, and a mesh per
    prop it carries, which Blender moves rigidly with the prop's joint (the constant
    joint binding) -- vertex for vertex where core's skinning puts them."""
    from crowd_addon.core.meshes.bodies import crowd_bodies
    from crowd_addon.core.authoring.synthetic import box_prop, humanoid_mesh
    from crowd_addon.usd import export_crowd

    cfg = make_config()
    fan = cfg.skeletons["fan"]
    cfg.add_variant(humanoid_mesh(fan, sides=5, rings=3, name="fan_slim"), lods=())
    cfg.add_prop(box_prop(fan, "hand.L", "flag", (0.04, 0.04, 0.4), (0.0, 0.0, 0.2)))
    cfg.add_prop(box_prop(fan, "head", "cap", (0.22, 0.22, 0.06), (0.0, 0.0, 0.24)))
    skel = [cfg.streams[s].skeleton if s >= 0 else cfg.uniques[u].skeleton
            for s, u in zip(cfg.agent_stream, cfg.agent_unique)]
    is_fan = np.array([k == "fan" for k in skel])
    ids = np.arange(cfg.agent_count)
    cfg.agent_variant = np.where(is_fan, ids % 2, 0).astype(np.int16)
    cfg.agent_props = np.where(is_fan, ids % 4, 0).astype(np.uint8)
    path = export_crowd(recording(cfg), tmp_path / "dressed.usdc", layout="blender").path
    bodies, agent_body = crowd_bodies(cfg, [list(cfg.skeletons).index(k) for k in skel])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=str(path))
    parts = {}
    for obj in bpy.data.objects:
        if obj.type == "MESH":
            holder = obj
            while not holder.name.startswith("agent_"):
                holder = holder.parent
            parts.setdefault(int(holder.name.split("_")[1].split(".")[0]), {})[
                obj.data.name.split(".")[0]] = obj
    scene = bpy.context.scene
    for frame in (FIRST, (FIRST + LAST) // 2, LAST):
        scene.frame_set(frame)
        for a in range(N):
            name = skel[a]
            variant = cfg.mesh_variants(name)[int(cfg.variant_ids[a])][0]
            props = [p for j, p in enumerate(cfg.props.get(name, ()))
                     if cfg.prop_masks[a] >> j & 1]
            assert sorted(parts[a]) == sorted([variant.name] + [p.mesh.name for p in props])
            assert bodies[agent_body[a]].name == "+".join([variant.name] +
                                                          [p.name for p in props])
            pose = truth["poses"][frame][a:a + 1]
            rows = skinning_matrices(pose, cfg.skeletons[name])
            c, s_ = np.cos(truth["heading"][frame][a]), np.sin(truth["heading"][frame][a])
            rot = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
            for mesh in [variant] + [p.mesh for p in props]:
                v = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                                  rows)[0] * float(cfg.scales[a])
                want = v @ rot.T + truth["position"][frame][a]
                err = float(np.abs(world_vertices(parts[a][mesh.name]) - want).max())
                assert err < TOLERANCE, (a, mesh.name, frame, err)
