"""A shot recorded once (core.recording): every agent's pose, transform and event is
rebuilt from the recording alone, and the oracle is the crowd itself: what
``crowd.view`` showed after each step of the same run."""

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig, CrowdError
from crowd_addon.core.runtime.agents import STREAM, TRANSITION, UNIQUE
from crowd_addon.core.shots.driver import FrameDriver
from crowd_addon.core.shots.recorder import Recorder, record
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

FIRST, LAST = 3, 24          # start frame 0: frames 1..3 run before the shot
N = 30


def config(slots=3):
    fan, kid = humanoid("fan", 24), humanoid("kid", 26)
    cfg = CrowdConfig(max_offset=6, transition_slots=slots, seed=2)
    for sk in (fan, kid):
        cfg.add_skeleton(sk)
    for i in range(3):
        cfg.add_clip(periodic_clip(fan, f"fan{i}", frames=11 + 4 * i, seed=i,
                                   events=[("clap", 3.0)] if i == 0 else ()))
    cfg.add_clip(periodic_clip(kid, "kid0", frames=9, seed=7, events=[("jump", 1.5)]))
    cfg.add_stream("idle", "fan", ClipPlayer("fan0"))
    cfg.add_stream("cheer", "fan", ClipPlayer("fan1"))
    cfg.add_stream("kid play", "kid", ClipPlayer("kid0"))
    cfg.add_unique("solo", "fan", ClipPlayer("fan2"))
    cfg.add_unique("solo2", "fan", ClipPlayer("fan2", speed=1.5))
    rng = np.random.default_rng(1)
    cfg.add_agents(N - 4, streams=np.arange(N - 4) % 2, offsets=np.arange(N - 4) % 6,
                   positions=rng.uniform(-5, 5, (N - 4, 3)))
    cfg.add_agents(4, streams="kid play", offsets=[0, 1, 2, 5])
    cfg.agent_stream[20], cfg.agent_unique[20] = -1, 1            # a unique from the start
    return cfg


def simulate(crowd, frame):
    """Transitions to a stream and to a unique, a queue (3 slots), a cut, a slot reused
    by a new request mid-blend, a transition done before the shot, moves."""
    if frame == 2:
        crowd.transition_to_streamed([9], "cheer", 1, offset=2)     # over before FIRST
    if frame == 5:
        crowd.transition_to_streamed([1, 2], "cheer", 4, offset=3)
        crowd.transition_to_unique([3], "solo", 3)
        crowd.transition_to_streamed([4, 5], "idle", 5)             # queued
    if frame == 7:
        crowd.transition_to_streamed([1], "idle", 6)                # slot reused
        crowd.transition_to_streamed([6], "cheer", 0, offset=5)     # a cut
        crowd.place_agents([7], position=(1.0, 2.0, 3.0))
    if frame == 12:
        crowd.transition_to_unique([8, 20], "solo", 4, restart=False)
        crowd.place_agents([7, 8], heading=[0.5, -1.0])
    if frame == 16:
        crowd.transition_to_streamed([20, 3], "idle", 3, offset=[1, 4])
        crowd.place_agents([0], position=crowd.view.agents.position[0])  # no change


def jump_reaction(crowd):
    """An event callback that requests a transition during a step (once, at the first
    jump from frame 20 on, when slots are free): its agent blends from that frame."""
    done = []

    def react(name, frame, ids):
        if frame >= 20 and not done:
            done.append(crowd.transition_to_streamed(ids[:1], "kid play", 2, offset=4))
    crowd.on_event("jump", react)


def run(skinning="gpu"):
    """Record the shot; the oracle is read from ``crowd.view`` after every step."""
    crowd = Crowd(config(), skinning=skinning)
    seen = {"poses": {}, "position": {}, "heading": {}, "kind": {}, "events": []}
    jump_reaction(crowd)
    crowd.on_event("*", lambda n, f, ids: seen["events"].append((n, f, ids.tolist())))
    recorder = Recorder(crowd, FIRST, LAST)

    def look(crowd):
        v = crowd.view
        if v.frame >= FIRST:
            seen["poses"][v.frame] = v.agent_poses()
            seen["position"][v.frame] = np.array(v.agents.position)
            seen["heading"][v.frame] = np.array(v.agents.heading)
            seen["kind"][v.frame] = np.array(v.agents.kind)
    look(crowd)
    FrameDriver(crowd, simulate, [recorder.capture, look]).run(LAST)
    return crowd, recorder.finish(), seen


@pytest.fixture(scope="module")
def shot():
    return run()


def test_poses_rebuilt_from_the_recording_are_what_the_crowd_showed(shot):
    _, rec, seen = shot
    kinds = np.stack([seen["kind"][f] for f in rec.frames])
    for k in (STREAM, UNIQUE, TRANSITION):              # the shot has every kind
        assert (kinds == k).any()
    for f in rec.frames:
        np.testing.assert_array_equal(rec.agent_poses(f), seen["poses"][f], err_msg=f)
        some = np.array([20, 3, 1, 0])
        np.testing.assert_array_equal(rec.agent_poses(f, some), seen["poses"][f][some])
    some = np.array([20, 3, 1, 0, 26, 27])              # every frame at once
    np.testing.assert_array_equal(rec.agent_poses(rec.frames, some),
                                  np.stack([seen["poses"][f][some] for f in rec.frames]))


def test_queued_reused_and_event_driven_transitions_are_segments(shot):
    _, rec, _ = shot
    def segments(a):
        m = rec.segment_agent == a
        return list(zip(rec.segment_frame[m].tolist(), rec.segment_kind[m].tolist()))
    # queued at 5 (3 slots busy), served when agent 3's blend ends at 8
    assert segments(4)[0] == (FIRST, STREAM) and segments(4)[1][1] == TRANSITION
    assert segments(4)[1][0] > 6
    # agent 1: one blend, a second request reusing its slot, then the stream
    assert [k for _, k in segments(1)] == [STREAM, TRANSITION, TRANSITION, STREAM]
    assert rec.t0[rec.segment_ref[(rec.segment_agent == 1) & (rec.segment_kind == TRANSITION)]
                  ].tolist() == [4, 6]
    kid = [a for a in range(26, 30) if len(segments(a)) > 1]   # the jump callback's
    assert len(kid) == 1
    (frame, kind), = [s for s in segments(kid[0]) if s[1] == TRANSITION]
    (t0,) = rec.t0[rec.segment_ref[(rec.segment_agent == kid[0]) & (
        rec.segment_kind == TRANSITION)]].tolist()
    assert frame == t0 >= 20                   # shown from its start frame, S = 0
    assert segments(6) == [(FIRST, STREAM), (7, STREAM)]        # the cut


def test_static_and_moving_agents(shot):
    _, rec, seen = shot
    kinds = np.stack([seen["kind"][f] for f in rec.frames])
    assert rec.static[9] and rec.playing(FIRST, [9])[1].tolist() == [1]   # done before
    dynamic = {1, 2, 3, 4, 5, 6, 8, 20} | {int(a) for a in np.flatnonzero(
        (kinds != STREAM).any(0))}
    assert set(np.flatnonzero(~rec.static).tolist()) == dynamic
    assert set(np.flatnonzero(rec.moving).tolist()) == {7, 8}
    for f in rec.frames:
        pos, head = rec.agent_transforms(f)
        np.testing.assert_array_equal(pos, seen["position"][f])
        np.testing.assert_array_equal(head, seen["heading"][f])
    pos, head = rec.agent_transforms(rec.frames, [8, 7, 0])
    np.testing.assert_array_equal(pos, np.stack([seen["position"][f][[8, 7, 0]]
                                                 for f in rec.frames]))
    assert head.shape == (rec.frames.size, 3)


def test_segments_only_for_changes(shot):
    _, rec, _ = shot
    assert rec.segment_agent.size < N + 25 and rec.move_agent.size == 3
    assert np.all(np.diff(rec.segment_agent) >= 0)


def test_events_and_stream_tags_are_recorded(shot):
    crowd, rec, seen = shot
    fired = [(n, f, ids) for n, f, ids in seen["events"] if f >= FIRST]
    assert [(n, f, ids.tolist()) for n, f, ids in rec.events] == fired
    assert {n for n, _, _ in fired} == {"clap", "jump"}
    stream, name, frame = rec.stream_events
    assert (np.diff(frame) >= 0).all()
    assert frame.min() >= FIRST - 5 and frame.max() <= LAST
    # agent 0 plays idle at offset 0 all along: it claps when the head crosses the tag
    heads = {int(f) for s, n, f in zip(stream, name, frame) if s == 0 and n == "clap"
             and f >= FIRST}
    assert heads and heads == {f for n, f, ids in fired if n == "clap" and 0 in ids}


def test_cpu_skinning_records_the_same_shot(shot):
    _, rec, _ = shot
    _, cpu, seen = run("cpu")
    np.testing.assert_array_equal(cpu.stream_poses, rec.stream_poses)
    np.testing.assert_array_equal(cpu.unique_poses, rec.unique_poses)
    for f in (FIRST, 9, 14, LAST):
        np.testing.assert_array_equal(cpu.agent_poses(f), seen["poses"][f])


def test_record_in_one_call_resets_a_crowd_past_the_shot(shot):
    _, rec, _ = shot
    crowd = Crowd(config(), skinning="gpu")
    jump_reaction(crowd)
    crowd.advance_to(FIRST + 4)
    reports = []
    again = record(crowd, FIRST, LAST, before_step=simulate,
                   progress=lambda *r: reports.append(r))
    assert reports[-1] == ("simulate", LAST, LAST) and len(reports) == LAST
    for name in ("stream_poses", "unique_poses", "segment_agent", "segment_frame",
                 "segment_ref", "start_pose", "move_position"):
        np.testing.assert_array_equal(getattr(again, name), getattr(rec, name))
    assert crowd.view.frame == LAST
    crowd.step()                                    # the recorder no longer listens
    assert len(again.events) == len(rec.events)


def test_a_crowd_stepped_elsewhere_is_recorded_with_capture(shot):
    _, rec, _ = shot
    crowd = Crowd(config(), skinning="gpu")
    jump_reaction(crowd)
    recorder = Recorder(crowd, FIRST, LAST)
    while crowd.view.frame < LAST:
        recorder.capture()
        recorder.capture()                          # the same frame twice: nothing
        simulate(crowd, crowd.view.frame + 1)
        crowd.step()
    recorder.capture()
    again = recorder.finish()
    for f in (FIRST, 8, 13, LAST):
        np.testing.assert_array_equal(again.agent_poses(f), rec.agent_poses(f))
    crowd2 = Crowd(config(), skinning="gpu")
    recorder = Recorder(crowd2, 0, 4)
    crowd2.step()
    crowd2.step()
    with pytest.raises(CrowdError, match="at frame 2, the recording expects frame 1"):
        recorder.capture()


@pytest.mark.parametrize("first, last, message", [
    (6, 2, "frame range 6-2 is empty"),
    (-3, 4, "starts before the crowd's start frame 0"),
    (1.5, 4, "whole numbers"),
])
def test_bad_frames(first, last, message):
    with pytest.raises(CrowdError, match=message):
        record(Crowd(config(), skinning="gpu"), first, last)


def test_failing_simulation_names_the_frame():
    def broken(crowd, frame):
        if frame == 5:
            crowd.transition_to_streamed([0], "nope", 3)
    with pytest.raises(CrowdError, match="before_step callback failed at frame 5: CrowdError: "
                                         "unknown stream 'nope'"):
        record(Crowd(config(), skinning="gpu"), 2, 8, before_step=broken)


def test_lookups_outside_the_shot_and_finish_too_early(shot):
    _, rec, _ = shot
    with pytest.raises(CrowdError, match="frame 25 is outside the shot 3-24"):
        rec.agent_poses(LAST + 1)
    recorder = Recorder(Crowd(config(), skinning="gpu"), 0, 4)
    with pytest.raises(CrowdError, match="frame 4 is not recorded yet"):
        recorder.finish()


def test_every_agent_reported_changed_still_records_only_changes():
    """Agents turned every frame overflow the crowd's change log (over 4,096 changes),
    so it reports every agent as changed now and then: the recording stays exact and
    adds segments only for animation changes."""
    crowd = Crowd(config(), skinning="gpu")

    def turn(crowd, frame):
        simulate(crowd, frame)
        crowd.place_agents(np.arange(N), heading=0.01 * frame)

    seen = {}
    recorder = Recorder(crowd, 0, 160)
    cursor = crowd.view.agent_changes(0).cursor
    FrameDriver(crowd, turn, [recorder.capture, lambda c: seen.__setitem__(
        c.view.frame, (c.view.agent_poses(), np.array(c.view.agents.heading)))]).run(160)
    assert crowd.view.agent_changes(cursor).agents is None     # the log overflowed
    rec = recorder.finish()
    for f in range(1, 161, 7):
        np.testing.assert_array_equal(rec.agent_poses(f), seen[f][0])
        np.testing.assert_array_equal(rec.agent_transforms(f)[1], seen[f][1])
    assert rec.segment_agent.size < N + 30 and rec.moving.all()


def test_a_far_first_frame_or_a_huge_range_is_refused_before_running(two_streams):
    """Regression: a first frame two billion frames after the start simulated for
    days, and a 100-million-frame range asked for hundreds of GiB."""
    from crowd_addon.core.shots.recorder import MAX_PREROLL
    crowd = two_streams(2)
    start = crowd.view.config.start_frame
    with pytest.raises(CrowdError, match="2,000,000,000 frames after the crowd's start"):
        Recorder(crowd, start + 2_000_000_000, start + 2_000_000_001)
    with pytest.raises(CrowdError, match="GiB of poses"):
        Recorder(crowd, start + 1, start + 100_000_000)
    assert crowd.view.frame == start                 # nothing ran
    Recorder(crowd, start + MAX_PREROLL, start + MAX_PREROLL).close()   # at the limit: fine
