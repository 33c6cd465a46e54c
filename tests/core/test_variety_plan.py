"""The variety planner (core.variety_plan): its input from a configuration, its
candidates within the budget, and its choice. Oracles: the metric's own definition
on the same agents (every candidate's value is what ``frame_repetition`` gives for
the streams and offsets it draws), the memory model (``budget.plan`` with S and M
fixed), and the hand-checkable ordering (Spread offsets and more keys repeat less)."""

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, CrowdConfig, CrowdError
from crowd_addon.core.runtime.agents import STREAM, UNIQUE
from crowd_addon.core.planning.budget import plan as budget_plan
from crowd_addon.core.variety.repetition import RepetitionSettings, frame_repetition
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip
from crowd_addon.core.variety.timing import Timing, expand
from crowd_addon.core.planning.variety_plan import _assign, plan_input, plan_variety

N, SIDE = 3000, 60
TOP = np.diag([1 / 40, 1 / 40, -0.001, 1.0])
TOP[:2, 3] = -1


def config(timing=Timing(), m=30, clip_frames=(200, 200, 121)):
    sk = humanoid("fan", 16)
    cfg = CrowdConfig(max_offset=m, transition_slots=10, seed=4)
    cfg.add_skeleton(sk)
    for i, f in enumerate(clip_frames):
        cfg.add_clip(periodic_clip(sk, f"c{i}", frames=f, seed=i))
        for name, speed, phase in expand(f"s{i}", timing if i == 0 else Timing(), m):
            cfg.add_stream(name, "fan", ClipPlayer(f"c{i}"), speed, phase,
                           f"s{i}" if timing.count > 1 and i == 0 else "")
    cfg.add_unique("solo", "fan", ClipPlayer("c0"))
    pos = np.zeros((N, 3))
    pos[:, 0], pos[:, 1] = np.arange(N) % SIDE * 1.2, np.arange(N) // SIDE * 1.5
    cfg.add_agents(N, positions=pos, colors=np.full((N, 3), 0.4))
    cfg.agent_stream[7], cfg.agent_unique[7] = -1, 0
    return cfg


def test_the_input_groups_streams_by_template():
    cfg = config(Timing(0.8, 1.2, 2, 3))
    inp = plan_input(cfg)
    assert [t.name for t in inp.templates] == ["s0", "s1", "s2"]
    assert [t.period for t in inp.templates] == pytest.approx([199, 199, 120])
    np.testing.assert_allclose(inp.periods, [199 / 0.9] * 3 + [199 / 1.1] * 3 + [199, 120])
    assert inp.templates[0].speeds == (0.9, 1.1) and inp.copies == (3, 1, 1)
    assert inp.templates[2].clip_frames == 120             # 121 keys loop every 120 frames
    st = cfg.agent_stream
    # streams 0..5 are s0 (2 speeds x 3 copies), then s1, s2
    np.testing.assert_array_equal(inp.template[st >= 0],
                                  np.array([0] * 6 + [1, 2])[st[st >= 0]])
    np.testing.assert_array_equal(inp.speed[st >= 0],
                                  np.array([0, 0, 0, 1, 1, 1, 0, 0])[st[st >= 0]])
    assert inp.template[7] == -1 and inp.unique[7] == 0 and inp.uniques == 1
    assert inp.bones == 16 and inp.slots == 10 and inp.max_offset == 30


def test_every_candidate_is_the_metric_of_what_it_draws():
    inp = plan_input(config())
    s = RepetitionSettings(k=4)
    result = plan_variety(inp, TOP, 5e6, s, m_choices=(15, 30, 60), copy_choices=(1, 2),
                          offset_modes=("UNIFORM", "SPREAD"))
    n = 0
    grid = [(m, c, mode) for m in (15, 30, 60) for c in (1, 2) for mode in ("UNIFORM",
                                                                             "SPREAD")]
    for k, (m, c, mode) in enumerate(grid):
        cand = result.candidates[n]
        assert (cand.max_offset, cand.copies, cand.offset_mode) == (m, c, mode)
        n += 1
        stream, off = _assign(inp, m, cand.template_copies, mode, inp.seed + 17 * k)
        kind = np.where(stream >= 0, STREAM, UNIQUE)
        # the streams' loops: template, then its copies (s2 loops every 120 frames)
        period = np.repeat([199.0, 199.0, 120.0], cand.template_copies)
        want = frame_repetition(inp.positions, kind, np.where(stream >= 0, stream,
                                                              inp.unique),
                                off, inp.look, inp.colors, TOP, s, period)[0]
        assert cand.repetition == pytest.approx(want, abs=1e-12)
        # memory: the model's rows for S and M
        want_bytes = budget_plan(N, 1e12, 16, [m], max_offset=m, streams=cand.streams,
                                 unique_agents=1, transition_slots=10).bytes_used
        assert cand.bytes == want_bytes == (m * cand.streams + 11) * 16 * 48
        # copies are capped per template by its clip: s2 loops every 120 frames
        assert cand.template_copies == tuple(min(c, max(1, f // m)) for f in (199, 199, 120))
    # the default is the configuration's own agents
    d = result.default
    assert (d.max_offset, d.streams, d.offset_mode) == (30, 3, "AS IS")
    cfg = config()
    st = cfg.agent_stream
    want = frame_repetition(cfg.agent_position, np.where(st >= 0, STREAM, UNIQUE),
                            np.where(st >= 0, st, 0), cfg.agent_offset, np.zeros(N),
                            cfg.agent_color, TOP, s, [199.0, 199.0, 120.0])[0]
    assert d.repetition == pytest.approx(want)


def test_the_plan_repeats_less_within_the_budget_and_stream_cap():
    inp = plan_input(config(Timing(0.9, 1.1, 2)))
    budget = 4e6
    result = plan_variety(inp, TOP, budget, max_streams=12)
    p, d = result.planned, result.default
    assert p.fits and p.bytes <= budget and p.streams <= 12
    assert p.repetition < d.repetition / 10
    assert p.offset_mode == "SPREAD"
    over = [c for c in result.candidates if not c.fits]
    assert over and all(c.bytes > budget or c.streams > 12 for c in over)
    assert all(c.repetition is None for c in over)
    best = min(c.repetition for c in result.candidates if c.fits)
    assert p.repetition <= best * 1.02
    uniform = {(c.max_offset, c.copies): c.repetition for c in result.candidates
               if c.offset_mode == "UNIFORM" and c.fits}
    assert uniform[60, 1] < uniform[15, 1]            # more keys, less repetition
    out = result.as_dict()
    assert out["repetition_default"] == d.repetition
    assert out["repetition_planned"] == p.repetition
    assert len(out["candidates"]) == len(result.candidates)


def test_what_cannot_be_planned_is_named():
    inp = plan_input(config())
    with pytest.raises(CrowdError, match="no candidate fits 1,000 B"):
        plan_variety(inp, TOP, 1000)
    with pytest.raises(CrowdError, match="the budget must be a positive number"):
        plan_variety(inp, TOP, -5)
    cfg = config()
    cfg.agent_stream[:], cfg.agent_unique[:] = -1, 0
    with pytest.raises(CrowdError, match="no agent plays a stream"):
        plan_variety(plan_input(cfg), TOP, 1e9)
