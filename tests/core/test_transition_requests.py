"""Transition requests keep their promises (defects found by probing): the queue is
first in, first out; no slots at all never strands a request; a request is validated
before anything changes."""

import numpy as np
import pytest

from crowd_addon.core import Crowd, CrowdConfig, CrowdError
from crowd_addon.core.authoring import synthetic
from crowd_addon.core.runtime.agents import STREAM, TRANSITION
from crowd_addon.core.anim.controllers import ClipPlayer


def test_queue_is_first_in_first_out_when_a_slot_frees_between_steps(two_streams):
    """A request made after a slot frees but before the next step used to take the
    free slot ahead of agents already waiting (who could starve)."""
    c = two_streams(slots=2)
    c.transition_to_streamed([0, 1], "idle", 2)               # both slots busy
    r = c.transition_to_streamed([2, 3], "idle", 2)           # wait, 2 then 3
    assert r.queued.tolist() == [2, 3]
    c.step()
    c.step()                                                  # 0 and 1 finish: 2 slots free
    assert c.slots.free_slots().size == 2 and list(c.slots.queue) == [2, 3]
    late = c.transition_to_streamed([4], "idle", 2)           # asks now, arrived last
    assert late.queued.tolist() == [4] and late.started.size == 0
    served = set(c.slots.agent[c.slots.active_slots()].tolist())
    assert served == {2, 3}
    c.step()
    c.step()                                                  # 2 and 3 finish
    assert c.agents.kind[4] == STREAM and list(c.slots.queue) == [4]
    c.step()
    assert c.agents.kind[4] == TRANSITION                     # its turn came next


def test_served_in_request_order_over_a_long_interleaving(two_streams):
    """Two requests a frame for three slots and 3-6 frame blends: the queue is always in
    use, slots free during steps and requests arrive between them."""
    c = two_streams(slots=3, agents=60)
    rng = np.random.default_rng(1)
    started = []

    def newly_started(before):
        now = c.slots.agent[c.slots.active_slots()].tolist()
        return [a for a in now if a not in before]

    for i in range(0, 60, 2):
        before = set(c.slots.agent[c.slots.active_slots()].tolist())
        c.transition_to_streamed([i, i + 1], "idle" if i % 4 else "walk",
                                 int(rng.integers(3, 7)))
        started += sorted(newly_started(before))
        before = set(c.slots.agent[c.slots.active_slots()].tolist())
        c.step()
        started += sorted(newly_started(before))
    assert len(started) >= 20
    # first come, first served: the served are exactly the first requests, in order
    # (a later request jumping the queue leaves a gap: the waiting starve)
    assert started == list(range(len(started)))


def test_no_slots_cuts_instead_of_queueing_forever(two_streams):
    c = two_streams(slots=0)
    r = c.transition_to_streamed([1, 2], "idle", 5)           # policy "queue" by default
    assert r.cut.tolist() == [1, 2] and r.queued.size == 0 and not c.slots.queue
    assert (c.agents.kind[[1, 2]] == STREAM).all() and (c.agents.ref[[1, 2]] == 1).all()


@pytest.mark.parametrize("duration", [1e30, 2.0 ** 31, float("inf")])
def test_a_huge_duration_is_refused_before_anything_changes(two_streams, duration):
    c = two_streams(slots=2)
    with pytest.raises(CrowdError, match="duration"):
        c.transition_to_streamed([5], "idle", duration)
    assert c.agents.kind[5] == STREAM and c.slots.free_slots().size == 2


def test_an_empty_unique_request_leaves_its_clock_alone():
    skel = synthetic.humanoid(bones=24)
    cfg = CrowdConfig(max_offset=6, transition_slots=2)
    cfg.add_skeleton(skel)
    cfg.add_clip(synthetic.periodic_clip(skel, "walk", frames=9, seed=1))
    cfg.add_clip(synthetic.periodic_clip(skel, "solo", frames=11, seed=2))
    cfg.add_stream("walk", skel.name, ClipPlayer("walk"))
    cfg.add_unique("solo", skel.name, ClipPlayer("solo"))
    cfg.add_agents(4, streams=np.zeros(4, np.int64), seed=3)
    c = Crowd(cfg)
    for _ in range(3):
        c.step()
    start = c.uniques.start.copy()
    r = c.transition_to_unique([], "solo", 4)
    assert r.started.size == 0
    np.testing.assert_array_equal(c.uniques.start, start)


def test_a_parameter_that_is_not_a_number_is_named(two_streams):
    c = two_streams(slots=1)
    with pytest.raises(CrowdError, match="parameter 'speed': value must be a number, got 'fast'"):
        c.set_parameter("walk", "speed", "fast")
