"""The *Export Crowd USD* operator (``crowd.export_usd``): the Crowd panel button and
File > Export > Crowd (.usd).

Oracles: pxr reads the written stage back (one instanced agent ``SkelRoot`` per seat
vertex of the scene's agent source, each placed on its seat; the stage's time range
and rate are the scene's), Blender's error reports (``bpy.ops`` raises them as
RuntimeError) and the folder listing (a failed export leaves no file, and a previous
export as it was). Registration is checked against Blender's own menu and type
registries. The modal export (after the file browser) is driven with timer, Esc and
right-click events against Blender's window manager: its files are compared with
those of the one-call export, and a cancel at each stage with the folder listing.
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
from crowd_addon.blender import scene_export  # noqa: E402
from crowd_addon.blender import panels, preview, registration  # noqa: E402

SEATS = (6, 5)                      # 30 agents, one per seat vertex
SPACING = 1.5


extension = cs.extension_fixture()


@pytest.fixture
def scene():
    """24 fps, frames 1..12: an armature, one stream, a proxy mesh, a grid of seats."""
    preview.stop_all()
    scene = cs.reset()
    scene.frame_end = 12
    rig = cs.make_armature()
    walk = cs.make_action(rig, "walk", seed=1, amplitude=1.0)
    s = scene.crowd
    s.max_offset, s.seed = 8, 3
    cs.add_stream(cs.add_character(s, rig, cs.make_proxy(rig)), "walk", walk)
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


def test_the_blender_layout_from_the_operator(scene, tmp_path):
    path = tmp_path / "for_blender.usdc"
    assert bpy.ops.crowd.export_usd(filepath=str(path), usd_layout="blender") == {"FINISHED"}
    from pxr import Usd
    stage = Usd.Stage.Open(str(path))
    agents = stage.GetPrimAtPath("/Crowd/Agents").GetChildren()
    assert len(agents) == 30 and not any(p.IsInstanceable() for p in agents)
    assert stage.GetRootLayer().customLayerData["crowd"]["layout"] == "blender"


def test_samples_per_frame_from_the_operator(scene, tmp_path):
    """Sub-frame samples for motion blur: the stage holds 3 samples a frame."""
    path = tmp_path / "blur.usdc"
    assert bpy.ops.crowd.export_usd(filepath=str(path), use_scene_range=False,
                                    frame_start=2, frame_end=5, substeps=3) == {"FINISHED"}
    from pxr import Gf, Usd, UsdSkel
    stage = Usd.Stage.Open(str(path))
    assert stage.GetRootLayer().customLayerData["crowd"]["substeps"] == 3
    anim = next(UsdSkel.Animation(p) for p in stage.Traverse()
                if p.IsA(UsdSkel.Animation) and "/Streams/" in str(p.GetPath()))
    times = anim.GetRotationsAttr().GetTimeSamplesInInterval(Gf.Interval(2, 5))
    assert times == pytest.approx([2 + k / 3 for k in range(10)])
    with pytest.raises(TypeError):
        bpy.ops.crowd.export_usd(filepath=str(path), substeps=0.5)


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
        s.characters[0].armature = None
    elif what == "no action":
        s.characters[0].streams[0].nodes[0].action = None
    elif what == "no streams":
        s.characters[0].streams.remove(0)
    elif what == "empty range":
        kw.update(use_scene_range=False, frame_start=9, frame_end=4)
    elif what == "before start":
        kw.update(use_scene_range=False, frame_start=0, frame_end=4)
    elif what == "bad extension":
        kw["filepath"] = str(tmp_path / "bad.abc")
    elif what == "folder is a file":
        (tmp_path / "taken").write_text("mine")
        kw["filepath"] = str(tmp_path / "taken" / "deeper" / "bad.usdc")
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
    ("folder is a file", "cannot create it"),
    ("too many agents", "31 agents requested but the crowd has 30"),
])
def test_bad_input_is_reported_and_writes_nothing(scene, tmp_path, what, message):
    kw = _break(scene, what, tmp_path)
    with pytest.raises(RuntimeError, match="Crowd export: .*" + message.replace("(", r"\(")):
        bpy.ops.crowd.export_usd(**kw)
    assert listing(tmp_path) == (["taken"] if what == "folder is a file" else [])


def test_a_missing_folder_is_made_and_gone_again_when_the_export_fails(scene, tmp_path):
    """Issue 35, item 6: *Export Crowd USD* refused a folder that does not exist yet,
    which ``crowd export`` creates. Now it is created (its missing parents too), and
    removed again when the export fails, so a failure still leaves nothing behind."""
    path = tmp_path / "new" / "shots" / "shot.usdc"
    with pytest.raises(RuntimeError, match="31 agents requested"):
        bpy.ops.crowd.export_usd(filepath=str(path), agents=31)
    assert listing(tmp_path) == []
    assert bpy.ops.crowd.export_usd(filepath=str(path)) == {"FINISHED"}
    assert listing(path.parent) == ["shot.layers", "shot.usdc"]
    assert len(agents_of(path)[1]) == 30


def test_a_cancelled_modal_export_removes_the_folder_it_made(scene, tmp_path, event_loop,
                                                            new_threads):
    path = tmp_path / "new" / "shot.usdc"
    op, ctx = _ModalExport(path), _Context()
    assert op.execute(ctx) == {"RUNNING_MODAL"}
    assert listing(tmp_path) == ["new"]                # made when the export starts
    _run_until(op, ctx, "simulate", 2)
    assert op.modal(ctx, ESC) == {"CANCELLED"}
    assert listing(tmp_path) == [] and new_threads() == []


def test_failed_export_keeps_the_previous_one(scene, tmp_path):
    path = tmp_path / "shot.usdc"
    assert bpy.ops.crowd.export_usd(filepath=str(path)) == {"FINISHED"}
    before = {str(f): f.read_bytes() for f in tmp_path.rglob("*") if f.is_file()}
    with pytest.raises(RuntimeError, match="31 agents requested"):
        bpy.ops.crowd.export_usd(filepath=str(path), agents=31)
    after = {str(f): f.read_bytes() for f in tmp_path.rglob("*") if f.is_file()}
    assert after == before and listing(tmp_path) == ["shot.layers", "shot.usdc"]


def test_read_only_folder_is_reported(scene):
    """A folder the user may not write in. Root writes anywhere, so as root (CI) the
    export runs for this call with the effective user id of nobody, in a folder that
    nobody may reach but not write in."""
    import shutil
    import tempfile
    base = tempfile.mkdtemp(prefix="crowd_locked_")
    os.chmod(base, 0o755)
    folder = os.path.join(base, "locked")
    os.mkdir(folder, 0o555)
    as_root = hasattr(os, "geteuid") and os.geteuid() == 0
    try:
        if as_root:
            os.seteuid(65534)
        try:
            with pytest.raises(RuntimeError, match="cannot write in"):
                bpy.ops.crowd.export_usd(filepath=os.path.join(folder, "shot.usdc"))
        finally:
            if as_root:
                os.seteuid(0)
        assert listing(folder) == []
    finally:
        os.chmod(folder, 0o755)
        shutil.rmtree(base)


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


# ------------------------------------------------------ the modal (cancellable) export
# Background mode has no event loop: the operator's own methods run against a stand-in
# instance (as the bake's modal tests do), with a context whose window manager is
# Blender's, recording the calls the operator makes on it.

class _WindowManager:
    """``bpy.context.window_manager`` with its calls recorded; timers are Blender's
    own (``event_timer_add`` works without a window)."""

    def __init__(self):
        self.wm, self.calls, self.timers = bpy.context.window_manager, [], []

    def event_timer_add(self, step, window=None):
        timer = self.wm.event_timer_add(step)          # no window in background mode
        self.calls.append("timer_add")
        self.timers.append(timer)
        return timer

    def event_timer_remove(self, timer):
        self.timers.remove(timer)                      # ValueError: not one of ours
        self.wm.event_timer_remove(timer)
        self.calls.append("timer_remove")

    def modal_handler_add(self, op):
        self.calls.append("modal_handler_add")
        return True

    def progress_begin(self, lo, hi):
        self.calls.append(("progress_begin", lo, hi))
        self.wm.progress_begin(lo, hi)

    def progress_update(self, value):
        self.calls.append(("progress_update", value))
        self.wm.progress_update(value)

    def progress_end(self):
        self.calls.append("progress_end")
        self.wm.progress_end()

    @property
    def progress(self):
        return [c[1] for c in self.calls if c[0] == "progress_update"]


class _Workspace:
    def __init__(self):
        self.status = []

    def status_text_set(self, text):
        self.status.append(text)


class _Context:
    """What the operator reads from the context after the file browser: a window."""

    def __init__(self):
        self.scene, self.window = bpy.context.scene, object()
        self.window_manager, self.workspace = _WindowManager(), _Workspace()
        self.evaluated_depsgraph_get = bpy.context.evaluated_depsgraph_get


@pytest.fixture
def event_loop(monkeypatch):
    """As in Blender's UI: the operator may go modal (background mode has no event
    loop, so it never does there)."""
    assert crowd_export._event_loop(bpy.context) is False
    monkeypatch.setattr(crowd_export, "_event_loop", lambda context: True)


class _ModalExport:
    """Stands in for the operator instance once the file browser is confirmed
    (``invoke`` set ``interactive``); the operator's methods run against it."""

    _op = crowd_export.CROWD_OT_export_usd
    execute, modal, cancel, _end, _fail, _finish, _unmake = (
        _op.execute, _op.modal, _op.cancel, _op._end, _op._fail, _op._finish, _op._unmake)
    _timer = _job = None
    _made = ()
    step_seconds = 0.0                   # one unit of work per timer event

    def __init__(self, path, **props):
        self.filepath, self.use_scene_range, self.agents = str(path), True, 0
        self.usd_layout, self.substeps = "instanced", 1
        self.frame_start, self.frame_end, self.interactive = 1, 250, True
        for k, v in props.items():
            setattr(self, k, v)
        self.reports = []

    def report(self, kind, message):
        self.reports.append((set(kind), message))


TIMER, ESC, RIGHT, MOUSE, ESC_UP = (type("Event", (), {"type": t, "value": v})()
                                    for t, v in (("TIMER", "NOTHING"), ("ESC", "PRESS"),
                                                 ("RIGHTMOUSE", "PRESS"),
                                                 ("MOUSEMOVE", "NOTHING"),
                                                 ("ESC", "RELEASE")))


@pytest.fixture
def new_threads():
    """Threads started since the test began: none, the export steps on the caller's
    thread."""
    import threading
    before = set(threading.enumerate())
    return lambda: [t for t in threading.enumerate() if t not in before]


def _files(folder):
    return {str(f.relative_to(folder)): f.read_bytes() for f in folder.rglob("*")
            if f.is_file()}


def test_modal_export_steps_on_timer_events_and_writes_what_a_script_export_writes(
        scene, tmp_path, event_loop, new_threads):
    (tmp_path / "modal").mkdir()
    (tmp_path / "script").mkdir()
    path = tmp_path / "modal" / "shot.usda"
    op, ctx = _ModalExport(path), _Context()
    assert op.execute(ctx) == {"RUNNING_MODAL"}
    assert ctx.window_manager.calls == [("progress_begin", 0, 1000), "timer_add",
                                        "modal_handler_add"]
    results, stages = [], []
    while not results or results[-1] == {"RUNNING_MODAL"}:
        if len(results) == 5:                          # other events pass through
            assert op.modal(ctx, MOUSE) == {"PASS_THROUGH"}
            assert op.modal(ctx, ESC_UP) == {"PASS_THROUGH"}
        results.append(op.modal(ctx, TIMER))
        if op._job is not None:
            stages.append(op._job.stage)
            assert not path.exists()                   # nothing in place before the end
        assert len(results) < 200
    assert results[-1] == {"FINISHED"}
    # one step per action baked, per simulated frame (the scene's 1..12), per layer
    assert stages[:3] == ["bake"] * 3 and stages.count("simulate") == 11
    assert {"characters", "streams", "layout"} <= set(stages)
    progress = ctx.window_manager.progress
    assert progress == sorted(progress) and 0 <= progress[0] and progress[-1] <= 1000
    assert ctx.window_manager.calls[-2:] == ["timer_remove", "progress_end"]
    assert ctx.window_manager.timers == [] and ctx.workspace.status[-1] is None
    assert "Esc to cancel" in ctx.workspace.status[0]
    assert op.reports[-1][0] == {"INFO"} and \
        f"wrote 30 agents, frames 1-12 to {path}" in op.reports[-1][1]
    assert new_threads() == []
    # the stage: 30 agents over the scene's range ...
    stage, agents = agents_of(path)
    assert len(agents) == 30
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1, 12)
    info = stage.GetRootLayer().customLayerData["crowd"]
    assert (info["agents"], info["firstFrame"], info["lastFrame"]) == (30, 1, 12)
    # ... and every file the same text as the operator run from a script writes
    assert bpy.ops.crowd.export_usd(filepath=str(tmp_path / "script" / "shot.usda")) == \
        {"FINISHED"}
    modal, script = _files(tmp_path / "modal"), _files(tmp_path / "script")
    assert sorted(modal) == sorted(script) and len(modal) >= 3
    assert modal == script


def _run_until(op, ctx, stage, count=1):
    """Timer events until the job has reported ``stage`` ``count`` times."""
    seen = 0
    for _ in range(200):
        assert op.modal(ctx, TIMER) == {"RUNNING_MODAL"}
        seen += op._job.stage == stage
        if seen == count:
            return
    raise AssertionError(f"stage {stage!r} not reached")


@pytest.mark.parametrize("stage, count, event", [
    ("bake", 2, ESC),                    # between two bake steps
    ("simulate", 5, ESC),                # mid-simulation
    ("streams", 1, RIGHT),               # layers already written to the temporary folder
    ("layout", 1, ESC),                  # the last report before the files move in
])
def test_esc_cancels_the_modal_export_and_leaves_no_file(scene, tmp_path, event_loop,
                                                         stage, count, event, new_threads):
    path = tmp_path / "shot.usdc"
    op, ctx = _ModalExport(path), _Context()
    assert op.execute(ctx) == {"RUNNING_MODAL"}
    _run_until(op, ctx, stage, count)
    if stage in ("streams", "layout"):   # the export's temporary folder is there now
        (tmp,) = listing(tmp_path)
        assert tmp.startswith(".shot.usdc.") and tmp.endswith(".tmp")
        assert any((tmp_path / tmp).rglob("*.usdc"))
    assert new_threads() == []
    assert op.modal(ctx, event) == {"CANCELLED"}
    assert listing(tmp_path) == []                     # no file, no temporary left
    assert op.reports == [({"WARNING"}, "Export cancelled: nothing was written")]
    assert ctx.window_manager.calls[-2:] == ["timer_remove", "progress_end"]
    assert ctx.window_manager.timers == [] and op._timer is None
    assert ctx.workspace.status[-1] is None
    assert new_threads() == []


@pytest.mark.parametrize("stage", ["bake", "simulate", "streams", "layout"])
def test_a_cancelled_export_leaves_a_previous_export_untouched(scene, tmp_path,
                                                               event_loop, stage, new_threads):
    path = tmp_path / "shot.usdc"
    scene.frame_end = 6
    assert bpy.ops.crowd.export_usd(filepath=str(path)) == {"FINISHED"}
    before = _files(tmp_path)
    assert "shot.usdc" in before and len(before) >= 3
    scene.frame_end = 12                               # the new export differs
    op, ctx = _ModalExport(path, agents=12), _Context()
    assert op.execute(ctx) == {"RUNNING_MODAL"}
    _run_until(op, ctx, stage)
    assert op.modal(ctx, ESC) == {"CANCELLED"}
    assert _files(tmp_path) == before
    assert listing(tmp_path) == ["shot.layers", "shot.usdc"]
    assert ctx.window_manager.timers == [] and new_threads() == []


def test_modal_export_errors_are_reported_and_end_the_timer(scene, tmp_path, event_loop,
                                                           new_threads):
    # found when the export starts: no timer, no progress
    op, ctx = _ModalExport(tmp_path / "bad.abc"), _Context()
    assert op.execute(ctx) == {"CANCELLED"}
    assert op.reports[-1][0] == {"ERROR"} and "needs a name ending in" in op.reports[-1][1]
    assert ctx.window_manager.calls == []
    # found after the bake, on a timer event
    op, ctx = _ModalExport(tmp_path / "shot.usdc", agents=31), _Context()
    assert op.execute(ctx) == {"RUNNING_MODAL"}
    results = [op.modal(ctx, TIMER)]
    while results[-1] == {"RUNNING_MODAL"} and len(results) < 20:     # bake, report, ...
        results.append(op.modal(ctx, TIMER))
    assert results[-1] == {"CANCELLED"} and len(results) > 2
    assert op.reports[-1] == ({"ERROR"}, "Crowd export: 31 agents requested but the "
                                         "crowd has 30")
    assert ctx.window_manager.calls[-2:] == ["timer_remove", "progress_end"]
    assert ctx.window_manager.timers == [] and listing(tmp_path) == []
    assert new_threads() == []


def test_blender_ending_the_modal_export_drops_it(scene, tmp_path, event_loop, new_threads):
    """``cancel`` (Blender closes the operator: file loaded, window closed)."""
    op, ctx = _ModalExport(tmp_path / "shot.usdc"), _Context()
    op.cancel(ctx)                                     # file browser cancelled: no job
    assert ctx.window_manager.calls == []
    assert op.execute(ctx) == {"RUNNING_MODAL"}
    _run_until(op, ctx, "simulate", 3)
    op.cancel(ctx)
    assert listing(tmp_path) == [] and ctx.window_manager.timers == []
    assert ctx.window_manager.calls[-2:] == ["timer_remove", "progress_end"]
    assert new_threads() == []


def test_without_a_window_the_export_runs_in_one_call(scene, tmp_path, new_threads):
    """``interactive`` (set by invoke) needs an event loop: a script in background
    Blender passing it still exports in one call."""
    path = tmp_path / "shot.usdc"
    assert bpy.app.background and not crowd_export._event_loop(bpy.context)
    assert bpy.ops.crowd.export_usd(filepath=str(path), interactive=True) == {"FINISHED"}
    assert len(agents_of(path)[1]) == 30 and new_threads() == []


def test_export_scene_drops_the_export_when_a_callback_raises(scene, tmp_path, new_threads):
    """The one-call export drives the same steps: a raising callback stops it at
    once and nothing is written."""
    path = tmp_path / "shot.usdc"
    reports = []

    def progress(stage, done, total):
        reports.append((stage, done, total))
        if stage == "streams":
            assert listing(tmp_path)[0].startswith(".shot.usdc.")
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        scene_export.export_scene(scene, path, (1, 12), progress=progress)
    assert listing(tmp_path) == [] and new_threads() == []
    assert [r for r in reports if r[0] == "simulate"][-1] == ("simulate", 11, 11)
    bakes = []
    config, result = scene_export.export_scene(
        scene, path, (1, 12), on_bake=lambda *a: bakes.append(a))
    # the bake's steps, then its report (the test's random walk misses between frames)
    steps = [b[2] for b in bakes if not b[2].startswith("warning:")]
    assert steps == ["baking action 'walk'", "reading the proxy mesh", "placing agents"]
    assert all("between frames" in b[2] for b in bakes if b[2].startswith("warning:"))
    assert result.agents == 30 and config.start_frame == 1
    assert listing(tmp_path) == ["shot.layers", "shot.usdc"]
