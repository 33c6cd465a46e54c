"""Bad input (docs/architecture.md: a CrowdError naming the culprit, and nothing changed."""

import math

import numpy as np
import pytest

from crowd_addon.core import Blend2, ClipPlayer, Crowd, CrowdConfig, CrowdError
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

M = 8
N = 12


def make_config(when_full="queue"):
    sk = humanoid("fan", bones=24)
    cfg = CrowdConfig(max_offset=M, transition_slots=2, when_full=when_full)
    cfg.add_skeleton(sk)
    for i in range(3):
        cfg.add_clip(periodic_clip(sk, f"c{i}", frames=13 + 2 * i, seed=i))
    cfg.add_stream("walk", "fan", ClipPlayer("c0"))
    cfg.add_stream("mix", "fan", Blend2(ClipPlayer("c0"), ClipPlayer("c1"), "w"))
    cfg.add_unique("solo", "fan", ClipPlayer("c2"))
    cfg.add_agents(N, streams=np.arange(N) % 2, offsets=np.arange(N) % M)
    return cfg


@pytest.fixture
def busy():
    """A crowd with active slots and a queued request, so 'unchanged' means something."""
    crowd = Crowd(make_config())
    crowd.step()
    crowd.set_parameter("mix", "w", 0.25)
    crowd.transition_to_streamed([0, 1, 2], 1, 5, offset=3)      # 2 slots, 1 queued
    crowd.step()
    assert crowd.slots.active.all() and len(crowd.slots.queue) == 1
    return crowd


def state(crowd):
    sl = crowd.slots
    return {
        "frame": crowd.frame,
        "agent_kind": crowd.agents.kind.copy(), "agent_ref": crowd.agents.ref.copy(),
        "agent_offset": crowd.agents.offset.copy(),
        "slots": [a.copy() for a in (sl.active, sl.agent, sl.target_kind, sl.target_ref,
                                     sl.target_offset, sl.t0, sl.length, sl.start_pose,
                                     sl.pose)],
        "queue": list(sl.queue.items()),
        "unique_start": crowd.uniques.start.copy(),
        "params": [dict(p) for p in crowd.evaluator.ctx.params],
        "index": crowd.agents.index.keys.copy(),
        "dirty": list(crowd.storage._dirty),
    }


def assert_unchanged(before, after):
    assert before["frame"] == after["frame"]
    for k in ("agent_kind", "agent_ref", "agent_offset", "unique_start", "index"):
        np.testing.assert_array_equal(before[k], after[k], err_msg=k)
    for a, b in zip(before["slots"], after["slots"]):
        np.testing.assert_array_equal(a, b, err_msg="slots")
    assert [(k, v[:2], v[3]) for k, v in before["queue"]] == \
        [(k, v[:2], v[3]) for k, v in after["queue"]]
    assert [int(v[2]) for _, v in before["queue"]] == [int(v[2]) for _, v in after["queue"]]
    assert before["params"] == after["params"]
    assert before["dirty"] == after["dirty"]


def check_request(crowd, fn, *words):
    before = state(crowd)
    with pytest.raises(CrowdError) as e:
        fn(crowd)
    msg = str(e.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"
    assert_unchanged(before, state(crowd))
    crowd.step()                                      # still works afterwards
    return msg


# --------------------------------------------------------------- requests

REQUESTS = {
    "offset_eq_M": (lambda c: c.transition_to_streamed([4], 0, 3, offset=M), [str(M)]),
    "offset_big": (lambda c: c.transition_to_streamed([4, 5], 0, 3, offset=[1, 99]),
                   ["99"]),
    "offset_negative": (lambda c: c.transition_to_streamed([4], 0, 3, offset=-1), ["-1"]),
    "offset_fraction": (lambda c: c.transition_to_streamed([4], 0, 3, offset=2.5),
                        ["offset"]),
    "unknown_stream_name": (lambda c: c.transition_to_streamed([4], "run", 3), ["'run'"]),
    "unknown_stream_index": (lambda c: c.transition_to_streamed([4], 7, 3), ["7"]),
    "negative_stream_index": (lambda c: c.transition_to_streamed([4], -1, 3), ["-1"]),
    "unique_as_stream": (lambda c: c.transition_to_streamed([4], "solo", 3), ["'solo'"]),
    "unknown_unique_name": (lambda c: c.transition_to_unique([4], "solo2", 3), ["'solo2'"]),
    "unknown_unique_index": (lambda c: c.transition_to_unique([4], 3, 3), ["3"]),
    "agent_negative": (lambda c: c.transition_to_streamed([4, -1], 0, 3), ["-1"]),
    "agent_too_big": (lambda c: c.transition_to_streamed([N], 0, 3), [str(N)]),
    "agent_too_big_unique": (lambda c: c.transition_to_unique([3, N + 5], 0, 3),
                             [str(N + 5)]),
    "agent_float": (lambda c: c.transition_to_streamed([1.5], 0, 3), ["agent"]),
    "bad_policy": (lambda c: c.transition_to_streamed([4], 0, 3, when_full="drop"),
                   ["'drop'"]),
    "negative_duration": (lambda c: c.transition_to_streamed([4], 0, -2), ["-2"]),
    "nan_duration": (lambda c: c.transition_to_streamed([4], 0, float("nan")), ["duration"]),
    "nan_param": (lambda c: c.set_parameter("mix", "w", math.nan), ["'w'"]),
    "inf_param": (lambda c: c.set_parameter("mix", "w", math.inf), ["'w'"]),
    "param_unknown_target": (lambda c: c.set_parameter("sprint", "w", 0.5), ["'sprint'"]),
    "pose_unknown_stream": (lambda c: c.pose("sprint", 0), ["'sprint'"]),
    "pose_offset_M": (lambda c: c.pose(0, M), [str(M)]),
    "agent_poses_out_of_range": (lambda c: c.agent_poses([N]), [str(N)]),
}


@pytest.mark.parametrize("case", sorted(REQUESTS))
def test_bad_request_raises_and_changes_nothing(busy, case):
    fn, words = REQUESTS[case]
    check_request(busy, fn, *words)


# regression: restart used to move the unique's clock before the request was validated
@pytest.mark.parametrize("kwargs", [{"duration": -1}, {"duration": 3, "when_full": "drop"}])
def test_bad_unique_request_leaves_unique_clock(busy, kwargs):
    check_request(busy, lambda c: c.transition_to_unique([4], "solo", **kwargs))


# ---------------------------------------------------------------- config


def build_error(cfg, *words):
    with pytest.raises(CrowdError) as e:
        Crowd(cfg)
    msg = str(e.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"
    return msg


def test_clip_bone_count_mismatch():
    cfg = make_config()
    big = humanoid("big", bones=30)
    cfg.add_clip(periodic_clip(big, "tall", frames=13))
    cfg.add_stream("odd", "fan", ClipPlayer("tall"))
    build_error(cfg, "'tall'", "30", "24", "'fan'")


def test_unknown_clip_in_clip_player():
    cfg = make_config()
    cfg.add_unique("ghost", "fan", Blend2(ClipPlayer("c0"), ClipPlayer("nope")))
    build_error(cfg, "'nope'", "'ghost'")


def test_offset_at_M_in_config():
    cfg = make_config()
    cfg.agent_offset[5] = M
    build_error(cfg, "agent 5", str(M))
    with pytest.raises(CrowdError, match=str(M + 3)):
        make_config().add_agents(2, offsets=[0, M + 3])


def test_unknown_stream_and_unique_in_config():
    cfg = make_config()
    cfg.agent_stream[7] = 9
    build_error(cfg, "agent 7", "9")
    cfg = make_config()
    cfg.agent_stream[2], cfg.agent_unique[2] = -1, 4
    build_error(cfg, "agent 2", "4")
    with pytest.raises(CrowdError, match="'jog'"):
        make_config().add_agents(3, streams="jog")


@pytest.mark.parametrize("stream,unique", [(0, 0), (-1, -1)])
def test_agent_needs_exactly_one_of_stream_or_unique(stream, unique):
    cfg = make_config()
    cfg.agent_stream[6], cfg.agent_unique[6] = stream, unique
    build_error(cfg, "agent 6")


def test_duplicate_animation_names():
    cfg = make_config()
    cfg.add_unique("walk", "fan", ClipPlayer("c1"))
    build_error(cfg, "duplicate", "'walk'")
    cfg = make_config()
    cfg.add_stream("mix", "fan", ClipPlayer("c1"))
    build_error(cfg, "'mix'")


def test_empty_names_are_refused():
    # accepted before: an unnamed stream or skeleton cannot be addressed afterwards
    cfg = make_config()
    with pytest.raises(CrowdError, match=r"an animation on skeleton 'fan' has an empty name"):
        cfg.add_stream(" ", "fan", ClipPlayer("c0"))
    with pytest.raises(CrowdError, match=r"skeleton: the name must not be empty"):
        humanoid("", bones=24)


def test_bad_when_full_in_config():
    build_error(make_config(when_full="drop"), "when_full", "'drop'")


def test_unknown_skeleton_of_stream():
    cfg = make_config()
    cfg.add_stream("alien", "martian", ClipPlayer("c0"))
    build_error(cfg, "'alien'", "'martian'")


def test_nan_blend_weight_in_tree():
    with pytest.raises(CrowdError, match="finite"):
        Blend2(ClipPlayer("c0"), ClipPlayer("c1"), float("nan"))


def test_failed_build_leaves_config_usable():
    cfg = make_config()
    good = Crowd(cfg)
    saved = cfg.agent_offset.copy()
    cfg.agent_offset[0] = M
    build_error(cfg, "agent 0")
    cfg.agent_offset[:] = saved
    again = Crowd(cfg)
    for _ in range(3):
        good.step()
        again.step()
    np.testing.assert_array_equal(good.streams.history, again.streams.history)


# regressions: these raised numpy/builtin errors that named nothing


def test_offsets_of_wrong_length(busy):
    msg = check_request(busy, lambda c: c.transition_to_streamed([4, 5, 6], 0, 3,
                                                                 offset=[1, 2]), "offset")
    assert "3" in msg and "2" in msg


def test_two_dimensional_agent_ids(busy):
    before = state(busy)
    try:
        busy.transition_to_streamed([[4, 5]], 0, 0)
    except CrowdError:
        assert_unchanged(before, state(busy))
        return
    assert busy.agents.ref[4] == 0 and busy.agents.ref[5] == 0


def test_non_numeric_duration(busy):
    check_request(busy, lambda c: c.transition_to_streamed([4], 0, "soon"), "duration")


@pytest.mark.parametrize("field, value, message", [
    ("max_offset", 1.5, "max offset M must be a whole number >= 1, got 1.5"),
    ("max_offset", 0, "max offset M must be a whole number >= 1, got 0"),
    ("transition_slots", 2.5, "transition slots NT must be a whole number >= 0, got 2.5"),
])
def test_sizes_must_be_whole_numbers(field, value, message):
    """Regression: M = 1.5 was truncated and then blamed an agent's offset."""
    cfg = make_config()
    setattr(cfg, field, value)
    with pytest.raises(CrowdError, match=message):
        Crowd(cfg)


def test_a_non_finite_agent_position_names_the_agent():
    cfg = make_config()
    cfg.agent_position[7, 1] = np.nan
    with pytest.raises(CrowdError, match=r"agent 7: agent_position is not finite"):
        Crowd(cfg)


def test_a_singular_inverse_bind_is_named():
    # accepted before; a USD export then failed inverting it (fuzz seed 5, export:616)
    from crowd_addon.core import Skeleton
    sk = humanoid("fan", bones=24)
    inv = sk.inverse_bind.copy()
    inv[3] = 0.0
    with pytest.raises(CrowdError, match=r"skeleton 'fan': inverse_bind of bone "
                                         r"'.+' is singular"):
        Skeleton("fan", sk.bone_names, sk.parents, sk.bind_pose, inv)


# ------------------------------------------------- advance_to, on_event (issue 31)

def refused(crowd, fn, *words):
    """``fn(crowd)`` raises CrowdError with ``words``, changes nothing, and never steps:
    a refused run is refused before its first frame (before the fix
    ``advance_to(10**30)`` stepped for 13 minutes until it was killed)."""
    def step():
        pytest.fail("the crowd stepped: the run was not refused before it began")
    crowd.step = step
    try:
        before = state(crowd)
        with pytest.raises(CrowdError) as e:
            fn(crowd)
        assert_unchanged(before, state(crowd))
    finally:
        del crowd.step
    msg = str(e.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"
    crowd.step()                                      # still works afterwards
    return msg


@pytest.mark.parametrize("frame, words", [
    ("abc", ["advance_to", "'abc'", "whole number"]),
    (2.5, ["advance_to", "2.5"]),
    (None, ["advance_to", "None"]),
    (True, ["advance_to", "True"]),
])
def test_advance_to_a_frame_that_is_not_a_whole_number_is_named(busy, frame, words):
    # regression: advance_to("abc") raised int()'s bare ValueError
    refused(busy, lambda c: c.advance_to(frame), *words)


def test_advance_to_a_frame_past_the_largest_is_refused_before_stepping(busy):
    from crowd_addon.core.base.bounds import MAX_FRAME
    refused(busy, lambda c: c.advance_to(10**30), "advance_to", str(10**30),
            str(MAX_FRAME))


def test_a_run_longer_than_the_bound_is_refused_before_stepping(busy):
    """One call steps at most MAX_RUN_FRAMES frames; the error says the bound, where
    the run would start and how to split it, and changes nothing."""
    from crowd_addon.core.base.bounds import MAX_RUN_FRAMES
    now = busy.frame
    far = now + MAX_RUN_FRAMES + 1
    msg = refused(busy, lambda c: c.advance_to(far), "advance_to", f"frame {far}",
                  f"{MAX_RUN_FRAMES:,}", f"from frame {now}", "split")
    assert f"advance_to({now + MAX_RUN_FRAMES})" in msg          # the first part


def test_a_run_of_exactly_the_bound_is_not_refused(busy, monkeypatch):
    from crowd_addon.core.base.bounds import MAX_RUN_FRAMES
    steps = []

    def step():                                       # one fake step to the end
        steps.append(busy.frame)
        busy.frame += MAX_RUN_FRAMES
    monkeypatch.setattr(busy, "step", step)
    busy.advance_to(busy.frame + MAX_RUN_FRAMES)
    assert len(steps) == 1


@pytest.mark.parametrize("name, fn, words", [
    ("x", 5, ["on_event", "'x'", "5", "not callable"]),
    (5, print, ["on_event", "event name", "5"]),
    ("", print, ["on_event", "event name", "''"]),
])
def test_on_event_with_a_bad_name_or_callback_is_named(busy, name, fn, words):
    # regression: on_event("x", 5) raised a bare TypeError
    before = dict(busy.events._handlers)
    check_request(busy, lambda c: c.on_event(name, fn), *words)
    assert busy.events._handlers == before


def test_a_recording_longer_than_the_bound_is_refused_before_running():
    """A range whose poses fit in memory but that steps more than MAX_RUN_FRAMES."""
    from crowd_addon.core.base.bounds import MAX_RUN_FRAMES
    from crowd_addon.core.shots.recorder import Recorder
    crowd = Crowd(make_config())
    start = crowd.frame
    with pytest.raises(CrowdError, match=f"at most {MAX_RUN_FRAMES:,} frames.*split it"):
        Recorder(crowd, start + 1, start + MAX_RUN_FRAMES + 1)
    assert crowd.frame == start
    Recorder(crowd, start + 1, start + 10).close()                  # a short one: fine
