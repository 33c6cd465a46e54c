"""The show (core/authoring/show.py, run by core/shots/show_runner.py): cues, reactions
and animated parameters run by the crowd.

Oracle: the same requests made by hand from Python (the API the show uses) at the
same frames give bit-identical poses; timing rules are checked agent by agent.
"""

import numpy as np
import pytest

from crowd_addon.core import (Blend2, ClipPlayer, Crowd, CrowdConfig, CrowdError, StateMachine,
                              StateTransition)
from crowd_addon.core.authoring import synthetic
from crowd_addon.core.runtime.agents import STREAM, TRANSITION, UNIQUE
from crowd_addon.core.shots.recorder import record
from crowd_addon.core.authoring.selections import (neighbours, select_fraction, select_inside,
                                                   select_value)
from crowd_addon.core.authoring.show import Action, Cue, Reaction, Show, Sweep, Track

M, N, SIDE = 8, 36, 6


def make_config(show=None, slots=64):
    sk = synthetic.humanoid("fan", bones=24)
    cfg = CrowdConfig(max_offset=M, transition_slots=slots, fps=24.0, start_frame=1)
    cfg.add_skeleton(sk)
    cfg.add_clip(synthetic.periodic_clip(sk, "idle", frames=25, seed=1, events=[("breath", 6)]))
    cfg.add_clip(synthetic.periodic_clip(sk, "cheer", frames=13, seed=2, events=[("clap", 3)]))
    cfg.add_clip(synthetic.periodic_clip(sk, "wave", frames=17, seed=3, amplitude=1.0))
    cfg.add_clip(synthetic.periodic_clip(sk, "fall", frames=21, seed=4, loop=False))
    cfg.add_stream("idle", "fan", ClipPlayer("idle"))
    cfg.add_stream("cheer", "fan", ClipPlayer("cheer"))
    cfg.add_stream("wave", "fan", ClipPlayer("wave"))
    cfg.add_stream("mix", "fan", Blend2(ClipPlayer("idle"), ClipPlayer("wave"), "w"))
    cfg.add_stream("fsm", "fan", StateMachine(
        {"calm": ClipPlayer("idle"), "up": ClipPlayer("cheer")},
        [StateTransition("calm", "up", 4, trigger="go")]))
    cfg.add_unique("hit", "fan", ClipPlayer("fall"))
    g = np.arange(N)
    pos = np.stack([g % SIDE * 2.0 - 5.0, g // SIDE * 2.0 - 5.0, np.zeros(N)], 1)
    cfg.add_agents(N, streams=np.where(g % 4 == 3, 3, 0), offsets=g % M, positions=pos)
    cfg.show = show if show is not None else Show()
    return cfg


def poses(crowd, last):
    out = []
    while crowd.frame < last:
        crowd.step()
        out.append(crowd.agent_poses().copy())
    return np.stack(out)


def by_hand(requests, last, **cfg_kw):
    """The oracle: a crowd with no show, driven by ``requests[frame](crowd)`` before each
    step of ``frame``."""
    crowd = Crowd(make_config(**cfg_kw))
    out = []
    while crowd.frame < last:
        f = crowd.frame + 1
        for r in requests.get(f, ()):
            r(crowd)
        crowd.step()
        out.append(crowd.agent_poses().copy())
    return np.stack(out)


def test_a_cue_equals_the_same_request_made_by_hand():
    ids = np.array([0, 4, 5, 9])
    cue = Cue("goal", 10, Action("stream", "cheer", duration=5, offset=2), agents=ids)
    got = poses(Crowd(make_config(Show((cue,)))), 30)
    want = by_hand({10: [lambda c: c.transition_to_streamed(ids, "cheer", 5, offset=2)]}, 30)
    assert np.array_equal(got, want)
    assert not np.array_equal(got, by_hand({}, 30))


def test_hold_sends_agents_back_to_their_own_stream_and_offset():
    ids = np.array([1, 2, 3, 7])           # 3 and 7 start on "mix", 1 and 2 on "idle"
    cue = Cue("cheer", 5, Action("stream", "cheer", duration=3, offset=0, hold=10), agents=ids)
    crowd = Crowd(make_config(Show((cue,))))
    got = poses(crowd, 40)
    home = np.array([0, 0, 3, 3])
    want = by_hand({5: [lambda c: c.transition_to_streamed(ids, "cheer", 3, offset=0)],
                    15: [lambda c: c.transition_to_streamed(ids[:2], 0, 3, offset=[1, 2]),
                         lambda c: c.transition_to_streamed(ids[2:], 3, 3, offset=[3, 7])]},
                   40)
    assert np.array_equal(got, want)
    assert (crowd.agents.kind[ids] == STREAM).all()
    assert list(crowd.agents.ref[ids]) == list(home)
    assert list(crowd.agents.offset[ids]) == [1, 2, 3, 7]
    assert crowd.show.stats["cheer"]["agents"] == 4


def test_a_cue_without_hold_makes_the_target_the_new_home():
    show = Show((Cue("sit", 3, Action("stream", "cheer", 0, offset=4), agents=np.array([0])),
                 Cue("wave", 6, Action("stream", "wave", 0, hold=4), agents=np.array([0]))))
    crowd = Crowd(make_config(show))
    crowd.advance_to(12)
    assert (crowd.agents.ref[0], crowd.agents.offset[0]) == (1, 4)     # back to "cheer"


def test_spread_starts_each_agent_once_within_the_range_and_repeatably():
    cue = Cue("stand", 10, Action("stream", "cheer", duration=0), spread=7, seed=5)
    crowd = Crowd(make_config(Show((cue,))))
    started = {}
    while crowd.frame < 20:
        before = crowd.agents.ref.copy()
        crowd.step()
        for a in np.flatnonzero((crowd.agents.ref == 1) & (before != 1)):
            started[int(a)] = crowd.frame
    assert sorted(started) == list(range(N))
    assert min(started.values()) >= 10 and max(started.values()) <= 17
    assert len(set(started.values())) > 4                     # really spread
    again = Crowd(make_config(Show((cue,))))
    assert np.array_equal(poses(again, 20), by_hand_replay(started, 20))


def by_hand_replay(started, last):
    req = {}
    for a, f in started.items():
        req.setdefault(f, []).append(
            lambda c, a=a: c.transition_to_streamed([a], "cheer", 0))
    return by_hand(req, last)


def test_an_angle_sweep_reaches_agents_in_order_of_angle():
    fps, omega = 24.0, np.pi / 2                  # a quarter turn per second
    cue = Cue("wave", 5, Action("stream", "wave", duration=2, hold=6),
              sweep=Sweep((0, 0, 0), "angle", omega, start_angle=0.0))
    crowd = Crowd(make_config(Show((cue,))))
    pos = crowd.agents.position.astype(np.float64)
    angle = np.mod(np.arctan2(pos[:, 1], pos[:, 0]), 2 * np.pi)
    expected = 5 + np.floor(angle / omega * fps).astype(int)
    first = np.full(N, -1)
    while crowd.frame < 5 + int(4 * fps) + 2:
        crowd.step()
        moving = (crowd.agents.kind == TRANSITION) & (first < 0)
        first[moving] = crowd.frame
    assert (first == expected).all()
    assert crowd.show.stats["wave"]["agents"] == N


def test_a_distance_sweep_with_laps_and_negative_speed():
    d = Sweep((1.0, 1.0, 0.0), "distance", 2.0).delays(np.array([[1.0, 1.0, 0.0],
                                                                  [4.0, 5.0, 0.0]]), 10.0)
    assert np.allclose(d[:, 0], [0.0, 25.0])
    a = Sweep((0, 0, 0), "angle", -np.pi, laps=2).delays(np.array([[0.0, -1.0, 0.0]]), 10.0)
    assert np.allclose(a, [[5.0, 25.0]])           # clockwise: -90 degrees is half a second


def test_cues_leave_held_agents_alone_unless_they_interrupt():
    ids = np.arange(6)
    show = Show((Cue("goal", 4, Action("stream", "cheer", 2, hold=20), agents=ids),
                 Cue("wave", 8, Action("stream", "wave", 2, hold=5), agents=np.arange(10)),
                 Cue("hit", 10, Action("unique", "hit", 2, hold=8), agents=np.array([2]),
                     interrupt=True)))
    crowd = Crowd(make_config(Show(show.cues)))
    crowd.advance_to(12)
    assert crowd.show.stats["wave"] == {"agents": 4, "skipped": 6, "queued": 0, "cut": 0,
                                        "switched": 0, "streams": 0}
    assert crowd.playing([2])[0][0] == UNIQUE
    crowd.advance_to(19)                      # the hit's return (frame 18) takes agent 2
    kind, ref, _ = crowd.playing([2, 3])      # home; agent 3 still cheers
    assert list(kind) == [STREAM, STREAM] and ref[0] == 0 and ref[1] == 1
    crowd.advance_to(24)                      # the goal's return (frame 24) moves agent 3
    assert crowd.agents.kind[3] == TRANSITION  # but not agent 2: the hit dropped it
    assert crowd.agents.kind[2] == STREAM and crowd.agents.ref[2] == 0


def test_a_hold_that_ends_while_its_request_waits_leaves_the_agent_home():
    """Agents still queued for the cue's blend when its hold ends never left home: they
    stop waiting and play on untouched (no slot, no blend from a frozen pose to where
    they are); the agents that did start go home through their slots."""
    ids = np.arange(6)
    cue = Cue("goal", 5, Action("stream", "cheer", duration=10, hold=4), agents=ids)
    crowd = Crowd(make_config(Show((cue,)), slots=2))
    got = poses(crowd, 30)
    assert crowd.show.stats["goal"]["queued"] == 4
    assert len(crowd.slots.queue) == 0 and crowd.slots.served == 4
    quiet = by_hand({}, 30, slots=2)
    assert np.array_equal(got[:, 2:], quiet[:, 2:])
    assert not np.array_equal(got[:, :2], quiet[:, :2])


def test_reactions_run_a_cue_on_the_agents_whose_event_fired_or_near_them():
    # agents on "cheer" clap at clip frame 3; the reaction sends them to "wave"
    starters = np.array([14])
    show = Show((Cue("start", 2, Action("stream", "cheer", 0, offset=0), agents=starters),
                 Cue("answer", 0, Action("stream", "wave", 0, offset=0), timeline=False)),
                (Reaction("near clap", "clap", "answer", source="cheer", radius=2.1),))
    crowd = Crowd(make_config(show))
    fired = []
    crowd.on_event("clap", lambda n, f, ids: fired.append((f, ids.tolist())))
    while not fired and crowd.frame < 30:
        crowd.step()
    f = fired[0][0]
    assert fired[0][1] == [14]
    crowd.step()
    pos = crowd.agents.position
    near = np.flatnonzero(np.linalg.norm(pos - pos[14], axis=1) <= 2.1)
    assert set(near) == {8, 13, 14, 15, 20}
    waving = np.flatnonzero(crowd.agents.ref == 2)
    assert list(waving) == list(near) and crowd.frame == f + 1
    assert crowd.show.reactions["near clap"] == 5


def test_reaction_source_filters_agents_by_what_they_play():
    show = Show((Cue("answer", 0, Action("stream", "wave", 0), timeline=False),),
                (Reaction("r", "breath", "answer", source="mix"),))
    crowd = Crowd(make_config(show))
    crowd.advance_to(60)
    assert set(np.flatnonzero(crowd.agents.ref == 2)) == set(np.flatnonzero(np.arange(N) % 4 == 3))


def test_parameter_and_trigger_tracks_equal_set_by_hand():
    values = np.linspace(0, 1, 20)
    show = Show(tracks=(Track("mix", "w", 3, values),
                        Track("fsm", "go", 1, (np.arange(30) >= 9).astype(float), "trigger")))
    cfg_agents = dict()
    got = poses(Crowd(make_config(show)), 30)
    req = {f: [lambda c, v=values[min(max(f - 3, 0), 19)]: c.set_parameter("mix", "w", v)]
           for f in range(2, 31)}
    req[9].append(lambda c: c.set_trigger("fsm", "go"))
    assert np.array_equal(got, by_hand(req, 30, **cfg_agents))


def test_going_back_replays_the_show_exactly():
    show = Show((Cue("wave", 3, Action("stream", "wave", 2, hold=5),
                     sweep=Sweep((0, 0, 0), "angle", 2.0)),
                 Cue("goal", 9, Action("stream", "cheer", 3, offset="random", hold=12),
                     agents=np.arange(0, N, 2)),
                 Cue("w", 5, Action("parameter", "mix", name="w", value=0.7))),
                tracks=(Track("fsm", "go", 1, (np.arange(40) % 10 == 5).astype(float),
                              "trigger"),))
    straight = poses(Crowd(make_config(show)), 40)
    crowd = Crowd(make_config(show))
    crowd.advance_to(25)
    crowd.advance_to(4)                          # backwards: reset and re-simulate
    again = poses(crowd, 40)
    assert np.array_equal(again, straight[3:])


def test_reset_forgets_parameters_set_by_hand():
    # before: a reset crowd kept the parameters, so scrubbing back played differently
    crowd = Crowd(make_config())
    fresh = poses(Crowd(make_config()), 10)
    crowd.set_parameter("mix", "w", 1.0)
    crowd.advance_to(5)
    crowd.reset()
    assert np.array_equal(poses(crowd, 10), fresh)


def test_a_recording_of_a_show_rebuilds_its_poses():
    show = Show((Cue("goal", 4, Action("stream", "cheer", 3, hold=6), agents=np.arange(9)),
                 Cue("hit", 6, Action("unique", "hit", 2, hold=10), agents=np.array([20]))))
    live = Crowd(make_config(show), skinning="gpu")
    want = poses(Crowd(make_config(show)), 20)
    rec = record(live, 1, 20)
    assert np.array_equal(rec.agent_poses(np.arange(2, 21)), want[:19])


@pytest.mark.parametrize("make, message", [
    (lambda: Cue("x", 2, Action("stream", "dance")), r"cue 'x': unknown stream or unique "
                                                     r"'dance'"),
    (lambda: Cue("x", 2, Action("stream", "hit")), r"cue 'x': 'hit' is a unique"),
    (lambda: Cue("x", 2, Action("unique", "idle")), r"cue 'x': 'idle' is a stream"),
    (lambda: Cue("x", 2, Action("stream", "idle"), agents=np.array([3, 99])),
     r"cue 'x': agent 99 does not exist \(the crowd has 36 agents\)"),
    (lambda: Cue("x", 2, Action("stream", "idle", offset=8)), r"cue 'x': offset 8 is outside"),
    (lambda: Cue("x", 2, Action("trigger", "nope", name="go")), r"cue 'x': unknown stream"),
])
def test_bad_cues_are_named_when_the_crowd_is_built(make, message):
    with pytest.raises(CrowdError, match=message):
        Crowd(make_config(Show((make(),))))


@pytest.mark.parametrize("make, message", [
    (lambda: Cue("x", 1, Action("stream", "idle"), agents=np.zeros(0, int)),
     r"cue 'x': the selection is empty"),
    (lambda: Sweep(speed=0), r"sweep: speed must be != 0, got 0 \(a front that does not move"),
    (lambda: Sweep(mode="distance", speed=-1), r"sweep: speed must be > 0"),
    (lambda: Cue("x", 1.5, Action("stream", "idle")), r"cue 'x': frame must be a whole"),
    (lambda: Cue("", 1, Action("stream", "idle")), r"cue: the name must not be empty"),
    (lambda: Action("stream", "idle", duration=float("nan")), r"duration must be finite"),
    (lambda: Action("dance", "idle"), r"action: kind must be one of"),
    (lambda: Action("parameter", "mix"), r"parameter action: no parameter name"),
    (lambda: Cue("x", 1, Action("stream", "idle"), spread=3, sweep=Sweep()),
     r"choose a spread or a sweep"),
    (lambda: Show((Cue("a", 1, Action("stream", "idle")),) * 2), r"two cues are named 'a'"),
    (lambda: Show(reactions=(Reaction("r", "clap", "nope"),)), r"reaction 'r': unknown cue"),
    (lambda: Track("mix", "w", 0, [0.0, np.inf]), r"value at frame 1 is not finite"),
])
def test_bad_show_data_is_named_on_construction(make, message):
    with pytest.raises(CrowdError, match=message):
        make()


def test_a_reaction_to_an_event_no_clip_has_is_named():
    show = Show((Cue("a", 0, Action("stream", "wave"), timeline=False),),
                (Reaction("r", "goal!", "a"),))
    with pytest.raises(CrowdError, match=r"reaction 'r': no clip has event 'goal!'"):
        Crowd(make_config(show))


def test_cues_of_another_skeleton_leave_its_agents_alone():
    cfg = make_config(Show((Cue("all", 2, Action("stream", "cheer", 0)),)))
    kid = cfg.add_skeleton(synthetic.humanoid("kid", bones=20))
    cfg.add_clip(synthetic.periodic_clip(kid, "kid_idle", frames=11, seed=9))
    cfg.add_stream("kid_idle", "kid", ClipPlayer("kid_idle"))
    cfg.agent_stream[-4:] = 5
    crowd = Crowd(cfg)
    crowd.advance_to(4)
    assert (crowd.agents.ref[-4:] == 5).all() and (crowd.agents.ref[:-4] == 1).all()
    assert crowd.show.describe()[0]["agents"] == N - 4


def test_selection_helpers():
    pos = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0], [5, 5, 1]], float)
    world_to_local = np.eye(4)
    world_to_local[:3, 3] = [-1, -1, 0]
    assert list(select_inside(pos, world_to_local, [-1.5, -1.5, -1], [1.5, 1.5, 1])) == [0, 1]
    assert list(select_value(np.array([1, 2, 3, 2]), "==", 2)) == [1, 3]
    ids = np.arange(100)
    half = select_fraction(ids, 0.3, 7)
    assert half.size == 30 and np.array_equal(half, select_fraction(ids, 0.3, 7))
    assert not np.array_equal(half, select_fraction(ids, 0.3, 8))
    with pytest.raises(CrowdError, match="fraction must be in 0..1"):
        select_fraction(ids, 1.5, 0)


def test_neighbours_match_brute_force():
    rng = np.random.default_rng(3)
    pos = rng.uniform(-20, 20, (3000, 3)) * [1, 1, 0.1]
    ids = rng.choice(3000, 40, replace=False)
    for radius in (0.5, 1.7, 6.0):
        d = np.linalg.norm(pos[:, None] - pos[ids][None], axis=2)
        want = np.flatnonzero((d <= radius).any(1))
        assert np.array_equal(neighbours(pos, ids, radius), want)


def test_parameter_tracks_hold_from_the_start_frame():
    # before: the start frame's history was filled with the parameters' defaults
    crowd = Crowd(make_config(Show(tracks=(Track("mix", "w", 1, [1.0]),))))
    for offset in range(M):
        assert np.allclose(crowd.pose("mix", offset), crowd.pose("wave", offset), atol=1e-6)


def test_a_cue_at_the_start_frame_is_named():
    # before: accepted and never run (the crowd's first step is the frame after it)
    with pytest.raises(CrowdError, match=r"cue 'early': frame 1 is not after the crowd's "
                                         r"start frame 1"):
        Crowd(make_config(Show((Cue("early", 1, Action("stream", "cheer")),))))


def test_event_counts_start_again_with_a_reset():
    crowd = Crowd(make_config())
    crowd.advance_to(20)
    fired = dict(crowd.events.fired)
    crowd.advance_to(5)                       # back: reset and replay
    crowd.advance_to(20)
    assert dict(crowd.events.fired) == fired and sum(fired.values()) > 0
