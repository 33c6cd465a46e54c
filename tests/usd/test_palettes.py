"""Palette colours in the USD (docs/variety.md): each agent's colour for a palette
material is the constant primvar ``crowdPalette<column>`` on the agent, which the
character's material for that look reads through a ``UsdPrimvarReader_float3`` (the
look's own colour its fallback). Read back with pxr: the primvar each agent's mesh
inherits (through its instance) is the colour the crowd draws, the agent texture's
packed colour included."""

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdShade

from crowd_addon.core import Crowd
from crowd_addon.core.meshes.mesh import Look, tint_weight, tinted
from crowd_addon.gpu.instances import InstanceData, pack_colors
from crowd_addon.usd import export_crowd
from crowd_addon.usd.character import tint_primvar

from .conftest import FAN_AGENTS, make_config, recording
from .test_looks import dressed

SHIRT, SKIN = Look("shirt", (0.9, 0.9, 0.9, 1.0)), Look("skin", (0.8, 0.5, 0.35, 1.0))
RED, BLUE = (0.9, 0.1, 0.1), (0.1, 0.2, 0.9)


def palette_config():
    cfg = make_config()
    cfg.meshes["fan"] = [dressed(cfg.meshes["fan"][0], (SHIRT, SKIN))]
    n = cfg.agent_count
    pal = np.full((n, 4, 3), -1.0, np.float32)
    fans = np.arange(FAN_AGENTS)
    pal[fans, 1] = np.where(fans[:, None] % 2 == 0, RED, BLUE)      # column 1: the shirt
    cfg.agent_palette = pal
    cfg.palette_materials = {"fan": ("hat", "shirt")}              # column 0: not worn
    return cfg


@pytest.fixture(scope="module")
def stage(tmp_path_factory):
    path = tmp_path_factory.mktemp("palettes") / "shot.usda"
    result = export_crowd(recording(palette_config()), path)
    return Usd.Stage.Open(str(result.path))


def agent_meshes(stage):
    """(agent index, its render mesh prim) for every agent mesh of ``stage`` (through
    the instances; proxies left out)."""
    for prim in Usd.PrimRange(stage.GetPrimAtPath("/Crowd/Agents"),
                              Usd.TraverseInstanceProxies()):
        if prim.IsA(UsdGeom.Mesh) and UsdGeom.Imageable(prim).GetPurposeAttr().Get() \
                != "proxy":
            yield int(prim.GetParent().GetName().split("_")[1]), prim


def test_each_agent_reads_its_palette_colour(stage):
    cfg = palette_config()
    crowd = Crowd(cfg, skinning="gpu")
    drawn = InstanceData(crowd.view).records[:, 2]          # what the GPU reads
    seen = 0
    for agent, prim in agent_meshes(stage):
        found = UsdGeom.PrimvarsAPI(prim).FindPrimvarWithInheritance("crowdPalette1")
        if agent < FAN_AGENTS:
            colour = np.array(found.Get(), np.float64)
            np.testing.assert_allclose(colour, RED if agent % 2 == 0 else BLUE, atol=1e-6)
            np.testing.assert_allclose(colour, crowd.agents.palette[agent, 1], atol=1e-7)
            assert drawn[agent, 1] == pack_colors(colour[None])[0]
            assert not UsdGeom.PrimvarsAPI(prim).FindPrimvarWithInheritance(
                "crowdPalette0").IsDefined()
            seen += 1
        else:                                              # kids have no palette
            assert not found.IsDefined() and (drawn[agent] == -1).all()
    assert seen == FAN_AGENTS


def test_the_palette_material_reads_the_primvar(stage):
    layer_root = None
    for layer in stage.GetUsedLayers():
        if "characters/fan" in layer.identifier:
            layer_root = Usd.Stage.Open(layer)
    assert layer_root is not None
    shirt = UsdShade.Material(layer_root.GetPrimAtPath("/fan/Looks/shirt"))
    surface = UsdShade.Shader(layer_root.GetPrimAtPath("/fan/Looks/shirt/PreviewSurface"))
    (source,) = surface.GetInput("diffuseColor").GetConnectedSources()[0]
    reader = UsdShade.Shader(source.source.GetPrim())
    assert reader.GetIdAttr().Get() == "UsdPrimvarReader_float3"
    assert reader.GetInput("varname").Get() == "crowdPalette1"
    np.testing.assert_allclose(reader.GetInput("fallback").Get(), SHIRT.color[:3], atol=1e-6)
    skin = UsdShade.Shader(layer_root.GetPrimAtPath("/fan/Looks/skin/PreviewSurface"))
    assert not skin.GetInput("diffuseColor").HasConnectedSource()
    assert shirt


def test_grey_looks_take_each_agents_tint(tmp_path):
    """Without a palette on it, the grey shirt takes each agent's colour as the GPU
    draws it (``tinted``: 0.9 x the agent's colour), through the constant primvar
    ``crowdTint_shirt`` on the agent, which the shirt's material reads (the look's
    colour its fallback); the saturated skin keeps its own colour and gets none.
    Before, the export carried the agent's colour only as ``displayColor``, which
    materials ignore: every shirt rendered grey."""
    cfg = make_config()
    cfg.meshes["fan"] = [dressed(cfg.meshes["fan"][0], (SHIRT, SKIN))]
    n = cfg.agent_count
    cfg.agent_color = np.where((np.arange(n) % 2 == 0)[:, None], RED, BLUE).astype(np.float32)
    stage = Usd.Stage.Open(str(export_crowd(recording(cfg), tmp_path / "shot.usda").path))
    crowd = Crowd(cfg)
    assert tint_primvar("shirt") == "crowdTint_shirt"
    seen = 0
    for agent, prim in agent_meshes(stage):
        api = UsdGeom.PrimvarsAPI(prim)
        found = api.FindPrimvarWithInheritance("crowdTint_shirt")
        if agent < FAN_AGENTS:
            colour = np.array(found.Get(), np.float64)
            np.testing.assert_allclose(colour, 0.9 * np.array(RED if agent % 2 == 0 else BLUE),
                                       atol=1e-6)
            np.testing.assert_allclose(colour, tinted(SHIRT.color, crowd.agents.color[agent]),
                                       atol=1e-7)
            assert not api.FindPrimvarWithInheritance("crowdTint_skin").IsDefined()
            seen += 1
        else:                                              # kids wear no looks
            assert not found.IsDefined()
    assert seen == FAN_AGENTS
    character = next(Usd.Stage.Open(layer) for layer in stage.GetUsedLayers()
                     if "characters/fan" in layer.identifier)
    surface = UsdShade.Shader(character.GetPrimAtPath("/fan/Looks/shirt/PreviewSurface"))
    (source,) = surface.GetInput("diffuseColor").GetConnectedSources()[0]
    reader = UsdShade.Shader(source.source.GetPrim())
    assert reader.GetInput("varname").Get() == "crowdTint_shirt"
    np.testing.assert_allclose(reader.GetInput("fallback").Get(), SHIRT.color[:3], atol=1e-6)
    skin = UsdShade.Shader(character.GetPrimAtPath("/fan/Looks/skin/PreviewSurface"))
    assert not skin.GetInput("diffuseColor").HasConnectedSource()


def test_tint_weight_is_the_previews_rule():
    """Grey and white take the tint fully, saturation 0.25 and above not at all, and
    linearly between (what gpu_shaders/crowd_vertex.glsl's agent_tint computes)."""
    np.testing.assert_allclose(tint_weight([(1, 1, 1), (0.5, 0.5, 0.5), (0.8, 0.5, 0.35),
                                            (1.0, 0.9, 0.9)]), [1, 1, 0, 0.6], atol=1e-12)
    assert tint_primvar("Fan Shirt.001") != tint_primvar("Fan_Shirt_001")
    assert tint_primvar("Fan Shirt.001").startswith("crowdTint_Fan_Shirt_001_")


def test_the_blender_layout_puts_each_agents_colours_on_its_meshes(tmp_path):
    """The ``blender`` layout (for Blender's importer, which reads only the primvars on
    a mesh prim itself, and constant ones only as arrays) gives each agent mesh, the
    proxy too, the colours the ``instanced`` layout gives the agent: a tinted shirt, a
    palette skin and displayColor, as one-element arrays of the same values, and
    nothing on the agent prim."""
    cfg = make_config()
    cfg.meshes["fan"] = [dressed(cfg.meshes["fan"][0], (SHIRT, SKIN))]
    n = cfg.agent_count
    cfg.agent_color = np.where((np.arange(n) % 2 == 0)[:, None], RED, BLUE).astype(np.float32)
    cfg.agent_palette = np.full((n, 4, 3), -1.0, np.float32)
    cfg.agent_palette[:FAN_AGENTS, 0] = np.linspace(0.2, 0.8, FAN_AGENTS)[:, None]
    cfg.palette_materials = {"fan": ("skin",)}
    rec = recording(cfg)
    stages = {layout: Usd.Stage.Open(str(export_crowd(
        rec, tmp_path / f"{layout}.usda", layout=layout).path))
        for layout in ("instanced", "blender")}
    names = ("displayColor", "crowdPalette0", "crowdTint_shirt")
    want = {}
    for agent, prim in agent_meshes(stages["instanced"]):
        api = UsdGeom.PrimvarsAPI(prim)
        found = {k: api.FindPrimvarWithInheritance(k) for k in names}
        want[agent] = {k: p.Get() if p.IsDefined() else None for k, p in found.items()}
    assert all(v["crowdTint_shirt"] is not None for a, v in want.items() if a < FAN_AGENTS)
    seen = 0
    for prim in stages["blender"].Traverse():
        if prim.GetParent().GetName().startswith("agent_"):
            agent = int(prim.GetParent().GetName().split("_")[1])
            on_agent = UsdGeom.PrimvarsAPI(prim.GetParent())
            assert not [k for k in names if on_agent.GetPrimvar(k).IsDefined()]
        if not prim.IsA(UsdGeom.Mesh):
            continue
        api = UsdGeom.PrimvarsAPI(prim)
        for name in names:
            primvar = api.GetPrimvar(name)          # on the mesh itself
            if want[agent][name] is None:
                assert not primvar.IsDefined(), (prim.GetPath(), name)
                continue
            value = primvar.Get()
            assert primvar.GetInterpolation() == "constant" and len(value) == 1
            np.testing.assert_allclose(np.array(value[0]), np.ravel(want[agent][name])[:3],
                                       atol=0)
        seen += 1
    assert seen >= n
