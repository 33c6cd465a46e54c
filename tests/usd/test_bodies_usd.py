"""Mesh variants and props in the USD export: one character layer per body used,
each agent referencing its body's layer, a prop as a Mesh of its own bound rigidly to
its joint. Read back with pxr (composition through the instances, UsdSkel's own
skinning) and compared with core: the body each agent has in the running crowd
(``crowd.view.bodies[crowd.view.agent_body[i]]``), and core's CPU skinning of the
body's and the props' meshes with the poses of the same crowd driven by the same
simulation (conftest's shot)."""

from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdSkel

from crowd_addon.core import Crowd
from crowd_addon.core.authoring.placement import CharacterStreams, PlacementPolicy, place_agents
from crowd_addon.core.base.skinning import skin_vertices, skinning_matrices
from crowd_addon.core.authoring.synthetic import box_prop, humanoid_mesh
from crowd_addon.usd import export_crowd

from .conftest import FIRST, LAST, make_config, recording, simulate
from .test_readback import agent_matrix

SEED = 11
FRAMES = (FIRST, 7, LAST)                 # before, among and after the shot's changes
TOL = 1e-4                                 # metres
PROPS = {"fan": ("flag", "cap"), "kid": ("ball",)}


def bodies_config(seed=SEED):
    """conftest's shot (40 fans, 6 kids, every kind of agent) with a second fan body
    "slim" and props (fan: flag in the left hand, cap; kid: ball in the left hand),
    each agent's variant and props drawn by the placement policy with ``seed``."""
    cfg = make_config()
    fan, kid = cfg.skeletons["fan"], cfg.skeletons["kid"]
    cfg.add_variant(humanoid_mesh(fan, sides=5, name="slim"), lods=())
    cfg.add_prop(box_prop(fan, "hand.L", "flag", size=(0.03, 0.03, 0.7), offset=(0, 0, 0.25)))
    cfg.add_prop(box_prop(fan, "head", "cap", size=(0.22, 0.22, 0.06), offset=(0, 0, 0.21)))
    cfg.add_prop(box_prop(kid, "hand.L", "ball", size=(0.15, 0.15, 0.15)))
    n = cfg.agent_count
    character = (np.asarray(cfg.agent_stream) == 3).astype(np.int64)      # "kid play"
    cast = (CharacterStreams("fan", ("idle", "cheer.loud", "wave"), variant_weights=(1, 1),
                             prop_shares=(0.5, 0.4)),
            CharacterStreams("kid", ("kid play",), prop_shares=(0.5,)))
    placed = place_agents("test", cfg.agent_position, cfg.agent_heading,
                          PlacementPolicy(character_mode="ATTRIBUTE"), characters=cast,
                          max_offset=cfg.max_offset, seed=seed,
                          attribute=lambda name, kind: character)
    assert placed.count == n
    cfg.agent_variant, cfg.agent_props = placed.variants, placed.props
    return cfg


def body_file(cfg, body):
    """The layer a body's agents reference, from the naming rule
    ``characters/<skeleton>[_<variant mesh>][_<prop>...]``."""
    skeleton = list(cfg.skeletons)[body.skeleton]
    parts = [skeleton]
    if body.variant:
        parts.append(cfg.mesh_variants(skeleton)[body.variant][0].name)
    parts += [cfg.props[skeleton][j].name for j in body.prop_ids]
    return "_".join(parts)


def export(tmp_path_factory, name, cfg, frames=(FIRST, LAST)):
    path = tmp_path_factory.mktemp(name) / "shot.usda"
    result = export_crowd(recording(cfg, frames), path, repetition=None)
    return result, Usd.Stage.Open(str(result.path))


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    return export(tmp_path_factory, "bodies", bodies_config())


@pytest.fixture(scope="module")
def crowd():
    """The crowd the shot was recorded from, as the preview shows it."""
    return Crowd(bodies_config(), skinning="gpu")


def agent_prim(stage, a):
    return stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}")


def reference(stage, a):
    (ref,) = next(s for s in agent_prim(stage, a).GetPrimStack()      # the layout's
                  if s.referenceList.prependedItems).referenceList.prependedItems
    return ref.assetPath


def test_the_config_has_every_kind_of_body(crowd):
    names = {b.name for b in crowd.view.bodies}
    assert {"fan_body", "fan_body+flag", "fan_body+cap", "fan_body+flag+cap", "slim",
            "slim+flag", "slim+cap", "kid_body", "kid_body+ball"} <= names, names


def test_each_agent_references_the_layer_of_its_body(shot, crowd):
    result, stage = shot
    view, cfg = crowd.view, crowd.config
    used = set()
    for a in range(view.agent_count):
        body = view.bodies[view.agent_body[a]]
        name = body_file(cfg, body)
        assert reference(stage, a) == f"./characters/{name}.usda", (a, body.name)
        used.add(name)
    layers = {f.split("/")[-1][:-len(".usda")] for f in result.files if "/characters/" in f}
    assert layers == used                      # one layer per body used, no other
    assert len(stage.GetPrototypes()) == len(used)


def test_props_are_rigid_meshes_only_on_the_bodies_that_carry_them(shot, crowd):
    _, stage = shot
    view, cfg = crowd.view, crowd.config
    for a in range(view.agent_count):
        body = view.bodies[view.agent_body[a]]
        skeleton = list(cfg.skeletons)[body.skeleton]
        root = body_file(cfg, body)
        carried = {cfg.props[skeleton][j].name for j in body.prop_ids}
        for j, prop in enumerate(cfg.props[skeleton]):
            prim = stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}/{prop.name}")
            assert prim.IsValid() == (prop.name in carried), (a, body.name, prop.name)
            if not prim.IsValid():
                continue
            assert prim.IsInstanceProxy() and prim.IsA(UsdGeom.Mesh)
            binding = UsdSkel.BindingAPI(prim)
            idx, w = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
            assert idx.GetInterpolation() == "constant" and w.GetInterpolation() == "constant"
            assert list(idx.Get()) == [prop.bone] and list(w.Get()) == [1.0]
            np.testing.assert_allclose(np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get()),
                                       prop.mesh.positions, atol=1e-6)
        # the body mesh is its variant's
        mesh = cfg.mesh_variants(skeleton)[body.variant][0]
        points = stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}/{mesh.name}")
        assert points.IsA(UsdGeom.Mesh), (a, mesh.name)
        assert len(UsdGeom.Mesh(points).GetPointsAttr().Get()) == mesh.vertex_count
        # the character layer's root says which variant and props
        layer_root = [p for p in agent_prim(stage, a).GetPrimStack()
                      if p.layer.identifier.endswith(f"/characters/{root}.usda")]
        assert len(layer_root) == 1, (a, root)
        info = layer_root[0].customData["crowd"]
        assert info["skeleton"] == skeleton and info["mesh"] == mesh.name
        if body.variant or body.props:
            assert info["variant"] == body.variant
            assert list(info["props"]) == sorted(carried, key=[p.name for p in
                                                               cfg.props[skeleton]].index)
        else:
            assert "variant" not in info and "props" not in info


def core_poses(cfg, frames):
    """Core's local poses (N, B, 10), positions, headings and scales at ``frames``: the
    same crowd driven by the same simulation, skinned on the CPU."""
    crowd = Crowd(cfg)
    out = {}
    while crowd.frame < max(frames):
        simulate(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame in frames:
            a = crowd.view.agents
            out[crowd.frame] = (crowd.view.agent_poses(), np.array(a.position, np.float64),
                                np.array(a.heading, np.float64), np.array(a.scale, np.float64))
    return out


def test_usdskel_skins_bodies_and_props_as_core_does(shot, crowd):
    """Every agent, every skinned mesh (its body and its props), at several frames:
    UsdSkel's skinned points in world space against core's CPU skinning."""
    _, stage = shot
    view, cfg = crowd.view, crowd.config
    truth = core_poses(bodies_config(), FRAMES)
    cache, pred = UsdSkel.Cache(), Usd.TraverseInstanceProxies()
    props_checked = 0
    for a in range(view.agent_count):
        body = view.bodies[view.agent_body[a]]
        skeleton_name = list(cfg.skeletons)[body.skeleton]
        skeleton = cfg.skeletons[skeleton_name]
        meshes = {cfg.mesh_variants(skeleton_name)[body.variant][0].name:
                  cfg.mesh_variants(skeleton_name)[body.variant][0]}
        meshes.update({cfg.props[skeleton_name][j].name: cfg.props[skeleton_name][j].mesh
                       for j in body.prop_ids})
        root = UsdSkel.Root(agent_prim(stage, a))
        assert cache.Populate(root, pred)
        (binding,) = cache.ComputeSkelBindings(root, pred)
        query = cache.GetSkelQuery(binding.GetSkeleton())
        targets = {t.GetPrim().GetName(): t for t in binding.GetSkinningTargets()}
        assert set(targets) == set(meshes), (a, body.name, sorted(targets))
        for frame in FRAMES:
            poses, position, heading, scale = truth[frame]
            xf = UsdGeom.XformCache(frame)
            skel_to_world = np.array(xf.GetLocalToWorldTransform(
                binding.GetSkeleton().GetPrim())).T
            agent = agent_matrix(position[a], heading[a], scale[a])
            rows = skinning_matrices(poses[a:a + 1], skeleton)
            for name, mesh in meshes.items():
                target = targets[name]
                points = UsdGeom.Mesh(target.GetPrim()).GetPointsAttr().Get(frame)
                assert target.ComputeSkinnedPoints(query.ComputeSkinningTransforms(frame),
                                                   points, frame)
                usd = np.asarray(points, np.float64) @ skel_to_world[:3, :3].T + \
                    skel_to_world[:3, 3]
                core = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                                     rows)[0] @ agent[:3, :3].T + agent[:3, 3]
                err = float(np.abs(usd - core).max())
                assert err < TOL, (a, frame, name, err)
                if target.IsRigidlyDeformed():
                    props_checked += 1
                    bone = int(mesh.bone_indices[0, 0])
                    # the joint's world transform times its bind inverse, on the points
                    world = np.array(query.ComputeJointWorldTransforms(xf)).transpose(0, 2, 1)
                    m = skel_to_world @ world[bone] @ skeleton.inverse_bind[bone]
                    rigid = mesh.positions @ m[:3, :3].T + m[:3, 3]
                    assert float(np.abs(rigid - core).max()) < TOL, (a, frame, name)
    assert props_checked == len(FRAMES) * int(sum(
        bin(int(view.bodies[b].props)).count("1") for b in view.agent_body))
    assert props_checked > 0


def test_the_same_seed_exports_the_same_bodies_and_another_seed_does_not(shot,
                                                                        tmp_path_factory):
    """Two configurations built with the same seed export the same references (and the
    same character layers, byte for byte); another seed's draw differs."""
    result, stage = shot
    again, stage2 = export(tmp_path_factory, "again", bodies_config(SEED), (FIRST, FIRST + 2))
    n = bodies_config().agent_count
    refs = [reference(stage, a) for a in range(n)]
    assert [reference(stage2, a) for a in range(n)] == refs
    chars = sorted(f for f in result.files if "/characters/" in f)
    assert sorted(f for f in again.files if "/characters/" in f) == chars
    for f in chars:
        assert (Path(result.path).parent / f).read_bytes() == \
            (Path(again.path).parent / f).read_bytes(), f
    other_cfg = bodies_config(SEED + 1)
    _, stage3 = export(tmp_path_factory, "other", other_cfg, (FIRST, FIRST + 2))
    other = [reference(stage3, a) for a in range(n)]
    assert sum(x != y for x, y in zip(other, refs)) > n // 4
    view = Crowd(other_cfg, skinning="gpu").view
    assert other == [f"./characters/"
                     f"{body_file(other_cfg, view.bodies[view.agent_body[a]])}.usda"
                     for a in range(n)]
