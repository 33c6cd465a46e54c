"""The simulation-side API (crowd_addon.api), headless and on the preview's crowd.

Oracle for event delivery: the paper's rule written out independently: a tag at
clip time tau on a looping stream of period P reaches the agents at offset O on the
frames F where the stream head crossed it O frames earlier, (F - O) = tau (mod P).
"""

import os
import sys

import numpy as np
import pytest

from crowd_addon import api
from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig, StateMachine, StateTransition
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

PERIOD, TAU, M = 24, 6.0, 10


def _config(agents=200, seed=3):
    sk = humanoid(bones=24)
    cfg = CrowdConfig(max_offset=M, transition_slots=8, seed=seed)
    cfg.add_skeleton(sk)
    cfg.add_clip(periodic_clip(sk, "walk", frames=PERIOD + 1, events=[("step", TAU)]))
    cfg.add_clip(periodic_clip(sk, "wave", frames=13, seed=5))
    cfg.add_stream("walk", sk.name, ClipPlayer("walk"))
    cfg.add_stream("mood", sk.name, StateMachine(
        {"calm": ClipPlayer("walk"), "wave": ClipPlayer("wave")},
        [StateTransition("calm", "wave", 3, trigger="hello"),
         StateTransition("wave", "calm", 3, condition=("energy", "<", 0.5))]))
    cfg.add_unique("solo", sk.name, ClipPlayer("wave"))
    cfg.add_agents(agents, streams=np.zeros(agents, np.int32))
    return cfg


def _expected(cfg, frame):
    off = cfg.agent_offset
    return np.flatnonzero((frame - off) % PERIOD == TAU)


def test_callbacks_get_all_agents_once_per_event_and_frame():
    cfg = _config()
    sim = api.wrap(Crowd(cfg))
    calls, every = [], []
    sim.on_event("step", lambda n, f, ids: calls.append((n, f, ids.copy())))
    sim.on_event("*", lambda n, f, ids: every.append((n, f)))
    start = sim.frame
    sim.advance_to(start + 3 * PERIOD)
    frames = [f for _, f, _ in calls]
    assert len(frames) == len(set(frames))                      # once per (event, frame)
    want = {f: _expected(cfg, f) for f in range(start + 1, start + 3 * PERIOD + 1)}
    assert frames == [f for f, ids in want.items() if ids.size]
    for name, f, ids in calls:
        assert name == "step" and ids.dtype == np.int64
        np.testing.assert_array_equal(ids, want[f])
    assert every == [("step", f) for f in frames]


def test_a_raising_callback_is_reported_and_the_crowd_goes_on():
    sim = api.wrap(Crowd(_config()))
    got = []

    def broken(name, frame, ids):
        raise ValueError("simulation bug")
    sim.on_event("step", broken)
    h = sim.on_event("step", lambda n, f, ids: got.append(f))
    sim.advance_to(sim.frame + PERIOD)
    assert len(got) >= 1 and len(sim.errors) == len(got)
    assert isinstance(sim.errors[0].error, ValueError)
    sim.off(h)
    before = len(got)
    sim.advance_to(sim.frame + PERIOD)
    assert len(got) == before


def test_going_back_replays_silently_then_reports_again():
    cfg = _config()
    sim = api.wrap(Crowd(cfg))
    frames = []
    sim.on_event("step", lambda n, f, ids: frames.append(f))
    end = sim.frame + 2 * PERIOD
    sim.advance_to(end)
    first = list(frames)
    frames.clear()
    for target in (first[0] + 1, first[1]):    # back to a frame without, with an event
        frames.clear()
        assert sim.advance_to(target) == target
        assert frames == [f for f in first if f == target]   # only the frame shown
        sim.advance_to(end)
        assert frames == [f for f in first if f >= target]


def test_transitions_triggers_and_parameters():
    cfg = _config(agents=20)
    sim = api.wrap(Crowd(cfg))
    res = sim.transition_to_unique([1, 2, 3], "solo", duration=4)
    assert list(res.started) == [1, 2, 3]
    res = sim.transition_to_streamed(np.array([4]), "mood", duration=0)
    assert list(res.cut) == [4]
    sim.set_trigger("mood", "hello")
    sim.step()
    assert sim.state_of("mood") == ["wave"]
    sim.set_parameter("mood", "energy", 0.1)
    sim.step()
    assert sim.state_of("mood") == ["calm"]
    with pytest.raises(CrowdError, match="unknown stream 'run'"):
        sim.transition_to_streamed([0], "run")
    with pytest.raises(CrowdError, match="agent id 99 out of range"):
        sim.transition_to_unique([99], "solo")


def test_a_handle_outlives_its_crowd():
    handle = api.CrowdHandle("test")
    with pytest.raises(CrowdError, match="test: no crowd is running"):
        handle.set_trigger("mood", "hello")
    got = []
    handle.on_event("step", lambda n, f, ids: got.append(f))
    handle.set_parameter("mood", "energy", 0.2)
    old, new = Crowd(_config()), Crowd(_config())
    handle.attach(old)
    handle.attach(new)                  # parameters re-applied, the old crowd silenced
    assert new.evaluator.ctx.params[1]["energy"] == 0.2
    old.advance_to(old.frame + PERIOD)
    assert got == []
    handle.advance_to(new.frame + PERIOD)
    assert got
    handle.detach()
    with pytest.raises(CrowdError, match="no crowd is running"):
        handle.step()


# --------------------------------------------------------------------- in Blender
@pytest.fixture
def blender_crowd():
    bpy = pytest.importorskip("bpy", reason="the bpy module runs the preview")
    sys.path.insert(0, os.path.dirname(__file__))
    import crowd_scene as cs
    from crowd_addon.blender import preview
    with cs.registered():
        preview.stop_all()
        scene = cs.reset()
        rig = cs.make_armature()
        walk = cs.make_action(rig, "walk", markers=[("step", 7)])
        wave = cs.make_action(rig, "wave", seed=2, bones=["arm.L"])
        s = scene.crowd
        s.max_offset = 6
        cs.add_character(s, rig)
        cs.add_stream(s, "walk", walk)
        cs.add_stream(s, "wave", wave, pool="uniques")
        src = s.agent_sources.add()
        src.name, src.object = "seats", cs.make_seats(6, 5)
        yield bpy, scene, preview
        preview.stop_all()


def test_callbacks_on_the_preview_crowd_follow_the_frame(blender_crowd):
    bpy, scene, preview = blender_crowd
    got = []
    handle = api.on_event("step", lambda n, f, ids: got.append((f, ids.copy())))
    try:
        with pytest.raises(CrowdError, match="scene 'Scene': no crowd is running"):
            api.transition_to_unique([0], "wave")
        assert bpy.ops.crowd.bake() == {"FINISHED"}
        crowd = preview.get(scene).crowd
        assert api.scene_crowd(scene).crowd is crowd
        for f in range(2, 40):
            scene.frame_set(f)
        off = crowd.config.agent_offset
        # marker at action frame 7 (clip frame 6), loop period 24, clip 0 at frame 1
        want = {f: np.flatnonzero((f - 1 - off) % 24 == 6) for f in range(2, 40)}
        assert [f for f, _ in got] == [f for f, ids in want.items() if ids.size]
        for f, ids in got:
            np.testing.assert_array_equal(ids, want[f])
        for back in (31, 10):           # scrub back: only the frame shown reports
            got.clear()
            scene.frame_set(back)
            assert crowd.frame == back
            assert [f for f, _ in got] == ([back] if want[back].size else [])
        assert want[31].size
        res = api.transition_to_unique([0, 5], "wave", duration=3)
        assert list(res.started) == [0, 5]
    finally:
        api.off(handle)


def test_callbacks_stay_with_their_file_and_go_when_another_opens(blender_crowd, tmp_path):
    """Reloading the file keeps its callbacks; opening another file (or File > New)
    drops them: they were for the first file's scenes."""
    bpy, scene, preview = blender_crowd
    mine, other = str(tmp_path / "mine.blend"), str(tmp_path / "other.blend")
    bpy.ops.wm.save_as_mainfile(filepath=other, copy=True)           # its own crowd
    bpy.ops.wm.save_as_mainfile(filepath=mine)
    got = []
    api.on_event("*", lambda n, f, ids: got.append(f))

    def play(path):
        bpy.ops.wm.open_mainfile(filepath=path)
        scene = bpy.context.scene
        preview.start(scene)
        for f in range(2, 20):
            scene.frame_set(f)
        return got
    assert play(mine)                                    # File > Revert, or opened again
    got.clear()
    assert play(other) == []
    api.on_event("*", lambda n, f, ids: got.append(f))
    bpy.ops.wm.read_homefile(use_empty=True)              # File > New
    assert api._SCENES == {}
