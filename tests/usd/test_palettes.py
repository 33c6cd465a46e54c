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
from crowd_addon.core.mesh import Look
from crowd_addon.gpu.instances import InstanceData, pack_colors
from crowd_addon.usd import export_crowd

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


def test_each_agent_reads_its_palette_colour(stage):
    cfg = palette_config()
    crowd = Crowd(cfg, skinning="gpu")
    drawn = InstanceData(crowd.view).records[:, 2]          # what the GPU reads
    seen = 0
    for prim in Usd.PrimRange(stage.GetPrimAtPath("/Crowd/Agents"),
                              Usd.TraverseInstanceProxies()):
        if not prim.IsA(UsdGeom.Mesh) or UsdGeom.Imageable(prim).GetPurposeAttr().Get() \
                == "proxy":
            continue
        agent = int(prim.GetParent().GetName().split("_")[1])
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
