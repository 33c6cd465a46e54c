"""The repetition metric (core.repetition): exact screen-space neighbours, the rule for
"looks alike", and the metric of a running crowd and of its recording. The oracles
are brute force written here (every pair compared) and hand-made crowds whose value
is known."""

import numpy as np
import pytest

from crowd_addon.core import Crowd, CrowdError
from crowd_addon.core.runtime.agents import STREAM, TRANSITION, UNIQUE
from crowd_addon.core.shots.driver import FrameDriver
from crowd_addon.core.shots.recorder import Recorder
from crowd_addon.core.variety.repetition import (RepetitionSettings, crowd_repetition,
                                                 frame_repetition, measure_frames,
                                                 nearest_neighbours, recording_repetition,
                                                 screen_points)

from .test_recording import config as recording_config
from .test_recording import simulate


def brute_neighbours(xy, k):
    """Every pair's distance; the k nearest others by (distance, index)."""
    n = len(xy)
    out = np.full((n, k), -1, np.int64)
    for i in range(n):
        d = ((xy - xy[i]) ** 2).sum(1)
        d[i] = np.inf
        order = np.lexsort((np.arange(n), d))[:min(k, n - 1)]
        out[i, :order.size] = order
    return out


def clustered(rng, n):
    centres = rng.uniform(-500, 500, (4, 2))
    scales = np.array([0.5, 5.0, 50.0, 400.0])
    which = rng.integers(0, 4, n)
    return centres[which] + rng.normal(0, 1, (n, 2)) * scales[which, None]


@pytest.mark.parametrize("case", ["uniform", "clustered", "grid ties", "duplicates"])
@pytest.mark.parametrize("n,k", [(7, 3), (600, 6), (4000, 6), (9000, 4)])
def test_neighbours_are_exact(case, n, k):
    rng = np.random.default_rng(n + k)
    if case == "uniform":
        xy = rng.uniform(0, 1920, (n, 2))
    elif case == "clustered":
        xy = clustered(rng, n)
    elif case == "grid ties":                 # many equal distances: ties by index
        xy = rng.integers(0, int(np.sqrt(n)) + 2, (n, 2)).astype(float)
    else:
        xy = np.repeat(rng.uniform(0, 100, (n // 5 + 1, 2)), 5, axis=0)[:n]
    if n > 4000:
        sample = rng.choice(n, 300, replace=False)
        got = nearest_neighbours(xy, k)[sample]
        want = np.empty_like(got)
        for r, i in enumerate(sample):
            d = ((xy - xy[i]) ** 2).sum(1)
            d[i] = np.inf
            want[r] = np.lexsort((np.arange(n), d))[:k]
        np.testing.assert_array_equal(got, want)
    else:
        np.testing.assert_array_equal(nearest_neighbours(xy, k), brute_neighbours(xy, k))


def test_fewer_points_than_neighbours():
    np.testing.assert_array_equal(nearest_neighbours(np.zeros((0, 2)), 3).shape, (0, 3))
    np.testing.assert_array_equal(nearest_neighbours([[0, 0]], 2), [[-1, -1]])
    np.testing.assert_array_equal(nearest_neighbours([[0, 0], [3, 0], [1, 0]], 4),
                                  [[2, 1, -1, -1], [2, 0, -1, -1], [0, 1, -1, -1]])


def top_view(half=60.0):
    """An orthographic camera above the origin looking down: x, y in -half..half fill
    the screen."""
    m = np.eye(4)
    m[0, 0] = m[1, 1] = 1.0 / half
    m[2, 2] = -0.001
    return m


def crowd_arrays(n, rng, streams=1, max_offset=1, colors=1):
    side = int(np.ceil(np.sqrt(n)))
    pos = np.zeros((n, 3))
    pos[:, 0] = (np.arange(n) % side) * 1.1 - 50 + rng.uniform(-0.3, 0.3, n)
    pos[:, 1] = (np.arange(n) // side) * 1.1 - 50 + rng.uniform(-0.3, 0.3, n)
    kind = np.zeros(n, np.int8)
    ref = rng.integers(0, streams, n)
    offset = rng.integers(0, max_offset, n)
    palette = rng.uniform(0, 1, (colors, 3))
    color = palette[rng.integers(0, colors, n)]
    look = np.zeros(n, np.int64)
    return pos, kind, ref, offset, look, color


def brute_metric(pos, kind, ref, offset, look, color, vp, s):
    """The metric from its definition, pair by pair."""
    clip = np.c_[pos, np.ones(len(pos))] @ vp.T
    ndc = clip[:, :3] / clip[:, 3:]
    vis = np.flatnonzero((clip[:, 3] > 0) & (np.abs(ndc) <= 1).all(1))
    xy = np.c_[(ndc[vis, 0] + 1) / 2 * s.width, (ndc[vis, 1] + 1) / 2 * s.height]
    nb = brute_neighbours(xy, s.k)
    alike = pairs = 0
    for a in range(len(vis)):
        for b in nb[a][nb[a] >= 0]:
            i, j = vis[a], vis[b]
            pairs += 1
            same = kind[i] == kind[j] and kind[i] != TRANSITION and ref[i] == ref[j]
            same = same and (kind[i] == UNIQUE or abs(int(offset[i]) - int(offset[j]))
                             <= s.offset_tolerance)
            if s.appearance:
                same = same and look[i] == look[j]
                same = same and np.abs(color[i] - color[j]).max() <= s.color_tolerance
            alike += same
    return alike / pairs


def test_one_stream_at_one_offset_repeats_fully():
    rng = np.random.default_rng(3)
    arrays = crowd_arrays(900, rng)
    share, visible, pairs = frame_repetition(*arrays, top_view())
    assert share == 1.0 and visible == 900 and pairs == 900 * 6


@pytest.mark.parametrize("streams,offsets,colors,k", [(3, 10, 1, 6), (8, 60, 2, 4),
                                                     (1, 4, 3, 8), (2, 1, 1, 1)])
def test_spread_agents_match_brute_force(streams, offsets, colors, k):
    rng = np.random.default_rng(streams * 100 + offsets)
    pos, kind, ref, offset, look, color = crowd_arrays(700, rng, streams, offsets, colors)
    kind[rng.random(700) < 0.05] = TRANSITION
    uniq = rng.random(700) < 0.05
    kind[uniq], ref[uniq] = UNIQUE, rng.integers(0, 2, uniq.sum())
    look[rng.random(700) < 0.1] = 1
    pos[:40, 0] += 200                       # off screen
    s = RepetitionSettings(k=k, width=640, height=480)
    vp = top_view()
    share, visible, _ = frame_repetition(pos, kind, ref, offset, look, color, vp, s)
    assert visible == 660
    assert share == pytest.approx(brute_metric(pos, kind, ref, offset, look, color, vp, s),
                                  abs=1e-12)
    assert 0 < share < 1


def test_motion_only_compares_no_bodies_or_colours():
    """``appearance=False``: agents in step are alike whatever they wear; the value is
    the brute-force one with bodies and colours left out, and at least the full
    metric's."""
    rng = np.random.default_rng(8)
    pos, kind, ref, offset, look, color = crowd_arrays(600, rng, 3, 8, 3)
    look[rng.random(600) < 0.5] = 1
    vp = top_view()
    full = RepetitionSettings(k=6, width=640, height=480)
    motion = RepetitionSettings(k=6, width=640, height=480, appearance=False)
    got = frame_repetition(pos, kind, ref, offset, look, color, vp, motion)[0]
    assert got == pytest.approx(brute_metric(pos, kind, ref, offset, look, color, vp,
                                             motion), abs=1e-12)
    assert got > 2 * frame_repetition(pos, kind, ref, offset, look, color, vp, full)[0] > 0
    with pytest.raises(CrowdError, match="appearance must be True or False"):
        RepetitionSettings(appearance="no")


def test_each_difference_breaks_likeness():
    """Two agents side by side, k = 1: alike until one thing differs."""
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    base = dict(kind=np.array([STREAM, STREAM]), ref=np.array([0, 0]),
                offset=np.array([3, 5]), look=np.array([0, 0]),
                color=np.array([[0.2, 0.3, 0.4], [0.22, 0.3, 0.4]]))
    s = RepetitionSettings(k=1)

    def share(**change):
        a = {**base, **change}
        return frame_repetition(pos, a["kind"], a["ref"], a["offset"], a["look"],
                                a["color"], top_view(), s)[0]

    assert share() == 1.0                                       # 2 frames, 0.02 apart
    assert share(offset=np.array([3, 6])) == 0.0
    assert share(ref=np.array([0, 1])) == 0.0
    assert share(look=np.array([0, 1])) == 0.0
    assert share(color=np.array([[0.2, 0.3, 0.4], [0.3, 0.3, 0.4]])) == 0.0
    assert share(kind=np.array([TRANSITION, TRANSITION])) == 0.0
    assert share(kind=np.array([UNIQUE, UNIQUE]), offset=np.array([0, 50])) == 1.0
    assert share(kind=np.array([UNIQUE, STREAM])) == 0.0
    assert frame_repetition(pos[:1], *(v[:1] for v in base.values()), top_view(), s) == \
        (None, 1, 0)


def test_screen_points_and_visibility():
    vp = top_view(10.0)
    xy, vis = screen_points([[0, 0, 0], [10, 10, 0], [-10, 0, 0], [11, 0, 0]], vp, 200, 100)
    np.testing.assert_allclose(xy[:3], [[100, 50], [200, 100], [0, 50]])
    np.testing.assert_array_equal(vis, [True, True, True, False])
    behind = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, -1, 0]], float)
    assert not screen_points([[0, 0, 5]], behind, 10, 10)[1][0]      # w < 0


def test_a_recording_measures_what_the_running_crowd_showed():
    """The oracle is the crowd itself: the metric of ``crowd.view`` after each step,
    against the recording's at the same frames (transitions, uniques and moves
    included)."""
    crowd = Crowd(recording_config(), skinning="gpu")
    first, last = 3, 24
    vp = top_view(8.0)
    s = RepetitionSettings(k=3, offset_tolerance=1, color_tolerance=1.0)
    recorder = Recorder(crowd, first, last)
    live = {}

    def measure(crowd):
        if crowd.view.frame >= first:
            live[crowd.view.frame] = crowd_repetition(crowd.view, vp, settings=s)
    measure(crowd)
    FrameDriver(crowd, simulate, [recorder.capture, measure]).run(last)
    rec = recorder.finish()
    got = recording_repetition(rec, vp, frames=range(first, last + 1), settings=s)
    assert got.per_frame == tuple(live[f].value for f in range(first, last + 1))
    assert len(set(got.per_frame)) > 3                  # the shot changes it
    assert got.value == pytest.approx(np.mean(got.per_frame))
    assert got.as_dict()["k"] == 3 and "repetition 0." in got.line()
    default = recording_repetition(rec, vp)
    assert default.frames == tuple(measure_frames(first, last, 8))
    some = np.arange(4, 26)                  # a subset: the exported agents
    a = crowd.view.agents
    want = frame_repetition(a.position[some], a.kind[some], a.ref[some], a.offset[some],
                            crowd.view.agent_skeleton[some], a.color[some], vp, s)
    assert recording_repetition(rec, vp, [last], agents=some, settings=s).per_frame == \
        (want[0],)


def test_a_recording_searches_neighbours_again_only_when_an_agent_moved(monkeypatch):
    """The screen neighbours depend on where the agents stand, not on what they play:
    over 22 frames of the shot whose only move (frame 7) changes a position (the turn
    at 12 and the move to where it stood at 16 do not), they are searched twice, and
    the metric is the one searched afresh every frame."""
    import crowd_addon.core.variety.repetition as rep
    crowd = Crowd(recording_config(), skinning="gpu")
    first, last = 3, 24
    vp = top_view(8.0)
    s = RepetitionSettings(k=3, offset_tolerance=1, color_tolerance=1.0)
    recorder = Recorder(crowd, first, last)
    FrameDriver(crowd, simulate, [recorder.capture]).run(last)
    rec = recorder.finish()
    frames = range(first, last + 1)
    calls, real = [], rep.nearest_neighbours
    monkeypatch.setattr(rep, "nearest_neighbours", lambda *a: calls.append(1) or real(*a))
    got = recording_repetition(rec, vp, frames=frames, settings=s)
    assert len(calls) == 2
    fresh = [rep.frame_repetition(*_state_at(rec, f), vp, s,
                                  rep.stream_periods(rec.config))[0] for f in frames]
    assert got.per_frame == tuple(fresh)


def _state_at(rec, f):
    """What :func:`frame_repetition` takes of a recording at frame ``f``."""
    import crowd_addon.core.variety.repetition as rep
    agents = np.arange(rec.agent_count)
    seg = rep._last_at(rec.segment_agent, rec.segment_frame, agents, f)
    pos = rec.position.copy()
    mv = rep._last_at(rec.move_agent, rec.move_frame, agents, f, missing=True)
    pos[mv >= 0] = rec.move_position[mv[mv >= 0]]
    look = rep.body_keys(rec.config, rec.agent_skeleton)[1]
    return (pos, rec.segment_kind[seg], rec.segment_ref[seg], rec.segment_offset[seg],
            look, rep.colors_shown(rec.color, rec.palettes))


@pytest.mark.parametrize("kwargs,message", [
    ({"k": 0}, "k must be an integer >= 1"),
    ({"width": 1.5}, "width must be an integer"),
    ({"offset_tolerance": -1}, "offset_tolerance must be an integer >= 0"),
    ({"color_tolerance": 2}, "color_tolerance must be in 0..1"),
])
def test_bad_settings_are_named(kwargs, message):
    with pytest.raises(CrowdError, match=message):
        RepetitionSettings(**kwargs)


def test_bad_input_is_named():
    with pytest.raises(CrowdError, match=r"points must be \(n, 2\)"):
        nearest_neighbours(np.zeros((4, 3)), 2)
    with pytest.raises(CrowdError, match="points must be finite"):
        nearest_neighbours([[0, np.nan], [1, 1]], 1)
    with pytest.raises(CrowdError, match="view_projection must be a finite 4x4"):
        screen_points(np.zeros((2, 3)), np.eye(3), 10, 10)
    with pytest.raises(CrowdError, match="outside the shot"):
        recording_repetition(type("R", (), {"first": 0, "last": 5})(), np.eye(4), [9])


def test_offsets_a_loop_apart_look_alike():
    """On a stream that loops every P frames, offsets P apart show the same pose: the
    offset distance is taken around the loop (``stream_periods``): loops of equal
    period blended repeat, loops of different periods, a clip that holds its last
    key, or a state machine do not; a stream's speed divides its period."""
    from crowd_addon.core import Blend2, ClipPlayer, CrowdConfig, StateMachine, StateTransition
    from crowd_addon.core.variety.repetition import stream_periods
    from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip
    sk = humanoid("fan", 8)
    cfg = CrowdConfig(max_offset=60, fps=30.0)
    cfg.add_skeleton(sk)
    for name, frames in (("a", 25), ("b", 25), ("c", 31)):
        cfg.add_clip(periodic_clip(sk, name, frames=frames, seed=len(name)))
    import dataclasses
    cfg.clips["held"] = dataclasses.replace(cfg.clips["c"], name="held", loop=False)
    cfg.add_stream("loop", "fan", ClipPlayer("a"))
    cfg.add_stream("fast", "fan", ClipPlayer("a", speed=2.0), speed=1.5)
    cfg.add_stream("pair", "fan", Blend2(ClipPlayer("a"), ClipPlayer("b")))
    cfg.add_stream("mixed", "fan", Blend2(ClipPlayer("a"), ClipPlayer("c")))
    cfg.add_stream("held", "fan", ClipPlayer("held"))
    cfg.add_stream("fsm", "fan", StateMachine({"x": ClipPlayer("a"), "y": ClipPlayer("b")},
                                              [StateTransition("x", "y", 3, trigger="t")]))
    period = stream_periods(cfg)
    np.testing.assert_allclose(period[:3], [24.0, 8.0, 24.0])   # 24 / 2 / 1.5 = 8
    assert np.isinf(period[3:]).all()
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    same = dict(kind=np.zeros(2, np.int8), look=np.zeros(2), color=np.zeros((2, 3)))
    s = RepetitionSettings(k=1)

    def alike(stream, offsets):
        return frame_repetition(pos, same["kind"], np.array([stream, stream]),
                                np.array(offsets), same["look"], same["color"], top_view(),
                                s, period)[0]

    assert alike(0, [0, 24]) == 1.0 and alike(0, [0, 23]) == 1.0 and alike(0, [3, 50]) == 1.0
    assert alike(0, [0, 12]) == 0.0
    assert alike(1, [0, 16]) == 1.0 and alike(1, [0, 4]) == 0.0
    assert alike(3, [0, 24]) == 0.0 and alike(4, [0, 30]) == 0.0
    assert frame_repetition(pos, same["kind"], np.array([0, 0]), np.array([0, 24]),
                            same["look"], same["color"], top_view(), s)[0] == 0.0


def test_palette_colours_count_as_colour():
    """Two neighbours on one stream in step look alike until their palette colours
    (a shirt) differ; agents without palettes compare by their colour alone."""
    from crowd_addon.core.variety.repetition import colors_shown
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    same = (np.zeros(2, np.int8), np.zeros(2, int), np.zeros(2, int), np.zeros(2))
    pal = np.full((2, 4, 3), -1.0)
    pal[:, 2] = [(0.9, 0.1, 0.1), (0.9, 0.1, 0.1)]
    s = RepetitionSettings(k=1)
    shown = colors_shown(np.zeros((2, 3)), pal)
    assert shown.shape == (2, 15)
    assert frame_repetition(pos, *same, shown, top_view(), s)[0] == 1.0
    pal[1, 2] = (0.1, 0.2, 0.9)
    assert frame_repetition(pos, *same, colors_shown(np.zeros((2, 3)), pal), top_view(),
                            s)[0] == 0.0
    pal[1, 2] = -1                                          # one has none: different
    assert frame_repetition(pos, *same, colors_shown(np.zeros((2, 3)), pal), top_view(),
                            s)[0] == 0.0
