"""Event tags (paper s.3.3; docs/architecture.md: delayed per offset, once per crossing,
one callback per (event, frame) with all agent ids.

Expected firings are computed independently from the clip period and tag time:
an agent at offset ``O`` on a stream whose head time is the frame number has
delayed time ``F - O``; a tag ``tau`` fires at frame ``F`` when
``(F - 1 - O, F - O]`` contains ``tau + k * period``.
"""

from collections import defaultdict

import numpy as np

from crowd_addon.core import TRANSITION, UNIQUE, ClipPlayer, Crowd, CrowdConfig
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

M = 10
N = 24
# clip name -> (frames, tags)
CLIPS = {
    "c0": (13, [("clap", 5), ("stomp", 7.5)]),       # period 12
    "c1": (17, [("wave", 3)]),                        # period 16
    "c2": (15, [("cheer", 4)]),                       # period 14, the unique
}


def build(n=N, slots=4):
    sk = humanoid(bones=24)
    cfg = CrowdConfig(max_offset=M, transition_slots=slots)
    cfg.add_skeleton(sk)
    for i, (name, (frames, tags)) in enumerate(CLIPS.items()):
        cfg.add_clip(periodic_clip(sk, name, frames=frames, seed=i, events=tags))
    cfg.add_stream("s0", "fan", ClipPlayer("c0"))
    cfg.add_stream("s1", "fan", ClipPlayer("c1"))
    cfg.add_unique("u0", "fan", ClipPlayer("c2"))
    a = np.arange(n)
    offsets = (a // 2) % M if n == N else a % M
    cfg.add_agents(n, streams=a % 2, offsets=offsets)
    return Crowd(cfg), cfg


def crosses(t, tau, period):
    """Does clip time going from t-1 (excluded) to t cross tau (looping)?"""
    t = np.asarray(t, np.float64)
    return np.floor((t - tau) / period) - np.floor((t - 1 - tau) / period) > 0


def tag_info(name):
    for clip, (frames, tags) in CLIPS.items():
        for n, tau in tags:
            if n == name:
                return int(clip[1]), float(tau), frames - 1
    raise KeyError(name)


class Recorder:
    def __init__(self):
        self.calls = []                                # (name, frame, ids)

    def __call__(self, name, frame, ids):
        self.calls.append((name, int(frame), np.array(ids)))

    def by_frame(self, name):
        out = defaultdict(list)
        for n, f, ids in self.calls:
            if n == name:
                out[f].append(ids)
        return out


def test_tag_fires_offset_frames_after_head():
    crowd, cfg = build()
    rec = Recorder()
    crowd.on_event("clap", rec)
    f0 = crowd.frame
    for _ in range(40):
        crowd.step()
    end = crowd.frame
    # frames at which the head (offset 0, time == frame) crossed clap (5 mod 12)
    heads = [h for h in range(f0 - M, end + 1) if crosses(h, 5, 12)]
    got = rec.by_frame("clap")
    for a in range(0, N, 2):                           # the agents on stream 0
        o = (a // 2) % M
        frames = sorted(f for f, lst in got.items() for ids in lst if a in ids)
        assert frames == [h + o for h in heads if f0 < h + o <= end], (a, o)


def test_one_fire_per_agent_per_crossing_over_many_loops():
    crowd, cfg = build()
    rec = Recorder()
    for name in ("clap", "stomp", "wave"):
        crowd.on_event(name, rec)
    f0 = crowd.frame
    steps = 5 * 16 + 3
    for _ in range(steps):
        crowd.step()
    for name in ("clap", "stomp", "wave"):
        s, tau, period = tag_info(name)
        count = np.zeros(N, np.int64)
        for n, f, ids in rec.calls:
            if n == name:
                np.add.at(count, ids, 1)
        want = np.zeros(N, np.int64)
        for a in range(N):
            if a % 2 != s:
                continue
            o = (a // 2) % M
            frames = np.arange(f0 + 1, f0 + steps + 1)
            want[a] = int(crosses(frames - o, tau, period).sum())
        np.testing.assert_array_equal(count, want, err_msg=name)
        assert want[np.arange(N) % 2 == s].min() >= 4       # several loops each


def test_reset_frame_dispatches_history_crossings():
    crowd, cfg = build()
    rec = Recorder()
    crowd.on_event("clap", rec)
    crowd.reset(30)
    got = rec.by_frame("clap")
    assert set(got) <= {30}
    ids = np.concatenate(got[30]) if got else np.zeros(0, np.int64)
    want = [a for a in range(N) if a % 2 == 0 and crosses(30 - (a // 2) % M, 5, 12)]
    assert sorted(ids.tolist()) == want


def test_one_callback_per_event_and_frame_with_all_ids():
    crowd, cfg = build()
    rec = Recorder()
    crowd.on_event("clap", rec)
    crowd.on_event("wave", rec)
    f0 = crowd.frame
    for _ in range(30):
        crowd.step()
    seen = set()
    for name, f, ids in rec.calls:
        assert (name, f) not in seen, "more than one call for one (event, frame)"
        seen.add((name, f))
        assert ids.ndim == 1 and np.issubdtype(ids.dtype, np.integer)
        assert np.all(np.diff(ids) > 0)              # ascending, no duplicates
        s, tau, period = tag_info(name)
        want = [a for a in range(N)
                if a % 2 == s and crosses(f - (a // 2) % M, tau, period)]
        assert ids.tolist() == want
    # frames where several agents share a crossing got them in one array
    assert any(ids.size > 1 for _, _, ids in rec.calls)
    assert {f for _, f, _ in rec.calls} <= set(range(f0 + 1, f0 + 31))


def test_agents_in_transition_get_target_events():
    crowd, cfg = build()
    rec = Recorder()
    crowd.on_event("*", rec)
    for _ in range(4):
        crowd.step()
    a, target_off = 0, 6                                # agent 0: stream 0, offset 0
    t0 = crowd.frame
    crowd.transition_to_streamed([a], 1, 8, offset=target_off)
    steps = 40
    for k in range(steps):
        crowd.step()
        if k < 7:
            assert crowd.agents.kind[a] == TRANSITION
    mine = defaultdict(list)
    for n, f, ids in rec.calls:
        if f > t0 and a in ids:
            mine[n].append(f)
    assert "clap" not in mine and "stomp" not in mine
    want = [f for f in range(t0 + 1, t0 + steps + 1) if crosses(f - target_off, 3, 16)]
    assert any(f < t0 + 8 for f in want), "test should cover a fire during the blend"
    assert mine["wave"] == want


def test_unique_events_fire_for_agents_on_unique():
    crowd, cfg = build()
    rec = Recorder()
    crowd.on_event("cheer", rec)
    for _ in range(2):
        crowd.step()
    on_u = np.array([3, 8, 15])
    blending = np.array([20])
    t0 = crowd.frame
    crowd.transition_to_unique(on_u, "u0", 0, restart=True)
    crowd.transition_to_unique(blending, "u0", 9, restart=True)
    assert (crowd.agents.kind[on_u] == UNIQUE).all()
    assert crowd.agents.kind[20] == TRANSITION
    steps = 45
    for _ in range(steps):
        crowd.step()
    # restarted: unique time is F - (t0 + 1); cheer at 4, period 14
    want = [f for f in range(t0 + 1, t0 + steps + 1) if crosses(f - t0 - 1, 4, 14)]
    got = rec.by_frame("cheer")
    assert sorted(got) == sorted(set(want))
    for f in want:
        assert len(got[f]) == 1
        assert got[f][0].tolist() == sorted(on_u.tolist() + blending.tolist())


def test_raising_callback_is_recorded_and_crowd_keeps_stepping():
    crowd, cfg = build()
    rec = Recorder()

    def boom(name, frame, ids):
        raise RuntimeError("simulation bug")

    crowd.on_event("clap", boom)
    crowd.on_event("clap", rec)
    f0 = crowd.frame
    for _ in range(30):
        crowd.step()
    assert crowd.frame == f0 + 30
    errs = crowd.events.errors                 # the newest kept, the rest counted
    assert len(errs) + crowd.events.errors_dropped == len(rec.calls) > 0
    assert crowd.events.error_counts[boom] == len(rec.calls)
    assert all(isinstance(e.error, RuntimeError) and e.event == "clap" for e in errs)
    assert [e.frame for e in errs] == [f for _, f, _ in rec.calls][-len(errs):]


def test_star_handler_receives_all_events():
    crowd, cfg = build()
    star, named = Recorder(), Recorder()
    crowd.on_event("*", star)
    for n in ("clap", "stomp", "wave", "cheer"):
        crowd.on_event(n, named)
    crowd.transition_to_unique([5], "u0", 0, restart=True)
    for _ in range(35):
        crowd.step()
    key = lambda c: (c[1], c[0])                       # noqa: E731
    a = sorted(((n, f, ids.tolist()) for n, f, ids in star.calls), key=key)
    b = sorted(((n, f, ids.tolist()) for n, f, ids in named.calls), key=key)
    assert a == b
    assert {n for n, _, _ in a} == {"clap", "stomp", "wave", "cheer"}


def test_events_follow_agents_after_many_reassignments():
    """Enough cuts to push the agent index through its overlay and a rebuild."""
    n = 3000
    crowd, cfg = build(n, slots=2)
    rng = np.random.default_rng(4)
    for _ in range(6):
        agents = rng.choice(n, 400, replace=False)
        crowd.transition_to_streamed(agents, int(rng.integers(2)), 0,
                                     offset=rng.integers(0, M, 400))
        crowd.step()
    stream, offset = crowd.agents.ref.copy(), crowd.agents.offset.copy()
    count = {name: np.zeros(n, np.int64) for name in ("clap", "stomp", "wave")}

    def rec(name, frame, ids):
        np.add.at(count[name], ids, 1)

    crowd.on_event("*", rec)
    f0 = crowd.frame
    for _ in range(33):
        crowd.step()
    frames = np.arange(f0 + 1, f0 + 34)
    for name in count:
        s, tau, period = tag_info(name)
        want = np.where(stream == s,
                        crosses(frames[None] - offset[:, None], tau, period).sum(1), 0)
        np.testing.assert_array_equal(count[name], want, err_msg=name)


def test_advance_to_backwards_replays_the_same_events():
    crowd, cfg = build()
    rec = Recorder()
    crowd.on_event("*", rec)
    crowd.reset()
    crowd.advance_to(25)
    first = [(n, f, ids.tolist()) for n, f, ids in rec.calls]
    rec.calls.clear()
    crowd.advance_to(7)                               # reset + re-simulate 0..7
    crowd.advance_to(25)
    again = [(n, f, ids.tolist()) for n, f, ids in rec.calls]
    assert first == again and len(first) > 5


def test_shared_tag_name_on_two_streams_gives_one_sorted_call():
    sk = humanoid(bones=24)
    cfg = CrowdConfig(max_offset=M, transition_slots=2)
    cfg.add_skeleton(sk)
    cfg.add_clip(periodic_clip(sk, "a", frames=9, seed=1, events=[("go", 2)]))
    cfg.add_clip(periodic_clip(sk, "b", frames=13, seed=2, events=[("go", 6)]))
    cfg.add_stream("sa", "fan", ClipPlayer("a"))
    cfg.add_stream("sb", "fan", ClipPlayer("b"))
    a = np.arange(N)
    cfg.add_agents(N, streams=(a // 3) % 2, offsets=(a * 7) % M)
    crowd = Crowd(cfg)
    crowd.transition_to_streamed([0, 23], 1, 0, offset=4)   # overlay entries
    rec = Recorder()
    crowd.on_event("go", rec)
    f0 = crowd.frame
    for _ in range(30):
        crowd.step()
    stream, offset = crowd.agents.ref, crowd.agents.offset
    frames = [f for _, f, _ in rec.calls]
    assert len(frames) == len(set(frames))
    for f in range(f0 + 1, f0 + 31):
        want = [i for i in range(N)
                if crosses(f - offset[i], *((2, 8) if stream[i] == 0 else (6, 12)))]
        got = [ids.tolist() for _, g, ids in rec.calls if g == f]
        assert got == ([want] if want else []), f
    assert any(len(set(stream[ids])) == 2 for _, _, ids in rec.calls)


def test_stream_events_are_the_head_crossings_of_the_last_m_frames():
    crowd, cfg = build()
    for _ in range(30):
        crowd.step()
    stream, name, frame = crowd.view.stream_events(crowd.frame - M + 1)
    expected = []
    for tag in ("clap", "stomp", "wave"):
        s, tau, period = tag_info(tag)
        expected += [(s, tag, h) for h in range(crowd.frame - M + 1, crowd.frame + 1)
                     if crosses(h, tau, period)]
    assert sorted(zip(stream.tolist(), name.tolist(), frame.tolist())) == sorted(expected)
    assert len(expected) >= 1
    since = crowd.frame - 1
    later = crowd.view.stream_events(since)[2]
    assert sorted(later.tolist()) == sorted(f for f in frame.tolist() if f >= since)


def test_a_callback_that_always_raises_costs_bounded_memory_and_log(caplog):
    """Regression: every error was kept with its traceback (207 MB after 3,000 frames)
    and logged. Now the newest few are kept, the rest counted per callback."""
    from crowd_addon.core.runtime.events import KEPT_ERRORS, LOGGED_ERRORS, EventDispatcher
    d = EventDispatcher("test")

    def boom(name, frame, ids):
        raise RuntimeError(f"bug at {frame}")

    d.on("clap", boom)
    with caplog.at_level("ERROR", logger="crowd_addon.events"):
        for f in range(500):
            d.dispatch(f, "clap", np.arange(3))
    assert len(d.errors) == KEPT_ERRORS
    assert [e.frame for e in d.errors] == list(range(500 - KEPT_ERRORS, 500))
    assert d.errors_dropped == 500 - KEPT_ERRORS
    assert d.error_counts[boom] == 500
    assert len(caplog.records) == LOGGED_ERRORS
    assert "counted, not logged" in caplog.records[-1].getMessage()
