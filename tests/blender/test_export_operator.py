"""The *Export Crowd USD* operator (``crowd.export_usd``): the Crowd panel button and
File > Export > Crowd (.usd).

Oracles: pxr reads the written stage back (one instanced agent ``SkelRoot`` per seat
vertex of the scene's agent source, each placed on its seat; the stage's time range
and rate are the scene's), Blender's error reports (``bpy.ops`` raises them as
RuntimeError) and the folder listing (a failed export leaves no file, and a previous
export as it was). Registration is checked against Blender's own menu and type
registries.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("pxr")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

import crowd_addon  # noqa: E402
from crowd_addon.blender import export as crowd_export  # noqa: E402
from crowd_addon.blender import panels, preview, registration  # noqa: E402

SEATS = (6, 5)                      # 30 agents, one per seat vertex
SPACING = 1.5


@pytest.fixture(scope="module", autouse=True)
def extension():
    with cs.registered():
        yield
        preview.stop_all()


@pytest.fixture
def scene():
    """24 fps, frames 1..12: an armature, one stream, a proxy mesh, a grid of seats."""
    preview.stop_all()
    scene = cs.reset()
    scene.frame_end = 12
    rig = cs.make_armature()
    walk = cs.make_action(rig, "walk", seed=1, amplitude=1.0)
    s = scene.crowd
    s.armature, s.proxy_mesh, s.max_offset, s.seed = rig, cs.make_proxy(rig), 8, 3
    cs.add_stream(s, "walk", walk)
    src = s.agent_sources.add()
    src.name, src.object = "seats", cs.make_seats(*SEATS, spacing=SPACING)
    return scene


def agents_of(path):
    """The stage and its agents: instanced SkelRoots, as UsdSkel.Root."""
    from pxr import Usd, UsdSkel
    stage = Usd.Stage.Open(str(path))
    return stage, [UsdSkel.Root(p) for p in stage.Traverse()
                   if p.IsA(UsdSkel.Root) and p.IsInstance()]


def seat_positions(scene):
    obj = scene.crowd.agent_sources[0].object
    return np.array([obj.matrix_world @ v.co for v in obj.data.vertices])


def sorted_rows(a):
    a = np.round(np.asarray(a, float), 5)
    return a[np.lexsort(a.T[::-1])]


def listing(folder):
    return sorted(os.listdir(folder))


def test_export_writes_the_scene_crowd_over_the_scene_range(scene, tmp_path, capfd):
    from pxr import Usd, UsdGeom, UsdSkel
    path = tmp_path / "shot.usdc"
    frame = scene.frame_current
    assert bpy.ops.crowd.export_usd(filepath=str(path)) == {"FINISHED"}
    stage, agents = agents_of(path)
    assert len(agents) == SEATS[0] * SEATS[1]
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1, 12)
    assert stage.GetTimeCodesPerSecond() == 24
    info = stage.GetRootLayer().customLayerData["crowd"]
    assert (info["agents"], info["firstFrame"], info["lastFrame"]) == (30, 1, 12)
    # every agent stands on a seat of the agent source, each seat has one agent
    xf = UsdGeom.XformCache(1)
    placed = [np.array(xf.GetLocalToWorldTransform(a.GetPrim()).ExtractTranslation())
              for a in agents]
    assert np.allclose(sorted_rows(placed), sorted_rows(seat_positions(scene)), atol=1e-5)
    # UsdSkel binds an agent's skeleton (the rig's joints) to a sampled animation
    cache = UsdSkel.Cache()
    pred = Usd.TraverseInstanceProxies()
    assert cache.Populate(agents[0], pred)
    (binding,) = cache.ComputeSkelBindings(agents[0], pred)
    query = cache.GetSkelQuery(binding.GetSkeleton())
    anim = query.GetAnimQuery()
    assert anim and anim.GetJointTransformTimeSamples()
    assert len(query.GetJointOrder()) == len(cs.BONES)
    assert scene.frame_current == frame                   # the scene is unchanged
    out = capfd.readouterr().out
    assert f"wrote 30 agents, frames 1-12 to {path}" in out
    size = sum(f.stat().st_size for f in tmp_path.rglob("*") if f.is_file())
    assert f"({size / 1000:.1f} KB)" in out


def test_custom_range_agent_limit_and_text_format(scene, tmp_path):
    path = tmp_path / "part.usda"
    assert bpy.ops.crowd.export_usd(filepath=str(path), use_scene_range=False,
                                    frame_start=3, frame_end=9, agents=5) == {"FINISHED"}
    stage, agents = agents_of(path)
    assert len(agents) == 5
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (3, 9)
    assert path.read_text()[:6] == "#usda "
    assert all(f.suffix == ".usda" for f in (tmp_path / "part.layers").rglob("*.*"))


def test_scene_range_wins_over_start_and_end_unless_turned_off(scene, tmp_path):
    path = tmp_path / "scene_range.usdc"
    scene.frame_start, scene.frame_end = 2, 6
    assert bpy.ops.crowd.export_usd(filepath=str(path), frame_start=4, frame_end=5) == \
        {"FINISHED"}
    stage, _ = agents_of(path)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (2, 6)


def _break(scene, what, tmp_path):
    """Make one thing wrong; returns the operator's keyword arguments."""
    kw = {"filepath": str(tmp_path / "bad.usdc")}
    s = scene.crowd
    if what == "no armature":
        s.armature = None
    elif what == "no action":
        s.streams[0].nodes[0].action = None
    elif what == "no streams":
        s.streams.remove(0)
    elif what == "empty range":
        kw.update(use_scene_range=False, frame_start=9, frame_end=4)
    elif what == "before start":
        kw.update(use_scene_range=False, frame_start=0, frame_end=4)
    elif what == "bad extension":
        kw["filepath"] = str(tmp_path / "bad.abc")
    elif what == "missing folder":
        kw["filepath"] = str(tmp_path / "nowhere" / "bad.usdc")
    elif what == "too many agents":                # fails after the bake, in the export
        kw["agents"] = 31
    return kw


@pytest.mark.parametrize("what, message", [
    ("no armature", "no armature chosen"),
    ("no action", "node 'clip': no action chosen"),
    ("no streams", "no streams or unique animations"),
    ("empty range", "frame range 9-4 is empty"),
    ("before start", "frame range 0-4 starts before scene 'Scene''s start frame 1"),
    ("bad extension", "needs a name ending in .usdc, .usd, .usda"),
    ("missing folder", "does not exist"),
    ("too many agents", "31 agents requested but the crowd has 30"),
])
def test_bad_input_is_reported_and_writes_nothing(scene, tmp_path, what, message):
    kw = _break(scene, what, tmp_path)
    with pytest.raises(RuntimeError, match="Crowd export: .*" + message.replace("(", r"\(")):
        bpy.ops.crowd.export_usd(**kw)
    assert listing(tmp_path) == []


def test_failed_export_keeps_the_previous_one(scene, tmp_path):
    path = tmp_path / "shot.usdc"
    assert bpy.ops.crowd.export_usd(filepath=str(path)) == {"FINISHED"}
    before = {str(f): f.read_bytes() for f in tmp_path.rglob("*") if f.is_file()}
    with pytest.raises(RuntimeError, match="31 agents requested"):
        bpy.ops.crowd.export_usd(filepath=str(path), agents=31)
    after = {str(f): f.read_bytes() for f in tmp_path.rglob("*") if f.is_file()}
    assert after == before and listing(tmp_path) == ["shot.layers", "shot.usdc"]


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root writes into read-only folders")
def test_read_only_folder_is_reported(scene, tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(RuntimeError, match="cannot write in"):
            bpy.ops.crowd.export_usd(filepath=str(folder / "shot.usdc"))
        assert listing(folder) == []
    finally:
        folder.chmod(0o755)


@pytest.mark.skipif(not os.path.isdir("/sys/kernel"), reason="needs Linux sysfs")
def test_unwritable_folder_is_reported(scene):
    """sysfs refuses new files even to root."""
    before = listing("/sys")
    with pytest.raises(RuntimeError, match="/sys/shot.usdc: cannot write in /sys"):
        bpy.ops.crowd.export_usd(filepath="/sys/shot.usdc")
    assert listing("/sys") == before


class _Layout:
    """Records the operators a draw function adds (any other layout call is a no-op
    returning a layout, so nested rows and columns record too)."""

    def __init__(self, ops=None):
        self.ops = [] if ops is None else ops

    def operator(self, idname, **kw):
        self.ops.append((idname, kw.get("text")))
        return _Props()

    def __getattr__(self, name):
        return lambda *a, **kw: _Layout(self.ops)


class _Props:
    def __setattr__(self, name, value):
        pass


def test_panel_and_file_export_menu_offer_the_operator(scene):
    from types import SimpleNamespace
    panel = SimpleNamespace(layout=_Layout())
    panels.CROWD_PT_main.draw(panel, bpy.context)
    assert ("crowd.export_usd", "Export USD...") in panel.layout.ops
    menu = SimpleNamespace(layout=_Layout())
    crowd_export.menu_export(menu, bpy.context)
    assert menu.layout.ops == [("crowd.export_usd", "Crowd (.usd)")]


@pytest.mark.parametrize("typed, kept", [
    ("/x/shot.usda", "/x/shot.usda"), ("/x/shot.USD", "/x/shot.USD"),
    ("/x/shot.usdc", "/x/shot.usdc"), ("/x/shot.abc", "/x/shot.usdc"),
    ("/x/shot", "/x/shot.usdc"), ("/x/", "/x/"),
])
def test_file_browser_keeps_usd_extensions_and_adds_usdc_otherwise(typed, kept):
    from types import SimpleNamespace
    op = SimpleNamespace(filepath=typed, filename_ext=".usdc")
    changed = crowd_export.CROWD_OT_export_usd.check(op, bpy.context)
    assert op.filepath == kept and changed == (typed != kept)


def _menu_entries():
    menu = bpy.types.TOPBAR_MT_file_export
    funcs = menu._dyn_ui_initialize() if menu.is_extended() else []
    return [f for f in funcs if f.__module__ == crowd_export.__name__]


def test_register_unregister_twice_adds_and_removes_the_menu_entry_and_operator():
    mine = hasattr(bpy.types.Scene, "crowd")
    if mine:
        crowd_addon.unregister()
    try:
        assert _menu_entries() == [] and not hasattr(bpy.types, "CROWD_OT_export_usd")
        for _ in range(2):
            crowd_addon.register()
            assert [f.__qualname__ for f in _menu_entries()] == ["menu_export"]
            assert hasattr(bpy.types, "CROWD_OT_export_usd")
            assert "menu TOPBAR_MT_file_export: menu_export" in registration.leftovers()
            crowd_addon.unregister()
            assert _menu_entries() == [] and registration.leftovers() == []
            assert not hasattr(bpy.types, "CROWD_OT_export_usd")
            with pytest.raises(KeyError, match="CROWD_OT_export_usd"):
                bpy.ops.crowd.export_usd.get_rna_type()
    finally:
        crowd_addon.register()
