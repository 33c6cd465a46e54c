"""Transition slots (paper s.4.3 Listing 2; docs/architecture.md, Behaviour) and the frame's graph.

Expected poses are computed independently: clip sampling for stream targets and
``pose.blend2`` for the blend ``StartP -> TargetP`` with ``S = (F - T0) / L``.
"""

import numpy as np
import pytest

from crowd_addon.core import STREAM, TRANSITION, UNIQUE, ClipPlayer, Crowd, CrowdConfig
from crowd_addon.core.base import pose as sqt
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

M = 8


def build(NT=4, when_full="queue", agents=24):
    sk = humanoid(bones=24)
    cfg = CrowdConfig(max_offset=M, transition_slots=NT, when_full=when_full)
    cfg.add_skeleton(sk)
    for i in range(5):
        cfg.add_clip(periodic_clip(sk, f"c{i}", frames=13 + 4 * i, seed=10 + i))
    for s in range(3):
        cfg.add_stream(f"s{s}", "fan", ClipPlayer(f"c{s}"))
    cfg.add_unique("u0", "fan", ClipPlayer("c3"))
    cfg.add_unique("u1", "fan", ClipPlayer("c4"))
    cfg.add_agents(agents, streams=np.arange(agents) % 3,
                   offsets=(np.arange(agents) * 5) % M)
    crowd = Crowd(cfg)
    for _ in range(3):
        crowd.step()
    return crowd, cfg


def head(cfg, s, t):
    return cfg.clips[f"c{s}"].sample(float(t))


def test_transition_starts_at_exact_current_pose_and_row():
    crowd, _ = build()
    agents = np.array([0, 4, 7])
    poses0 = crowd.agent_poses(agents)
    rows0 = crowd.agent_rows(agents)
    res = crowd.transition_to_streamed(agents, 2, 5, offset=3)
    np.testing.assert_array_equal(np.sort(res.started), agents)
    assert res.queued.size == 0 and res.cut.size == 0
    assert (crowd.agents.kind[agents] == TRANSITION).all()
    np.testing.assert_array_equal(crowd.agent_poses(agents), poses0)
    np.testing.assert_array_equal(crowd.agent_rows(agents), rows0)
    slot_rows = crowd.storage.rows[crowd.storage.slot_base + res.slots]
    order = np.searchsorted(agents, res.started)
    np.testing.assert_array_equal(slot_rows, rows0[order])


@pytest.mark.parametrize("L,target_off", [(4, 3), (5, 0), (1, 6)])
def test_blend_follows_listing_2_and_ends_on_target(L, target_off):
    crowd, cfg = build()
    agents = np.array([1, 2, 9])
    start = crowd.agent_poses(agents).copy()
    t0 = crowd.frame
    crowd.transition_to_streamed(agents, 1, L, offset=target_off)
    for k in range(1, L + 1):
        rep = crowd.step()
        F = crowd.frame
        assert F == t0 + k
        target = head(cfg, 1, F - target_off)
        if k < L:
            assert (crowd.agents.kind[agents] == TRANSITION).all()
            s = np.float32((F - t0) / L)
            want = sqt.blend2(start, np.broadcast_to(target, start.shape), s)
            np.testing.assert_allclose(crowd.agent_poses(agents), want, atol=1e-5)
            assert rep.transitions_active == 3
        else:
            assert rep.transitions_finished == 3
    assert (crowd.agents.kind[agents] == STREAM).all()
    assert (crowd.agents.ref[agents] == 1).all()
    assert (crowd.agents.offset[agents] == target_off).all()
    assert not crowd.slots.active.any()
    for a in agents:
        np.testing.assert_array_equal(crowd.agent_poses([a])[0], crowd.pose(1, target_off))
    np.testing.assert_allclose(crowd.pose(1, target_off),
                               head(cfg, 1, crowd.frame - target_off), atol=2e-6)


def test_default_offset_is_agents_own_offset():
    crowd, _ = build()
    agents = np.array([3, 5])
    offs = crowd.agents.offset[agents].copy()
    crowd.transition_to_streamed(agents, 0, 2)
    crowd.step()
    crowd.step()
    np.testing.assert_array_equal(crowd.agents.offset[agents], offs)
    assert (crowd.agents.ref[agents] == 0).all()


def test_transition_to_unique_blends_to_unique_pose():
    crowd, cfg = build()
    a = np.array([6])
    start = crowd.agent_poses(a).copy()
    t0 = crowd.frame
    res = crowd.transition_to_unique(a, "u1", 4, restart=True)
    assert res.started.tolist() == [6]
    for k in range(1, 5):
        crowd.step()
        target = cfg.clips["c4"].sample(float(k - 1))     # restarted: time 0 next frame
        np.testing.assert_allclose(crowd.uniques.poses[1], target, atol=2e-6)
        if k < 4:
            want = sqt.blend2(start, target[None], np.float32((crowd.frame - t0) / 4))
            np.testing.assert_allclose(crowd.agent_poses(a), want, atol=1e-5)
    assert crowd.agents.kind[6] == UNIQUE and crowd.agents.ref[6] == 1
    np.testing.assert_array_equal(crowd.agent_poses(a)[0], crowd.uniques.poses[1])


def test_transition_from_transition_reuses_slot():
    crowd, cfg = build()
    res1 = crowd.transition_to_streamed([2], 0, 6, offset=1)
    crowd.step()
    crowd.step()
    mid = crowd.agent_poses([2]).copy()
    free_before = crowd.slots.free_slots().copy()
    t0 = crowd.frame
    res2 = crowd.transition_to_streamed([2], 2, 3, offset=4)
    assert res2.slots.tolist() == res1.slots.tolist()
    np.testing.assert_array_equal(crowd.slots.free_slots(), free_before)
    np.testing.assert_array_equal(crowd.agent_poses([2]), mid)
    crowd.step()
    want = sqt.blend2(mid, head(cfg, 2, crowd.frame - 4)[None], np.float32(1 / 3))
    np.testing.assert_allclose(crowd.agent_poses([2]), want, atol=1e-5)
    crowd.step()
    crowd.step()
    assert crowd.frame == t0 + 3
    assert crowd.agents.kind[2] == STREAM and crowd.agents.ref[2] == 2
    assert crowd.agents.offset[2] == 4


def test_queue_policy_fifo_as_slots_free():
    crowd, _ = build(NT=2)
    r1 = crowd.transition_to_streamed([10, 11], 0, 2, offset=0)
    assert sorted(r1.started.tolist()) == [10, 11]
    r2 = crowd.transition_to_streamed([13], 1, 3, offset=2)
    r3 = crowd.transition_to_streamed([12], 2, 3, offset=5)
    assert r2.queued.tolist() == [13] and r2.started.size == 0 and r2.cut.size == 0
    assert r3.queued.tolist() == [12]
    assert crowd.slots.queued_agents().tolist() == [13, 12]
    assert crowd.agents.kind[13] == STREAM and crowd.agents.kind[12] == STREAM
    crowd.step()
    assert crowd.agents.kind[13] == STREAM          # slots still busy
    crowd.step()                                   # 10, 11 finish
    assert crowd.agents.kind[10] == STREAM and crowd.agents.kind[11] == STREAM
    pose13 = crowd.agent_poses([13]).copy()
    rep = crowd.step()                             # queue served before the frame
    assert rep.transitions_started == 2
    assert crowd.agents.kind[13] == TRANSITION and crowd.agents.kind[12] == TRANSITION
    assert crowd.agents.ref[13] < crowd.agents.ref[12]   # FIFO: 13 took the first free slot
    np.testing.assert_array_equal(crowd.slots.start_pose[crowd.agents.ref[13]], pose13[0])
    crowd.step()
    crowd.step()
    assert crowd.agents.ref[13] == 1 and crowd.agents.offset[13] == 2
    assert crowd.agents.ref[12] == 2 and crowd.agents.offset[12] == 5


def test_queue_serves_one_slot_to_first_in_line():
    crowd, _ = build(NT=1)
    crowd.transition_to_streamed([0], 2, 1)
    crowd.transition_to_streamed([5], 2, 1)
    crowd.transition_to_streamed([4], 2, 1)        # agent 4 plays stream 1
    crowd.step()                                   # 0 finishes
    crowd.step()                                   # 5 served, finishes (L=1)
    assert crowd.agents.kind[5] == STREAM and crowd.agents.ref[5] == 2
    assert crowd.slots.queued_agents().tolist() == [4]
    assert crowd.agents.kind[4] == STREAM and crowd.agents.ref[4] == 1
    crowd.step()                                   # 4 served and done
    assert crowd.agents.ref[4] == 2 and crowd.slots.queued_agents().size == 0


def test_cut_policy_switches_immediately_without_slot():
    crowd, _ = build(NT=1, when_full="cut")
    r1 = crowd.transition_to_streamed([0, 1, 2], 2, 4, offset=6)
    assert r1.started.tolist() == [0] and r1.cut.tolist() == [1, 2]
    assert r1.queued.size == 0
    for a in (1, 2):
        assert crowd.agents.kind[a] == STREAM
        assert crowd.agents.ref[a] == 2 and crowd.agents.offset[a] == 6
        np.testing.assert_array_equal(crowd.agent_poses([a])[0], crowd.pose(2, 6))
    assert crowd.slots.active.sum() == 1
    # per request override
    r2 = crowd.transition_to_streamed([3], 0, 4, when_full="queue")
    assert r2.queued.tolist() == [3]


def test_zero_duration_cuts():
    crowd, _ = build()
    r = crowd.transition_to_streamed([4, 8], 1, 0, offset=2)
    assert r.cut.tolist() == [4, 8]
    assert r.started.size == 0 and r.queued.size == 0 and r.slots.size == 0
    assert not crowd.slots.active.any()
    np.testing.assert_array_equal(crowd.agents.offset[[4, 8]], [2, 2])
    np.testing.assert_array_equal(crowd.agent_poses([4, 8]),
                                  np.stack([crowd.pose(1, 2)] * 2))


def test_cut_agent_in_slot_frees_it():
    crowd, _ = build(NT=1)
    crowd.transition_to_streamed([0], 1, 5)
    assert crowd.slots.active.sum() == 1
    crowd.transition_to_streamed([0], 2, 0, offset=1)
    assert not crowd.slots.active.any()
    assert crowd.agents.kind[0] == STREAM and crowd.agents.ref[0] == 2


# ------------------------------------------------------------ dependency graph


def closure(graph, name):
    out, stack = set(), [name]
    while stack:
        for d in graph.deps[stack.pop()]:
            if d not in out:
                out.add(d)
                stack.append(d)
    return out


def test_graph_orders_ready_before_controllers_and_waiting_after_store():
    crowd, _ = build()
    g = crowd.graph
    waves = g.waves()
    order = [n for w in waves for n in w]
    wave_of = {n: i for i, w in enumerate(waves) for n in w}
    ctrls = [n for n in order if n.startswith("controllers.")]
    assert ctrls
    # ready transitions need no controller: they only read history
    assert not any(c.startswith("controllers.") for c in closure(g, "transitions.ready"))
    assert "roots.store" not in closure(g, "transitions.ready")
    assert wave_of["transitions.ready"] <= max(wave_of[c] for c in ctrls) + 1
    assert order.index("transitions.ready") < order.index("roots.store")
    # waiting transitions need this frame's root poses
    assert "roots.store" in closure(g, "transitions.waiting")
    assert order.index("roots.store") < order.index("transitions.waiting")
    assert wave_of["roots.store"] < wave_of["transitions.waiting"]
    for c in ctrls:
        assert order.index(c) < order.index("roots.store")
    assert order.index("transitions.waiting") < order.index("transitions.finish")
    assert order.index("transitions.finish") < order.index("skinning")
    assert order.index("transitions.finish") < order.index("events")


def test_offset_zero_target_uses_current_frame_pose():
    crowd, cfg = build()
    a = np.array([3])
    start = crowd.agent_poses(a).copy()
    t0 = crowd.frame
    crowd.transition_to_streamed(a, 0, 3, offset=0)
    crowd.step()
    want = sqt.blend2(start, head(cfg, 0, crowd.frame)[None], np.float32((crowd.frame - t0) / 3))
    np.testing.assert_allclose(crowd.agent_poses(a), want, atol=1e-5)
    # not the previous frame's head
    stale = sqt.blend2(start, head(cfg, 0, crowd.frame - 1)[None], np.float32(1 / 3))
    assert not np.allclose(crowd.agent_poses(a), stale, atol=1e-4)


# --------------------------------------------------------------- row layout


def test_agent_rows_index_layout():
    crowd, _ = build(NT=4)
    crowd.transition_to_streamed([0, 1], 2, 5, offset=3)
    crowd.transition_to_unique([2], "u1", 0)
    crowd.transition_to_unique([3], "u0", 4)
    crowd.step()
    crowd.step()
    st, S, F = crowd.storage, crowd.streams.count, crowd.frame
    assert st.unique_base == M * S and st.slot_base == M * S + crowd.uniques.count
    idx = crowd.agent_rows_index()
    for a in range(crowd.agents.count):
        k, r = int(crowd.agents.kind[a]), int(crowd.agents.ref[a])
        if k == STREAM:
            want = ((F - int(crowd.agents.offset[a])) % M) * S + r
        elif k == UNIQUE:
            want = M * S + r
        else:
            want = M * S + crowd.uniques.count + r
        assert idx[a] == want, a
    assert crowd.agents.kind[2] == UNIQUE and idx[2] == M * S + 1
    assert crowd.agents.kind[0] == TRANSITION
    np.testing.assert_array_equal(crowd.agent_rows([0, 2]), st.rows[idx[[0, 2]]])


def test_dependency_graph_runs_each_task_once_after_what_it_follows():
    from crowd_addon.core.anim.graph import DependencyGraph
    ran, g = [], DependencyGraph()
    g.add("a", lambda: ran.append("a"))
    g.add("c", lambda: ran.append("c"), after=["a"])
    g.add("b", lambda: ran.append("b"))
    g.add("d", lambda: ran.append("d"), after=["c", "b"])
    assert g.waves() == [["a", "b"], ["c"], ["d"]]
    g.run()
    g.run()
    assert ran == ["a", "b", "c", "d"] * 2
    with pytest.raises(ValueError, match="unknown tasks"):
        g.add("e", lambda: None, after=["later"])


def test_the_crowd_steps_through_its_dependency_graph(monkeypatch):
    crowd, _ = build()
    seen = []
    task = crowd.graph.tasks["roots.store"]
    monkeypatch.setitem(crowd.graph.tasks, "roots.store", lambda: (seen.append(1), task()))
    crowd.step()
    assert seen == [1]
