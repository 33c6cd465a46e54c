"""*Import Crowd USD* (``bpy.ops.crowd.import_usd``): a ``--layout blender`` stage
plays in Blender as the crowd did (issue 35, item 5).

The shot is the USD tests' (tests/usd/conftest.py: two characters, streams, a unique,
blends, a queue, a cut, moving agents, at 30 fps) with two looks on each body, a grey
shirt the agents' colours tint and a skin. It is imported with the operator into a
scene at Blender's default 24 fps that already holds a material named like a look
(the crowd's template). Oracles: ``pxr`` for the stage's clock and range, core's
skinning for every agent's evaluated mesh at every frame, Blender's data for the
materials. Before, Blender's importer left the scene at 24 fps (the crowd played at
0.8x) and made each agent its own copy of every look.
"""

import dataclasses
import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("pxr")
from pxr import Usd  # noqa: E402
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import crowd_scene as cs  # noqa: E402
from test_usd_import import assert_plays_as_core, imported_agents  # noqa: E402
from usd.conftest import FIRST, LAST, core_truth, make_config, recording  # noqa: E402

from crowd_addon.core.meshes.mesh import Look  # noqa: E402

LOOKS = (Look("Shirt", (0.9, 0.9, 0.9, 1.0)), Look("Skin", (0.8, 0.5, 0.3, 1.0)))

extension = cs.extension_fixture()


def dressed_config():
    """The USD tests' configuration, each body wearing the two looks (alternate
    triangles): the same vertices, so core's skinning of it is theirs."""
    cfg = make_config()
    for meshes in cfg.meshes.values():
        mesh = meshes[0]
        meshes[0] = dataclasses.replace(
            mesh, material=(np.arange(len(mesh.triangles)) % 2).astype(np.uint16),
            looks=LOOKS)
    return cfg


@pytest.fixture(scope="module")
def stages(tmp_path_factory):
    from crowd_addon.usd import export_crowd
    folder = tmp_path_factory.mktemp("import")
    rec = recording(dressed_config())
    return {layout: export_crowd(rec, folder / f"{layout}.usdc", layout=layout).path
            for layout in ("blender", "instanced")}


@pytest.fixture(scope="module")
def truth():
    return core_truth()


def fresh_scene():
    """An empty scene at Blender's defaults (24 fps, frames 1-250) holding the crowd's
    template material "Shirt", which reads no agent colour."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    assert (scene.render.fps, scene.render.fps_base) == (24, 1.0)
    template = bpy.data.materials.new("Shirt")
    return scene, template


def test_the_imported_crowd_plays_at_the_stages_rate_sharing_one_material_per_look(
        stages, truth):
    stage = Usd.Stage.Open(str(stages["blender"]))
    scene, template = fresh_scene()
    assert bpy.ops.crowd.import_usd(filepath=str(stages["blender"])) == {"FINISHED"}
    # the clock: the scene's frame rate is the stage's, its range the stage's
    assert scene.render.fps / scene.render.fps_base == pytest.approx(
        stage.GetTimeCodesPerSecond(), abs=1e-9)
    assert stage.GetTimeCodesPerSecond() == 30.0
    assert (scene.frame_start, scene.frame_end) == (stage.GetStartTimeCode(),
                                                    stage.GetEndTimeCode()) == (FIRST, LAST)
    # one material per look, shared by every agent; the template kept and not worn
    agents = imported_agents()
    n = len(make_config().agent_stream)
    assert sorted(agents) == list(range(n))
    worn = {m for obj in agents.values() for m in obj.data.materials}
    assert len(worn) == len(LOOKS) and template not in worn
    assert sorted(m.name for m in worn) == ["Shirt.001", "Skin"]
    assert template.name == "Shirt"
    assert len(bpy.data.materials) == len(LOOKS) + 1
    for obj in agents.values():
        assert [m.name for m in obj.data.materials] == ["Shirt.001", "Skin"]
    # and every agent where core's skinning puts it, at every frame of the shot
    worst = assert_plays_as_core(agents, truth)
    print(f"worst vertex error {worst:.2e} m")


def test_without_sharing_blenders_default_copies_every_look_per_agent(stages):
    """The control: the importer's own default (what the operator's option turns
    off) makes an agent's own copy of each look."""
    scene, _ = fresh_scene()
    assert bpy.ops.crowd.import_usd(filepath=str(stages["blender"]), shared_materials=False,
                                    scene_timing=False) == {"FINISHED"}
    agents = imported_agents()
    worn = {m for obj in agents.values() for m in obj.data.materials}
    assert len(worn) == len(agents) * len(LOOKS)
    assert (scene.render.fps, scene.frame_start, scene.frame_end) == (24, 1, 250)


def test_an_instanced_stage_is_imported_with_a_warning(stages):
    from crowd_addon.blender.import_usd import import_crowd
    fresh_scene()
    result = import_crowd(bpy.context, stages["instanced"])
    assert result.layout == "instanced" and result.frames == (FIRST, LAST)
    assert any("instanced layout" in note and "--layout blender" in note
               for note in result.notes)


def test_no_stage_is_refused_and_nothing_changes(tmp_path):
    scene, template = fresh_scene()
    (tmp_path / "not.usdc").write_text("not a stage")
    for path, message in ((tmp_path / "missing.usdc", "no such USD file"),
                          (tmp_path / "not.usdc", "not a readable USD layer"),
                          (tmp_path / "shot.abc", "ends in .usdc, .usd, .usda")):
        with pytest.raises(RuntimeError, match="Crowd import: .*" + message):
            bpy.ops.crowd.import_usd(filepath=str(path))
    assert [o.name for o in bpy.data.objects] == [] and template.name == "Shirt"
    assert scene.render.fps == 24


@pytest.mark.parametrize("fps, rate", [(30.0, (30, 1.0)), (29.97, (30, 30 / 29.97)),
                                       (23.976, (24, 24 / 23.976)), (120.0, (120, 1.0))])
def test_scene_rate_is_the_stages_rate_exactly(fps, rate):
    from crowd_addon.blender.import_usd import scene_rate
    got = scene_rate(fps)
    assert got[0] == rate[0] and got[1] == pytest.approx(rate[1])
    assert got[0] / got[1] == pytest.approx(fps, abs=1e-9)


def test_file_import_menu_and_the_crowd_panel_offer_the_operator():
    from types import SimpleNamespace

    from crowd_addon.blender import import_usd, panels, registration

    class Layout:
        def __init__(self, ops):
            self.ops = ops

        def operator(self, idname, **kw):
            self.ops.append((idname, kw.get("text")))
            return SimpleNamespace()

        def __getattr__(self, name):
            return lambda *a, **kw: Layout(self.ops)
    menu = SimpleNamespace(layout=Layout([]))
    import_usd.menu_import(menu, bpy.context)
    assert menu.layout.ops == [("crowd.import_usd", "Crowd (.usd)")]
    assert ("TOPBAR_MT_file_import", import_usd.menu_import) in registration.MENUS
    bpy.ops.wm.read_factory_settings(use_empty=True)
    panel = SimpleNamespace(layout=Layout([]))
    panels.CROWD_PT_main.draw(panel, bpy.context)
    assert ("crowd.import_usd", "Import USD...") in panel.layout.ops
    menu = bpy.types.TOPBAR_MT_file_import
    assert [f.__qualname__ for f in menu._dyn_ui_initialize()
            if f.__module__ == import_usd.__name__] == ["menu_import"]
