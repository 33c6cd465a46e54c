"""The stadium show drives a core crowd through goals, a wave, hits and claps."""

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig, CrowdError, synthetic
from crowd_addon.core.agents import STREAM, TRANSITION, UNIQUE
from crowd_addon.demo.show import ShowPlan, StadiumShow

N = 240


def stadium(slots=40, clap_at=7.0):
    cfg = CrowdConfig(max_offset=20, transition_slots=slots, seed=3)
    sk = cfg.add_skeleton(synthetic.humanoid("fan", bones=24))
    for i, name in enumerate(("idle_a", "idle_b", "cheer", "wave", "hit")):
        cfg.add_clip(synthetic.periodic_clip(
            sk, name, frames=31 + 10 * i, seed=i, loop=name != "hit",
            events=[("clap", clap_at)] if name == "idle_a" else ()))
    for name in ("idle_a", "idle_b", "cheer", "wave"):
        cfg.add_stream(name, "fan", ClipPlayer(name))
    for k in range(3):
        cfg.add_unique(f"hit{k}", "fan", ClipPlayer("hit"))
    angle = np.linspace(0, 2 * np.pi, N, endpoint=False)
    cfg.add_agents(N, streams=np.arange(N) % 2, offsets="uniform",
                   positions=np.stack([40 * np.cos(angle), 30 * np.sin(angle),
                                       np.zeros(N)], 1))
    return cfg, angle


def playing(crowd, ids):
    """``(kind, ref, offset)`` each agent plays, a transition as its target."""
    a = crowd.view.agents
    kind, ref, off = (a.kind[ids].astype(np.int64), a.ref[ids].copy(),
                      a.offset[ids].copy())
    tr = np.flatnonzero(kind == TRANSITION)
    if tr.size:
        slot = crowd.view.transitions(ids[tr])
        kind[tr], ref[tr], off[tr] = (slot["target_kind"], slot["target_ref"],
                                      slot["target_offset"])
    return kind, ref, off


def run(show, crowd, frames):
    for _ in range(frames):
        show.before_step()
        crowd.step()


def test_goal_sends_home_to_cheer_through_slots_then_back():
    cfg, angle = stadium(slots=40)
    crowd = Crowd(cfg)
    home = np.cos(angle) > 0                      # one side of the bowl
    plan = ShowPlan(goal_frame=2, cheer_frames=60, wave_lap_frames=0, hit_frame=-1)
    show = StadiumShow(crowd, angle, home, plan=plan)
    run(show, crowd, 3)
    assert show.stats.cheering == home.sum() > 40
    assert show.stats.queued == home.sum() - 40    # more requests than slots: queued
    assert (crowd.agents.kind[home] == TRANSITION).sum() == 40
    assert (crowd.agents.kind[~home] == STREAM).all()
    run(show, crowd, 40)                           # queue drained: all home agents cheer
    assert (crowd.agents.kind[home] == STREAM).all()
    assert (crowd.agents.ref[home] == crowd.streams.index("cheer")).all()
    assert (crowd.agents.offset[home] == 0).all()
    run(show, crowd, 60)                           # cheer over: back to own idle + offset
    assert (crowd.agents.kind == STREAM).all()
    np.testing.assert_array_equal(crowd.agents.ref, cfg.agent_stream)
    np.testing.assert_array_equal(crowd.agents.offset, cfg.agent_offset)
    assert crowd.slots.served == 2 * home.sum() and show.stats.cut == 0


def test_wave_passes_each_seat_once_per_lap_in_angle_order():
    cfg, angle = stadium(slots=64)
    crowd = Crowd(cfg)
    plan = ShowPlan(goal_frame=-1, wave_start=0, wave_lap_frames=60, wave_hold=10,
                    hit_frame=-1)
    show = StadiumShow(crowd, angle, np.zeros(N, bool), plan=plan)
    first_wave = np.full(N, -1)
    wave = crowd.streams.index("wave")
    for f in range(80):
        show.before_step()
        crowd.step()
        kind, ref, _ = playing(crowd, np.arange(N))
        now = (kind == STREAM) & (ref == wave) & (first_wave < 0)
        first_wave[now] = f
    assert (first_wave >= 0).all() and show.stats.waves == N
    # the front travels with the seat angle: later seats stand up later
    assert (np.diff(first_wave) >= 0).all()
    assert first_wave[-1] - first_wave[0] >= 55
    run(show, crowd, 30)
    assert (crowd.agents.kind == STREAM).all()
    np.testing.assert_array_equal(crowd.agents.ref, cfg.agent_stream)


def test_hit_agents_get_their_own_unique_and_return():
    cfg, angle = stadium()
    crowd = Crowd(cfg)
    plan = ShowPlan(goal_frame=-1, wave_lap_frames=0, hit_frame=1)
    show = StadiumShow(crowd, angle, np.zeros(N, bool), hits=["hit0", "hit1", "hit2"],
                       hit_frames=20, plan=plan)
    run(show, crowd, 10)
    hit = show._hit_ids
    kind, ref, _ = playing(crowd, hit)
    assert (kind == UNIQUE).all() and sorted(ref.tolist()) == [0, 1, 2]
    run(show, crowd, 25)
    assert (crowd.agents.kind[hit] == STREAM).all()


def test_claps_counted_once_per_frame_with_all_agents():
    cfg, angle = stadium(clap_at=7.0)
    crowd = Crowd(cfg)
    show = StadiumShow(crowd, angle, np.zeros(N, bool),
                       plan=ShowPlan(goal_frame=-1, wave_lap_frames=0, hit_frame=-1))
    run(show, crowd, 60)
    # oracle: an idle_a agent at offset O claps at frame F when (F - O) mod 30 == 7
    period = cfg.clips["idle_a"].keys.shape[0] - 1
    on_a = cfg.agent_stream == 0
    expected = {}
    for f in range(crowd.frame - 59, crowd.frame + 1):
        n = int(((f - cfg.agent_offset[on_a]) % period == 7).sum())
        if n:
            expected[f] = n
    assert dict(show.stats.claps) == expected
    assert show.stats.clap_calls == len(expected)


def test_bad_show_input_is_named():
    cfg, angle = stadium()
    crowd = Crowd(cfg)
    with pytest.raises(CrowdError, match="one value per agent"):
        StadiumShow(crowd, angle[:5], np.zeros(N, bool))
    with pytest.raises(CrowdError, match="unknown stream 'cheers'"):
        StadiumShow(crowd, angle, np.zeros(N, bool), cheer="cheers")


def test_away_side_reacts_and_non_actors_are_never_moved():
    cfg, angle = stadium(slots=300)
    crowd = Crowd(cfg)
    home = np.cos(angle) > 0
    actors = np.arange(N) % 10 != 0                # every tenth agent is not in the show
    plan = ShowPlan(goal_frame=0, cheer_frames=30, wave_start=5, wave_lap_frames=40,
                    wave_hold=5, hit_frame=3)
    show = StadiumShow(crowd, angle, home, away_reaction="idle_b", actors=actors,
                       hits=["hit0", "hit1"], plan=plan)
    ref0 = crowd.agents.ref.copy()
    for _ in range(60):
        show.before_step()
        crowd.step()
        assert (crowd.agents.kind[~actors] == STREAM).all()
        np.testing.assert_array_equal(crowd.agents.ref[~actors], ref0[~actors])
    assert not np.isin(show._hit_ids, np.flatnonzero(~actors)).any()
    away_agents = np.flatnonzero(~home & actors)
    assert show.stats.requested >= 2 * (home & actors).sum() + away_agents.size


def test_a_hit_interrupts_a_cheer_and_the_fan_returns_once():
    """Regression: with the default plan every fan is cheering when the ball comes
    (goal at 45, hit at 70), and the hit was skipped for busy fans (0 hits)."""
    cfg, angle = stadium()
    crowd = Crowd(cfg)
    plan = ShowPlan(goal_frame=1, cheer_frames=30, wave_lap_frames=0, hit_frame=5)
    show = StadiumShow(crowd, angle, np.ones(N, bool), hits=["hit0", "hit1"],
                       hit_frames=10, plan=plan)
    run(show, crowd, 8)
    hit = show._hit_ids
    assert show.stats.hits == 2
    kind, ref, _ = playing(crowd, hit)
    assert (kind == UNIQUE).all() and sorted(ref.tolist()) == [0, 1]
    requested = show.stats.requested
    run(show, crowd, 40)                        # past the hit's end and the cheer's
    assert (crowd.agents.kind[hit] == STREAM).all()
    np.testing.assert_array_equal(crowd.agents.ref[hit], cfg.agent_stream[hit])
    # the cheer's return left them alone: one return each after the hit, no second
    others = N - hit.size
    assert show.stats.requested - requested == hit.size + others
