"""AgentState: read-only agent arrays and the change log readers use instead of diffs."""

import numpy as np
import pytest

from crowd_addon.core import CrowdError
from crowd_addon.core.runtime.agents import STREAM, TRANSITION, UNIQUE, AgentState


def state(n=10):
    return AgentState(np.zeros((n, 3)), np.zeros(n), np.full((n, 3), 0.5))


def test_new_reader_gets_everything_then_only_what_changed():
    a = state()
    first = a.changes_since(0)
    assert first.agents is None and first.moved
    again = a.changes_since(first.cursor)
    assert again.agents.size == 0 and not again.moved
    a.set_animation([3, 1], UNIQUE, 0)
    a.set_animation([1, 7], STREAM, 2, offset=[4, 5])
    ch = a.changes_since(again.cursor)
    np.testing.assert_array_equal(ch.agents, [1, 3, 7])
    assert not ch.moved
    assert a.offset[7] == 5 and a.kind[3] == UNIQUE
    a.place([2], heading=1.5)
    ch2 = a.changes_since(ch.cursor)
    np.testing.assert_array_equal(ch2.agents, [2])
    assert ch2.moved
    # an older cursor still sees everything since it
    np.testing.assert_array_equal(a.changes_since(again.cursor).agents, [1, 2, 3, 7])


def test_reset_and_a_far_behind_reader_read_everything():
    a = state(4)
    cur = a.changes_since(0).cursor
    a.reset(np.zeros(4), np.arange(4), np.zeros(4))
    assert a.changes_since(cur).agents is None
    cur = a.changes_since(cur).cursor
    assert a.changes_since(cur).agents.size == 0       # up to date after reading "all"
    for _ in range(5000):                              # more logged ids than agents
        a.set_animation([0], STREAM, 1)
    assert a.changes_since(cur).agents is None


def test_arrays_are_read_only_views():
    a = state()
    for name in ("kind", "ref", "offset", "position", "heading", "color"):
        with pytest.raises(ValueError):
            getattr(a, name)[0] = 1


@pytest.mark.parametrize("kwargs, match", [
    ({"position": [[0, 0, 0], [1, 1, 1]]}, "position"),
    ({"heading": np.nan}, "heading must be finite"),
    ({"color": [1, 2]}, "color"),
])
def test_place_rejects_bad_values_and_changes_nothing(kwargs, match):
    a = state()
    cur = a.changes_since(0).cursor
    before = (a.position.copy(), a.heading.copy(), a.color.copy())
    with pytest.raises(CrowdError, match=match):
        a.place([1, 2, 3], **kwargs)
    for x, y in zip(before, (a.position, a.heading, a.color)):
        np.testing.assert_array_equal(x, y)
    assert a.changes_since(cur).agents.size == 0


def test_place_names_a_bad_id():
    with pytest.raises(CrowdError, match="agent id 10 out of range 0..9"):
        state().place([10], heading=0.0)


def test_crowd_logs_every_agent_it_changes(two_streams):
    crowd = two_streams(2, 8, np.arange(8) % 2)
    cur = crowd.view.agent_changes(0).cursor
    r = crowd.transition_to_streamed([0, 1, 2, 3], "idle", 3, offset=1)   # 2 start, 2 queue
    ch = crowd.view.agent_changes(cur)
    np.testing.assert_array_equal(ch.agents, np.sort(r.started))
    cur = ch.cursor
    seen = set()
    for _ in range(10):
        crowd.step()
        ch = crowd.view.agent_changes(cur)
        cur = ch.cursor
        seen.update(ch.agents.tolist())
    assert seen == {0, 1, 2, 3}                       # queued ones served, all finished
    assert (crowd.agents.kind[:4] == STREAM).all() and (crowd.agents.offset[:4] == 1).all()
    crowd.place_agents([5], position=(1.0, 2.0, 0.0))
    ch = crowd.view.agent_changes(cur)
    assert ch.moved and ch.agents.tolist() == [5]
    np.testing.assert_array_equal(crowd.agents.position[5], (1.0, 2.0, 0.0))


def test_view_reports_the_transition_of_blending_agents(two_streams):
    crowd = two_streams(2, 8, np.arange(8) % 2)
    crowd.step()
    shown = crowd.view.agent_poses([4])
    crowd.transition_to_streamed([4], "walk", 5, offset=2)
    tr = crowd.view.transitions([4])
    assert crowd.agents.kind[4] == TRANSITION
    np.testing.assert_array_equal(tr["start_pose"][0], shown[0])
    assert (tr["t0"][0], tr["length"][0], tr["target_ref"][0], tr["target_offset"][0]) == \
        (crowd.frame, 5, 0, 2)
    with pytest.raises(CrowdError, match="agent 5 is not in a transition"):
        crowd.view.transitions([5])


def test_the_log_covers_every_change_a_diff_would_find(two_streams):
    """Property: over a random session (transitions that queue, cuts, uniques-free
    streams, moves), the agents the log reports each frame include every agent whose
    arrays differ from the last read."""
    crowd = two_streams(3, 8, np.arange(8) % 2)
    rng = np.random.default_rng(5)
    a = crowd.agents
    cursor = crowd.view.agent_changes(0).cursor
    last = [x.copy() for x in (a.kind, a.ref, a.offset, a.position, a.heading, a.color)]
    for _ in range(60):
        who = rng.choice(8, rng.integers(1, 4), replace=False)
        pick = rng.integers(4)
        if pick == 0:
            crowd.transition_to_streamed(who, int(rng.integers(2)), int(rng.integers(0, 5)),
                                         when_full=("queue", "cut")[int(rng.integers(2))])
        elif pick == 1:
            crowd.place_agents(who, position=rng.normal(size=(who.size, 3)))
        elif pick == 2:
            crowd.place_agents(who, color=rng.random(3))
        crowd.step()
        now = (a.kind, a.ref, a.offset, a.position, a.heading, a.color)
        diff = np.zeros(8, bool)
        for x, y in zip(now, last):
            d = x != y
            diff |= d if d.ndim == 1 else d.any(1)
        ch = crowd.view.agent_changes(cursor)
        cursor = ch.cursor
        assert set(np.flatnonzero(diff)) <= set(ch.agents.tolist())
        moved = ((now[3] != last[3]).any(1) | (now[4] != last[4])).any()
        assert ch.moved or not moved
        last = [x.copy() for x in now]


def test_an_up_to_date_reader_never_rereads_everything():
    """The log forgets its oldest entries, not the newest: a reader that keeps up gets
    only what changed however long the session (a regression: the whole log was
    dropped past N ids and every reader re-sent every agent)."""
    a = state(100)
    fast = slow = a.changes_since(0).cursor
    for i in range(20_000):
        a.set_animation([i % 100, (i * 7) % 100], STREAM, i % 3)
        ch = a.changes_since(fast)
        assert ch.agents is not None and ch.agents.size in (1, 2)
        fast = ch.cursor
    assert a.changes_since(slow).agents is None           # fell behind: read everything
    assert len(a._log) < 10_000                           # the forgotten are freed
