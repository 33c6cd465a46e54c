"""Mass reactions the paper's way (core/shots/show_runner.py, a cue with a switch ``trigger``).

A cue whose agents play streams with a state machine that takes its trigger sets the
trigger on those streams instead of sending the agents through transition slots: each
agent follows its stream into the new state at its own offset. Oracle: the same stream
triggered by hand, its head recorded; an agent at offset ``O`` shows, at frame ``F``,
the head the hand-triggered stream had at ``F - O`` (the ring rule), bit for bit.
"""

import numpy as np
import pytest

from crowd_addon.core import (ClipPlayer, Crowd, CrowdConfig, CrowdError, StateMachine,
                              StateTransition)
from crowd_addon.core.authoring import synthetic
from crowd_addon.core.runtime.agents import STREAM, TRANSITION
from crowd_addon.core.authoring.show import Action, Cue, Show, Sweep, slot_speed

M, CUE, HOLD = 12, 20, 30


def reacting_tree():
    return StateMachine({"idle": ClipPlayer("idle"), "cheer": ClipPlayer("cheer"),
                         "groan": ClipPlayer("groan")},
                        [StateTransition("*", "cheer", 4, trigger="celebrate"),
                         StateTransition("*", "groan", 4, trigger="despair"),
                         StateTransition("*", "idle", 6, trigger="calm")])


def make_config(show=None, slots=16, positions=None):
    """Streams: ``home_a`` and ``home_b`` take the reaction, ``plain`` does not (one
    clip), ``cheer`` is the slot target. Agents 0..23 on home_a (offsets 0..M-1 twice),
    24..35 on home_b, 36..41 on plain."""
    sk = synthetic.humanoid("fan", bones=16)
    cfg = CrowdConfig(max_offset=M, transition_slots=slots, fps=24.0, start_frame=1)
    cfg.add_skeleton(sk)
    cfg.add_clip(synthetic.periodic_clip(sk, "idle", frames=25, seed=1, amplitude=0.2))
    cfg.add_clip(synthetic.periodic_clip(sk, "cheer", frames=13, seed=2, amplitude=1.2))
    cfg.add_clip(synthetic.periodic_clip(sk, "groan", frames=19, seed=3, amplitude=0.9))
    cfg.add_stream("home_a", "fan", reacting_tree())
    cfg.add_stream("home_b", "fan", reacting_tree())
    cfg.add_stream("plain", "fan", ClipPlayer("idle"))
    cfg.add_stream("cheer", "fan", ClipPlayer("cheer"))
    streams = np.r_[np.zeros(24), np.ones(12), np.full(6, 2)].astype(np.int64)
    offsets = np.r_[np.arange(24) % M, np.arange(12), np.arange(6) * 2]
    if positions is None:
        positions = np.c_[np.arange(streams.size), np.zeros((streams.size, 2))]
    cfg.add_agents(streams.size, streams=streams, offsets=offsets, positions=positions)
    cfg.show = show if show is not None else Show()
    return cfg


def goal(agents=None, hold=0, release=""):
    return Cue("goal", CUE, Action("stream", "cheer", duration=4, offset=0, hold=hold,
                                   trigger="celebrate", release=release), agents=agents)


def hand_heads(triggers, last, stream=0):
    """Head poses (frame -> (B, 10)) of ``stream`` of a show-less crowd triggered by
    hand: ``triggers[frame]`` is a list of (stream, trigger) set before that step."""
    crowd = Crowd(make_config())
    heads = {crowd.frame: crowd.pose(stream, 0).copy()}
    while crowd.frame < last:
        for s, t in triggers.get(crowd.frame + 1, ()):
            crowd.set_trigger(s, t)
        crowd.step()
        heads[crowd.frame] = crowd.pose(stream, 0).copy()
    return heads


def test_a_triggered_stream_takes_its_agents_into_the_state_each_at_its_own_offset():
    crowd = Crowd(make_config(Show((goal(np.arange(36)),))))
    want = hand_heads({CUE: [(0, "celebrate")]}, CUE + M + 5)
    quiet = hand_heads({}, CUE + M + 5)
    ids = np.arange(24)                        # home_a
    offsets = crowd.agents.offset[ids]
    reached = np.full(ids.size, -1)
    while crowd.frame < CUE + M + 5:
        crowd.step()
        f = crowd.frame
        got = crowd.agent_poses(ids)
        for k, (a, o) in enumerate(zip(ids, offsets)):
            if f - o in want:
                np.testing.assert_array_equal(got[k], want[f - o], err_msg=f"agent {a} @ {f}")
                if reached[k] < 0 and not np.array_equal(want[f - o], quiet[f - o]):
                    reached[k] = f
    # every agent leaves the quiet pose at the cue's frame plus its offset: within M
    # frames, a ripple across the stream
    assert (reached == CUE + offsets).all()
    assert (reached - CUE < M).all()
    st = crowd.show.stats["goal"]
    assert st == {"agents": 36, "skipped": 0, "queued": 0, "cut": 0, "switched": 36,
                  "streams": 2}
    assert crowd.stats["transitions_served"] == 0          # no slot was used
    assert (crowd.agents.kind[:36] == STREAM).all()
    assert crowd.state_of("home_a") == ["cheer"] and crowd.state_of("home_b") == ["cheer"]
    assert crowd.state_of("plain") == [] and crowd.state_of("cheer") == []


def test_agents_that_cannot_follow_their_stream_go_through_slots():
    # home_a fully selected (switches); home_b only half selected (shared with agents
    # the cue leaves alone: its selected agents blend by slot); plain takes no trigger
    ids = np.r_[np.arange(24), np.arange(24, 30), np.arange(36, 42)]
    crowd = Crowd(make_config(Show((goal(ids),)), slots=64))
    crowd.advance_to(CUE)
    st = crowd.show.stats["goal"]
    assert st["switched"] == 24 and st["streams"] == 1
    assert st["agents"] == 36 and st["queued"] == 0
    assert crowd.stats["transitions_served"] == 12
    assert (crowd.agents.kind[np.r_[24:30, 36:42]] == TRANSITION).all()
    assert (crowd.agents.kind[np.r_[0:24, 30:36]] == STREAM).all()
    assert crowd.state_of("home_a") == ["cheer"]
    crowd.step()
    assert crowd.state_of("home_b") == ["idle"]              # its other agents stay calm
    # the agents left on home_b play exactly the quiet stream
    quiet = Crowd(make_config())
    quiet.advance_to(CUE + 1)
    np.testing.assert_array_equal(crowd.agent_poses(np.arange(30, 36)),
                                  quiet.agent_poses(np.arange(30, 36)))


def test_hold_releases_the_streams_and_the_agents_ripple_back():
    cue = goal(np.arange(24), hold=HOLD, release="calm")
    crowd = Crowd(make_config(Show((cue,))))
    last = CUE + HOLD + M + 8
    want = hand_heads({CUE: [(0, "celebrate")], CUE + HOLD: [(0, "calm")]}, last)
    offsets = crowd.agents.offset[:24]
    while crowd.frame < last:
        crowd.step()
        f = crowd.frame
        got = crowd.agent_poses(np.arange(24))
        for k, o in enumerate(offsets):
            if f - o in want:
                np.testing.assert_array_equal(got[k], want[f - o])
        if f == CUE + HOLD - 1:
            assert (crowd.show.held_until[:24] == CUE + HOLD).all()   # held: others wait
    assert crowd.state_of("home_a") == ["idle"]
    assert (crowd.show.held_until[:24] < 0).all()
    assert crowd.stats["transitions_served"] == 0


def test_a_held_switch_keeps_other_cues_off_its_agents():
    wave = Cue("wave", CUE + 2, Action("stream", "cheer", 2, hold=4), agents=np.arange(30))
    crowd = Crowd(make_config(Show((goal(np.arange(24), hold=HOLD, release="calm"), wave))))
    crowd.advance_to(CUE + 3)
    assert crowd.show.stats["wave"]["skipped"] == 24
    assert crowd.show.stats["wave"]["agents"] == 6


def test_a_snapshot_keeps_the_pending_release():
    show = Show((goal(np.arange(24), hold=HOLD, release="calm"),))
    a = Crowd(make_config(show))
    a.advance_to(CUE + 5)
    snap = a.snapshot()
    a.advance_to(CUE + HOLD + M + 4)
    b = Crowd(make_config(show))
    b.restore(snap)
    b.advance_to(CUE + HOLD + M + 4)
    np.testing.assert_array_equal(a.agent_poses(), b.agent_poses())
    assert b.state_of("home_a") == ["idle"]
    state = a.show.state()
    assert state["releases"]["frame"].size == 0


def test_describe_tells_what_a_cue_costs_in_slots():
    show = Show((goal(np.r_[np.arange(24), np.arange(36, 42)]),
                 Cue("plain", CUE, Action("stream", "cheer", 4), agents=np.arange(36, 42))))
    d = {x["name"]: x for x in Crowd(make_config(show)).show.describe()}
    assert (d["goal"]["agents"], d["goal"]["switched"], d["goal"]["streams"],
            d["goal"]["slots"]) == (30, 24, 1, 6)
    assert (d["plain"]["switched"], d["plain"]["slots"]) == (0, 6)


@pytest.mark.parametrize("kw, match", [
    (dict(kind="stream", release="calm", hold=5), "without a trigger"),
    (dict(kind="stream", trigger="celebrate", release="calm"), "needs a hold"),
    (dict(kind="stream", trigger="celebrate", hold=5), "needs a release"),
    (dict(kind="parameter", name="w", trigger="celebrate"), "stream and unique actions"),
    (dict(kind="stream", trigger=5), "trigger name"),
])
def test_bad_switch_settings_are_refused(kw, match):
    kind = kw.pop("kind")
    with pytest.raises(CrowdError, match=match):
        Action(kind, "cheer", **kw)


def test_a_switch_cannot_be_spread_or_swept():
    a = Action("stream", "cheer", trigger="celebrate")
    with pytest.raises(CrowdError, match="cannot be spread or swept"):
        Cue("x", 5, a, spread=10)
    with pytest.raises(CrowdError, match="cannot be spread or swept"):
        Cue("x", 5, a, sweep=Sweep(speed=1.0))


def test_the_switch_settings_survive_the_config_file(tmp_path):
    from crowd_addon.core.authoring.config_io import load_config, save_config
    cfg = make_config(Show((goal(np.arange(24), hold=HOLD, release="calm"),
                            Cue("plain", CUE, Action("stream", "cheer", 4)))))
    save_config(cfg, tmp_path / "c.json")
    back = load_config(tmp_path / "c.json").show.cues
    assert (back[0].action.trigger, back[0].action.release) == ("celebrate", "calm")
    assert (back[1].action.trigger, back[1].action.release) == ("", "")
    import json
    actions = [c["action"] for c in json.loads((tmp_path / "c.json").read_text())["show"]["cues"]]
    assert "trigger" in actions[0] and "release" in actions[0]
    assert "trigger" not in actions[1] and "release" not in actions[1]    # same hash as before


def _most_slots(speed, slots, blend=3, hold=5):
    """Run a wave (a sweep round the origin over 42 agents on a circle) at ``speed``:
    the most slots busy at once and the most agents waiting in the queue."""
    angle = np.linspace(0, 2 * np.pi, 42, endpoint=False)
    pos = np.c_[10 * np.cos(angle), 10 * np.sin(angle), np.zeros(42)]
    cue = Cue("wave", 5, Action("stream", "cheer", blend, offset=0, hold=hold),
              sweep=Sweep(mode="angle", speed=speed))
    crowd = Crowd(make_config(Show((cue,)), slots=slots, positions=pos))
    busy = waiting = 0
    while crowd.frame < 5 + 24.0 * 2 * np.pi / speed + hold + 2 * blend:
        crowd.step()
        busy = max(busy, int(crowd.slots.active.sum()))
        waiting = max(waiting, crowd.slots.queued_agents().size)
    return busy, waiting


def test_slot_speed_keeps_a_wave_within_its_slots():
    fast = Sweep(mode="angle", speed=40.0)
    angle = np.linspace(0, 2 * np.pi, 42, endpoint=False)
    pos = np.c_[10 * np.cos(angle), 10 * np.sin(angle), np.zeros(42)]
    speed = slot_speed(fast, pos, 24.0, slots=8, blend=3)
    assert 0 < speed < 40.0
    busy, waiting = _most_slots(speed, 8)
    assert waiting == 0 and busy <= 8
    busy, waiting = _most_slots(1.6 * speed, 8)              # faster: the queue fills
    assert waiting > 0
    assert slot_speed(Sweep(speed=-40.0), pos, 24.0, 8, 3) == -speed   # clockwise too
    slow = Sweep(speed=0.1)
    assert slot_speed(slow, pos, 24.0, 8, 3) == 0.1           # already fits: unchanged
    with pytest.raises(CrowdError, match="at least 2 slots"):
        slot_speed(fast, pos, 24.0, 1, 3)
