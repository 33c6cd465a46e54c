"""The show authored in the .blend (``scene.crowd.show``) and what the crowd makes of it.

Oracles: the scene's own data for selections (attributes, vertex groups, object bounds
through ``mathutils``), Blender's evaluation of animated properties (``frame_set``) for
parameter tracks, and, for the whole loop, pxr.UsdSkel reading a ``crowd export
--blend`` made by a fresh process from the saved file, against the crowd built in this
(the authoring) process: every agent's joint transforms at every frame, and the events.
"""

import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402
from mathutils import Vector  # noqa: E402

from crowd_addon.blender import preview, scene_config  # noqa: E402
from crowd_addon.blender.props import settings_fingerprint  # noqa: E402
from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.base import pose as sqt  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
NX, NY = 8, 6
N = NX * NY


extension = cs.extension_fixture()


def _cue(show, name, **props):
    c = show.cues.add()
    c.name = name
    for k, v in props.items():
        setattr(c, k, v)
    return c


def build():
    """One character, streams idle / cheer (a "clap" marker) / mix (blend by parameter
    "w") / fsm (trigger "go"), unique hit; 48 seats with an INT "team" attribute and a
    "front" vertex group; a show using every cue kind, selection and timing, a
    reaction and two animated parameters."""
    preview.stop_all()
    scene = cs.reset()
    rig = cs.make_armature("Rig")
    idle = cs.make_action(rig, "idle", seed=1)
    cheer = cs.make_action(rig, "cheer", seed=2, frames=(1, 7, 13), amplitude=1.0,
                           markers=[("clap", 4)])
    fall = cs.make_action(rig, "fall", seed=3, frames=(1, 11, 21), loop=False)
    s = scene.crowd
    s.max_offset, s.seed, s.transition_slots = 6, 4, 16
    fan = cs.add_character(s, rig, cs.make_proxy(rig))
    cs.add_stream(fan, "idle", idle)
    cs.add_stream(fan, "cheer", cheer)
    mix = fan.streams.add()
    mix.name = "mix"
    cs.add_node(mix, "blend", "BLEND2", ["a", "b"], weight_parameter="w")
    cs.add_node(mix, "a", "CLIP", action=idle)
    cs.add_node(mix, "b", "CLIP", action=cheer)
    fsm = fan.streams.add()
    fsm.name = "fsm"
    sm = cs.add_node(fsm, "sm", "STATE_MACHINE", [("calm", "a"), ("up", "b")])
    t = sm.transitions.add()
    t.source, t.target, t.trigger, t.duration = "calm", "up", "go", 4
    cs.add_node(fsm, "a", "CLIP", action=idle)
    cs.add_node(fsm, "b", "CLIP", action=cheer)
    cs.add_stream(fan, "hit", fall, pool="uniques")
    seats = cs.make_seats(NX, NY)
    team = (np.arange(N) % 3).astype(np.int32)
    seats.data.attributes.new("team", "INT", "POINT").data.foreach_set("value", team)
    seats.vertex_groups.new(name="front").add(list(range(NX)), 1.0, "REPLACE")
    src = s.agent_sources.add()
    src.name, src.object = "seats", seats
    box = bpy.data.objects.new("Box", bpy.data.meshes.new("Box"))
    box.data.from_pydata([(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)], [], [])
    box.location, box.scale = (-0.5, 1.5, -1.0), (3.0, 2.0, 2.0)
    scene.collection.objects.link(box)
    centre = bpy.data.objects.new("Centre", None)
    centre.location = (3.5, 2.5, 0.0)
    scene.collection.objects.link(centre)
    show = s.show
    _cue(show, "goal", frame=5, target="cheer", duration=4, offset_mode="GIVEN", offset=0,
         hold=10, select="ATTRIBUTE", attribute="team", op="==", compare=1)
    _cue(show, "wave", frame=8, target="cheer", duration=3, hold=6, source="seats",
         timing="SWEEP", sweep_centre=centre, sweep_speed=3.0)
    _cue(show, "fall", frame=12, action="UNIQUE", target="hit", duration=2, hold=8,
         interrupt=True, select="GROUP", vertex_group="front", fraction=0.5, seed=3)
    _cue(show, "box", frame=3, target="idle", offset_mode="RANDOM", select="INSIDE",
         bounds=box, timing="SPREAD", spread=6, duration=2)
    _cue(show, "calm", frame=30, action="PARAMETER", target="mix", parameter="w",
         set_value=0.25)
    _cue(show, "answer", timeline=False, target="idle", duration=2)
    r = show.reactions.add()
    r.name, r.event, r.source, r.cue, r.radius = "near clap", "clap", "cheer", "answer", 1.1
    for name, target, kind, keys in (("w", "mix", "PARAMETER", ((1, 0.0), (30, 1.0))),
                                     ("go", "fsm", "TRIGGER", ((1, 0.0), (20, 0.0),
                                                               (21, 1.0)))):
        p = show.parameters.add()
        p.name, p.target, p.kind = name, target, kind
        for frame, value in keys:
            p.value = value
            p.keyframe_insert("value", frame=frame)
    scene.frame_set(1)
    return scene


@pytest.fixture
def scene():
    return build()


def _inside(box, points):
    inv = box.matrix_world.inverted()
    lo = Vector([min(v[i] for v in box.bound_box) for i in range(3)])
    hi = Vector([max(v[i] for v in box.bound_box) for i in range(3)])
    return np.array([all(lo[i] <= (inv @ Vector(p))[i] <= hi[i] for i in range(3))
                     for p in points])


def test_selections_are_the_agents_the_scene_data_names(scene):
    cfg = scene_config.config_from_scene(scene)
    cues = {c.name: c for c in cfg.show.cues}
    seats = bpy.data.objects["Seats"]
    team = np.array([seats.data.attributes["team"].data[i].value for i in range(N)])
    assert list(cues["goal"].agents) == list(np.flatnonzero(team == 1))
    front = {v.index for v in seats.data.vertices if v.groups}
    fall = set(cues["fall"].agents.tolist())
    assert len(fall) == len(front) // 2 and fall <= front
    world = [tuple(seats.matrix_world @ v.co) for v in seats.data.vertices]
    inside = np.flatnonzero(_inside(bpy.data.objects["Box"], world))
    assert 0 < inside.size < N and list(cues["box"].agents) == list(inside)
    assert list(cues["wave"].agents) == list(range(N))
    assert cues["wave"].sweep.centre == (3.5, 2.5, 0.0)
    assert cues["answer"].timeline is False and cues["box"].spread == 6
    assert [(r.event, r.cue, r.radius) for r in cfg.show.reactions] == [("clap", "answer",
                                                                         pytest.approx(1.1))]


def test_animated_parameters_are_sampled_as_blender_evaluates_them(scene):
    cfg = scene_config.config_from_scene(scene)
    tracks = {t.name: t for t in cfg.show.tracks}
    p = scene.crowd.show.parameters
    for f in (1, 7, 19, 20, 21, 30, 48):
        scene.frame_set(f)
        assert tracks["w"].at(f) == pytest.approx(p["w"].value, abs=1e-7)
        assert tracks["go"].at(f) == pytest.approx(p["go"].value, abs=1e-7)
    assert tracks["go"].kind == "trigger" and tracks["w"].first == scene.frame_start


def test_a_driven_parameter_follows_its_driver(scene):
    p = scene.crowd.show.parameters["w"]
    p.driver_add("value").driver.expression = "frame / 10"
    values = scene_config.config_from_scene(scene).show.tracks[0].values
    assert np.allclose(values, np.arange(1, 49) / 10)
    assert scene.frame_current == 1


def test_a_keyframe_edit_makes_the_running_crowd_stale(scene):
    before = settings_fingerprint(scene.crowd)
    scene.frame_set(17)                             # animated values do not count
    assert settings_fingerprint(scene.crowd) == before
    p = scene.crowd.show.parameters["w"]
    p.value = 0.5
    p.keyframe_insert("value", frame=10)            # but their keyframes do
    assert settings_fingerprint(scene.crowd) != before


@pytest.mark.parametrize("edit, message", [
    (lambda s: setattr(s.show.cues["goal"], "target", "dance"),
     r"cue 'goal': unknown stream or unique 'dance'"),
    (lambda s: setattr(s.show.cues["goal"], "compare", 7),
     r"cue 'goal': the selection is empty"),
    (lambda s: setattr(s.show.cues["fall"], "frame", 400),
     r"cue 'fall': frame 400 is outside the scene's frames 2..48"),
    (lambda s: setattr(s.show.cues["wave"], "sweep_speed", 0.0),
     r"cue 'wave': sweep: speed must be != 0"),
    (lambda s: setattr(s.show.cues["wave"], "source", "stands"),
     r"cue 'wave': no enabled agent source is named 'stands'"),
    (lambda s: setattr(s.show.reactions["near clap"], "cue", "nope"),
     r"reaction 'near clap': unknown cue 'nope'"),
    (lambda s: setattr(s.show.reactions["near clap"], "event", "boo"),
     r"reaction 'near clap': no clip has event 'boo'"),
    (lambda s: setattr(s.show.parameters["w"], "target", "ghost"),
     r"parameter track 'w'.*unknown stream or unique 'ghost'"),
])
def test_a_bad_show_is_named_and_changes_nothing(scene, edit, message):
    edit(scene.crowd)
    before = settings_fingerprint(scene.crowd)
    with pytest.raises(CrowdError, match=message):
        Crowd(scene_config.config_from_scene(scene))
    assert settings_fingerprint(scene.crowd) == before


def run_here(scene, last, trusted=False):
    """The crowd as the preview builds it in this process: local poses per frame and
    the events, from the scene's first frame to ``last`` (``trusted``: its crowd script
    trusted for this build, as ``--trust-scripts`` does)."""
    crowd, _note = scene_config.build_crowd(scene, scene_config.config_from_scene(scene),
                                            trust_script=trusted)
    events = []
    crowd.on_event("*", lambda name, frame, ids: events.append((name, int(frame), ids.size)))
    poses = {crowd.frame: crowd.agent_poses().copy()}
    while crowd.frame < last:
        crowd.step()
        poses[crowd.frame] = crowd.agent_poses().copy()
    return crowd, poses, events


def test_a_fresh_process_exports_what_the_authoring_session_plays(scene, tmp_path):
    from pxr import Usd, UsdSkel

    last = 40
    _script(scene, SCRIPT)                 # a crowd script's callback, trusted both sides
    crowd, poses, events = run_here(scene, last, trusted=True)
    untrusted = run_here(scene, last)[1]
    assert not np.array_equal(untrusted[last], poses[last])     # the script mattered
    stats = crowd.show.stats
    assert stats["goal"]["agents"] and stats["wave"]["agents"] and stats["fall"]["agents"]
    assert crowd.show.reactions["near clap"] > 0
    blend, out = tmp_path / "show.blend", tmp_path / "show.usdc"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "export", "--blend", str(blend),
                          "--out", str(out), "--frames", f"1-{last}", "--json",
                          "--trust-scripts"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert Counter({(n, f): k for n, f, k in result["events"]}) == \
        Counter({(n, f): k for n, f, k in events if f >= 1}) != Counter()
    assert result["clip_agents"] > 0
    stage = Usd.Stage.Open(str(out))
    cache, pred = UsdSkel.Cache(), Usd.TraverseInstanceProxies()
    worst = 0.0
    for a in range(N):
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/Crowd/Agents/agent_{a:02d}"))
        assert cache.Populate(root, pred)
        (binding,) = cache.ComputeSkelBindings(root, pred)
        query = cache.GetSkelQuery(binding.GetSkeleton())
        for f in range(1, last + 1):
            local = np.array(query.ComputeJointLocalTransforms(f)).transpose(0, 2, 1)
            want = sqt.pose_to_matrices(poses[f][a, :local.shape[0]].astype(np.float64))
            worst = max(worst, float(np.abs(local - want).max()))
    assert worst < 1e-6, worst


def test_a_chunk_exported_from_a_snapshot_equals_it_simulated_from_the_start(scene, tmp_path):
    """From the saved .blend, in fresh processes: ``crowd snapshot --blend`` writes the
    snapshots, and ``crowd export --blend --snapshots`` of frames 13-40 writes the
    same files and events as that export simulated from frame 1 (the show and the
    trusted crowd script's callback run in both)."""
    _script(scene, SCRIPT)
    blend, snaps = tmp_path / "show.blend", tmp_path / "snaps"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))

    def crowd(*args):
        run = subprocess.run([sys.executable, "-m", "crowd_addon", *args, "--blend",
                              str(blend), "--json", "--trust-scripts"], cwd=ROOT,
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr[-3000:]
        return json.loads(run.stdout.strip().splitlines()[-1])

    written = crowd("snapshot", "--frames", "1-40", "--every", "12", "--out", str(snaps))
    assert [f.rsplit("_f", 1)[1] for f in written["files"]] == \
        ["12.npz", "24.npz", "36.npz", "40.npz"]
    results = {}
    for name, extra in (("plain", ()), ("chunk", ("--snapshots", str(snaps)))):
        results[name] = crowd("export", "--frames", "13-40", "--out",
                              str(tmp_path / name / "show.usdc"), *extra)
    assert results["chunk"]["started_from"] == 12 and results["plain"]["started_from"] is None
    assert results["chunk"]["events"] == results["plain"]["events"] != []
    assert results["chunk"]["clip_agents"] > 0
    read = {name: {f: (Path(r["path"]).parent / f).read_bytes() for f in r["files"]}
            for name, r in results.items()}
    assert read["chunk"] == read["plain"]


def test_saving_and_reloading_gives_the_same_crowd(scene, tmp_path):
    _, want, events = run_here(scene, 30)
    before = settings_fingerprint(scene.crowd)
    path = tmp_path / "again.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    scene = bpy.context.scene
    assert settings_fingerprint(scene.crowd) == before
    _, got, events_again = run_here(scene, 30)
    assert events_again == events
    assert all(np.array_equal(got[f], want[f]) for f in want)


def test_generate_agents_reselects_the_cues_of_the_new_agents(scene):
    # before: the running crowd kept the old agents' ids in its cues
    pv = preview.start(scene)
    assert pv.crowd.show.describe()[0]["agents"] == N // 3
    seats = bpy.data.objects["Seats"]
    with bpy.context.temp_override(object=seats):
        seats.data.attributes["team"].data.foreach_set("value", [1] * N)
    seats.data.update()              # as an edit in the UI tags it (Blender 4.2 needs it)
    assert bpy.ops.crowd.generate_agents() == {"FINISHED"}
    pv = preview.get(scene)
    assert pv.crowd.show.describe()[0]["agents"] == N
    preview.stop(scene)


SCRIPT = '''\
import numpy as np

def register(crowd):
    def sit_down(name, frame, agents):
        crowd.transition_to_streamed(agents, "idle", 3)
    crowd.on_event("clap", sit_down)
'''


def _script(scene, body, name="show.py"):
    text = bpy.data.texts.new(name)
    text.from_string(body)
    scene.crowd.show.script = text
    return text


def test_the_crowd_script_runs_only_where_scripts_are_trusted(scene):
    from crowd_addon.blender import crowd_script
    _, plain, _ = run_here(scene, 30)
    _script(scene, SCRIPT)
    cfg = scene_config.config_from_scene(scene)
    crowd, note = scene_config.build_crowd(scene, cfg)
    assert "crowd script 'show.py' did not run: scripts in .blend files are not trusted" \
        in note
    try:
        crowd_script.trust_script(scene.crowd.show.script)     # the panel's Trust Script
        crowd, note = scene_config.build_crowd(scene, cfg)
        assert note == ""
        crowd.advance_to(30)
        _, scripted, _ = run_here(scene, 30)
    finally:
        crowd_script.forget_trusted_scripts()
    assert not np.array_equal(crowd.agent_poses(), plain[30])   # the callback moved them
    assert np.array_equal(crowd.agent_poses(), scripted[30])


@pytest.mark.parametrize("body, message", [
    ("x = 1\n\ndef register(crowd):\n    raise ValueError('no stands')\n",
     r"crowd script 'show.py' failed at line 4: ValueError: no stands"),
    ("def setup(crowd):\n    pass\n", r"crowd script 'show.py' defines no register\(crowd\)"),
    ("def register(crowd)\n", r"crowd script 'show.py' failed.*SyntaxError"),
])
def test_a_failing_crowd_script_is_named(scene, body, message):
    _script(scene, body)
    with pytest.raises(CrowdError, match=message):
        scene_config.build_crowd(scene, scene_config.config_from_scene(scene),
                                 trust_script=True)


def test_an_untrusted_export_stops_with_exit_code_3_unless_told_to_ignore_it(scene,
                                                                              tmp_path):
    """Issue 35, item 6: an untrusted crowd script was a warning and exit 0, so a farm
    silently exported another show. Now the command stops with exit code 3 and the
    reason, writing nothing (not even the output's folder); ``--ignore-scripts`` goes
    on without the script, and says so."""
    _script(scene, SCRIPT)
    blend = tmp_path / "show.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))

    def export(*extra):
        return subprocess.run([sys.executable, "-m", "crowd_addon", "export", "--blend",
                               str(blend), "--out", str(tmp_path / "out" / "s.usdc"),
                               "--frames", "1-4", "--json", *extra],
                              cwd=ROOT, capture_output=True, text=True, timeout=300)
    run = export()
    assert run.returncode == 3, run.stderr[-2000:]
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("crowd export: error: crowd script 'show.py' did not run: "
                           "scripts in .blend files are not trusted"), last
    assert "--ignore-scripts" in last and "Traceback" not in run.stderr
    assert run.stdout == "" and not (tmp_path / "out").exists()
    run = export("--ignore-scripts")
    assert run.returncode == 0, run.stderr[-2000:]
    assert "crowd script 'show.py' left out (--ignore-scripts)" in run.stderr
    assert json.loads(run.stdout)["frames"] == [1, 4]
    run = export("--ignore-scripts", "--trust-scripts")          # one or the other
    assert run.returncode == 2 and "not allowed with argument" in run.stderr


def test_undoing_a_cue_edit_gives_the_same_crowd(scene):
    _, want, events = run_here(scene, 30)
    bpy.ops.ed.undo_push(message="show built")
    scene.crowd.show.cues["goal"].compare = 2            # another team cheers
    bpy.ops.ed.undo_push(message="cue edited")
    _, edited, _ = run_here(bpy.context.scene, 30)
    assert not np.array_equal(edited[30], want[30])
    bpy.ops.ed.undo()
    scene = bpy.context.scene
    assert scene.crowd.show.cues["goal"].compare == 1
    _, got, events_again = run_here(scene, 30)
    assert events_again == events
    assert all(np.array_equal(got[f], want[f]) for f in want)
