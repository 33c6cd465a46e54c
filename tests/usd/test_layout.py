"""The exported layout: validation, metadata, sharing of offset animations, which agents
get their own animation, instancing, event tags — checked against USD's validators
and core's own run of the same shot (conftest)."""

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdSkel, UsdValidation

from crowd_addon.core.runtime.agents import STREAM

from .conftest import DYNAMIC, FIRST, FAN_AGENTS, KID_AGENTS, LAST, MOVING, make_config

N = FAN_AGENTS + KID_AGENTS
M = 8


@pytest.fixture(scope="module")
def stage(shot):
    return Usd.Stage.Open(str(shot[1]))


def agent_prim(stage, a):
    return stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}")


def animation_source(stage, a):
    (target,) = UsdSkel.BindingAPI(agent_prim(stage, a)).GetAnimationSourceRel().GetTargets()
    return target


def usdchecker(stage):
    """What ``usdchecker`` (the validation framework) reports: every registered
    validator except the usdz-package ones, as usdchecker runs for a non-usdz file."""
    reg = UsdValidation.ValidationRegistry()
    names = [m.name for m in reg.GetAllValidatorMetadata()
             if "UsdzValidators" not in m.GetKeywords()
             and m.name != "usdUtilsValidators:RootPackageValidator"]
    ctx = UsdValidation.ValidationContext(reg.GetOrLoadValidatorsByName(names))
    return [e.GetErrorAsString() for e in ctx.Validate(stage)]


def test_usdchecker_passes(shot, stage):
    assert usdchecker(stage) == []
    layers = shot[1].parent / "shot.layers" / "v1"
    for character in sorted((layers / "characters").iterdir()):
        assert usdchecker(Usd.Stage.Open(str(character))) == []


def test_usdchecker_would_notice_a_broken_binding(shot, tmp_path):
    """Control: the same checker flags a skinned mesh without SkelBindingAPI."""
    copy = tmp_path / "fan.usda"
    copy.write_bytes((shot[1].parent / "shot.layers/v1/characters/fan.usda").read_bytes())
    bad = Usd.Stage.Open(str(copy))
    mesh = next(p for p in bad.Traverse() if p.IsA(UsdGeom.Mesh))
    mesh.RemoveAPI(UsdSkel.BindingAPI)
    assert usdchecker(bad) != []


def test_every_layer_shares_units_axis_and_time(shot):
    result, path = shot
    assert set(result.files) == {
        "shot.usda", "shot.layers/v1/agents.usda", "shot.layers/v1/layout.usda",
        "shot.layers/v1/characters/fan.usda",
        "shot.layers/v1/characters/kid.usda", "shot.layers/v1/streams/idle.usda",
        "shot.layers/v1/streams/cheer_loud.usda", "shot.layers/v1/streams/wave.usda",
        "shot.layers/v1/streams/kid_play.usda", "shot.layers/v1/uniques/solo.usda",
        "shot.layers/v1/blends/fan_0.usda", "shot.layers/v1/manifest.usda"}
    for name, size in result.files.items():
        file = path.parent / name
        assert file.stat().st_size == size
        layer = Sdf.Layer.FindOrOpen(str(file))
        assert layer.timeCodesPerSecond == layer.framesPerSecond == 30
        assert layer.pseudoRoot.GetInfo("metersPerUnit") == 1.0
        assert layer.pseudoRoot.GetInfo("upAxis") == "Z"
    assert not [p for p in path.parent.iterdir() if p.name.startswith(".")]


def test_stage_metadata_holds_crowd_settings(stage):
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (FIRST, LAST)
    crowd = stage.GetRootLayer().customLayerData["crowd"]
    assert (crowd["M"], crowd["NT"], crowd["fps"], crowd["seed"]) == (M, 3, 30.0, 5)
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/Crowd")


def test_static_agents_share_one_offset_animation_per_key(stage, oracle):
    first = oracle["animation"][FIRST]
    static = [a for a in range(N) if a not in DYNAMIC]
    by_key = {}
    for a in static:
        kind, ref, off = first[a]
        assert kind == STREAM
        by_key.setdefault((ref, off), set()).add(animation_source(stage, a))
    assert all(len(targets) == 1 for targets in by_key.values())
    targets = [next(iter(t)) for t in by_key.values()]
    assert len(set(targets)) == len(targets)                      # one prim per key
    offsets = [p for p in stage.Traverse()
               if p.GetPath().HasPrefix("/Crowd/Streams") and p.IsA(UsdSkel.Animation)]
    assert sorted(p.GetPath() for p in offsets) == sorted(targets)
    assert len(offsets) < len(static)
    for (ref, off), (target,) in by_key.items():
        prim = stage.GetPrimAtPath(target)
        (arc,) = prim.GetPrimIndex().rootNode.children
        assert arc.mapToRoot.Evaluate().timeOffset == Sdf.LayerOffset(float(off), 1.0)
        assert prim.GetCustomDataByKey("crowd:streamIndex") == ref


def test_exactly_the_agents_that_change_get_their_own_animation(shot, stage, oracle):
    frames = np.stack([oracle["animation"][f] for f in range(FIRST, LAST + 1)])
    changing = {a for a in range(N) if (frames[:, a] != frames[0, a]).any()
                or frames[0, a, 0] != STREAM}
    assert changing == DYNAMIC
    own = {a for a in range(N)
           if animation_source(stage, a).HasPrefix("/Crowd/AgentAnimations")}
    assert own == DYNAMIC
    assert shot[0].clip_agents == len(DYNAMIC)
    assert shot[0].shared_agents == N - len(DYNAMIC)


def test_agents_are_instances_of_two_characters(stage):
    assert all(agent_prim(stage, a).IsInstance() for a in range(N))
    assert len(stage.GetPrototypes()) == 2
    for a, character in ((0, "fan"), (FAN_AGENTS, "kid")):
        (ref,) = next(s for s in agent_prim(stage, a).GetPrimStack()      # the layout's
                      if s.referenceList.prependedItems).referenceList.prependedItems
        assert ref.assetPath == f"./characters/{character}.usda"     # from layout.usda


def test_only_moving_agents_have_time_sampled_transforms(stage):
    sampled = {a for a in range(N)
               if UsdGeom.Xformable(agent_prim(stage, a)).TransformMightBeTimeVarying()}
    assert sampled == MOVING


def test_stream_event_tags_are_what_agents_receive(stage, oracle):
    """customData (name, frame) on a stream, shifted by an agent's offset, is exactly
    the set of events core delivers to that agent in the shot."""
    first = oracle["animation"][FIRST]
    checked = 0
    for a in range(N):
        if a in DYNAMIC:
            continue
        data = stage.GetPrimAtPath(animation_source(stage, a)).GetCustomData()["crowd"]
        off = int(first[a, 2])
        expected = {(name, int(f) + off) for name, f in
                    zip(data["eventNames"], data["eventFrames"]) if FIRST <= f + off <= LAST}
        got = {(n, f) for agent, n, f in oracle["events"] if agent == a}
        assert got == expected, a
        checked += bool(got)
    assert checked > 10


def test_stream_layers_cover_every_offset(shot):
    path = shot[1].parent / "shot.layers/v1/streams/idle.usda"
    layer = Sdf.Layer.FindOrOpen(str(path))
    times = layer.ListTimeSamplesForPath("/Animation.rotations")
    assert (min(times), max(times), len(times)) == (FIRST - M + 1, LAST, LAST - FIRST + M)


def test_the_result_lists_the_events_the_agents_heard(shot, oracle):
    from collections import Counter
    got = Counter({(name, frame): n for name, frame, n in shot[0].events})
    expected = Counter((name, frame) for _agent, name, frame in oracle["events"])
    assert got == expected and sum(got.values()) > 20


def test_each_agent_colour_reaches_its_mesh_as_an_inherited_primvar(stage):
    """``primvars:displayColor`` on the agent (constant) is what its instanced mesh
    inherits: the crowd's per-agent colour, as render delegates read it."""
    colors = make_config().agent_color
    for a in (0, 7, 39, FAN_AGENTS, N - 1):
        agent = agent_prim(stage, a)
        (mesh,) = [p for p in Usd.PrimRange(agent, Usd.TraverseInstanceProxies())
                   if p.IsA(UsdGeom.Mesh)]
        primvar = UsdGeom.PrimvarsAPI(mesh).FindPrimvarWithInheritance("displayColor")
        assert primvar.GetInterpolation() == UsdGeom.Tokens.constant
        np.testing.assert_array_equal(np.array(primvar.Get())[0], colors[a])
