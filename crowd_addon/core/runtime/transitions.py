"""Transition slots (paper s.4.3, Listing 2): ``NT`` pre-allocated blends.

A slot blends one agent from a fixed start pose ``StartP`` (the agent's pose when
the request was served) to ``TargetP``, read every frame from the target: the
stream's history ``PH_B(O_B)`` or a unique's current pose ``P_B``. With
``S = (F - T0) / L`` the slot's pose is ``StartP + (TargetP - StartP) * S``
(nlerp for rotations). When ``S`` reaches 1 the agent becomes ``(B, O_B)`` (or
unique ``B``) and the slot is freed.

When every slot is busy a request waits in a FIFO queue (``"queue"``, default) or
switches the agent at once without a blend (``"cut"``); :class:`TransitionResult`
tells the caller which happened to each agent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base import pose as sqt
from .agents import STREAM, TRANSITION, UNIQUE
from .request_queue import RequestQueue
from ..base.errors import CrowdError

#: What a request does when every slot is busy: wait in the queue, or cut at once.
WHEN_FULL = ("queue", "cut")

__all__ = ["TransitionSlots", "TransitionResult", "MAX_DURATION", "WHEN_FULL"]

#: The longest transition, in frames (2**31 - 1: frame arithmetic stays in int64).
MAX_DURATION = 2 ** 31 - 1

@dataclass(frozen=True)
class TransitionResult:
    """What happened to each agent of a request (agent id arrays).

    ``started``: got a slot now (``slots`` holds their slot indices); ``queued``:
    wait for a free slot; ``cut``: switched immediately, no blend.
    """

    started: np.ndarray
    slots: np.ndarray
    queued: np.ndarray
    cut: np.ndarray


class TransitionSlots:
    """Slot arrays (all ``(NT, ...)``), the request queue and the request policy.

    Attributes
    ----------
    active : (NT,) bool.
    agent : (NT,) int64 agent per slot.
    target_kind, target_ref, target_offset : (NT,) the animation blended to.
    t0, length : (NT,) start frame and length L in frames.
    start_pose : (NT, B, 10) float32 StartP.
    pose : (NT, B, 10) float32 the slot's pose P as last blended on the CPU (every active
        slot's with CPU skinning; with GPU skinning only those a CPU read evaluated).
    queue : the :class:`~.request_queue.RequestQueue` of waiting requests.
    when_full : the default policy, ``"queue"`` or ``"cut"``.

    ``begin(slots, agents, kind, ref, offsets, length)`` is the crowd's: it takes the
    agents' current poses as StartP and calls :meth:`start`.
    """

    def __init__(self, count, bones, agents, when_full="queue", begin=None):
        self.count = int(count)
        n = self.count
        self.agents = agents
        self.when_full = when_full
        self._begin = begin
        self.active = np.zeros(n, bool)
        self.agent = np.full(n, -1, np.int64)
        self.target_kind = np.zeros(n, np.int8)
        self.target_ref = np.zeros(n, np.int64)
        self.target_offset = np.zeros(n, np.int64)
        self.t0 = np.zeros(n, np.int64)
        self.length = np.ones(n, np.int64)
        self.start_pose = sqt.identity_pose((n, bones))
        self.pose = sqt.identity_pose((n, bones))
        self.queue = RequestQueue(agents.count)
        self.served = 0
        self.cuts = 0

    #: the slot arrays a snapshot keeps (see :mod:`.snapshot`)
    STATE = ("active", "agent", "target_kind", "target_ref", "target_offset", "t0", "length",
             "start_pose")

    def state(self) -> dict:
        """What a :mod:`.snapshot` keeps: the slot arrays (StartP included), the counts
        and the queue. ``pose`` is not kept: the skinning mode rebuilds it."""
        return {**{k: getattr(self, k) for k in self.STATE}, "served": self.served,
                "cuts": self.cuts, "queue": self.queue.state()}

    def set_state(self, state: dict):
        for k in self.STATE:
            getattr(self, k)[...] = state[k]
        self.served, self.cuts = int(state["served"]), int(state["cuts"])
        self.queue.set_state(state["queue"])

    def check_refs(self, refs_ok) -> None:
        """Raise ValueError unless the agents in transition hold their own active
        slots, and every active slot (and queued request) targets what exists
        (``refs_ok(kind, ref, offset)``): restored values the shape checks cannot see."""
        a = self.agents
        tr = a.kind == TRANSITION
        slot = np.where(tr, a.ref, 0)
        if not ((slot >= 0) & (slot < max(self.count, 1))).all():
            raise ValueError("an agent plays a slot that does not exist")
        if tr.any() and not (self.active[slot[tr]].all()
                             and (self.agent[slot[tr]] == np.flatnonzero(tr)).all()):
            raise ValueError("an agent's transition slot is not its own")
        act = self.active_slots()
        if not (((self.agent[act] >= 0) & (self.agent[act] < a.count)).all()
                and refs_ok(self.target_kind[act], self.target_ref[act],
                            self.target_offset[act])
                and (self.length[act] >= 1).all()):
            raise ValueError("a transition slot targets what does not exist")
        self.queue.check_refs(refs_ok, a.count)

    def free_slots(self) -> np.ndarray:
        return np.flatnonzero(~self.active)

    def active_slots(self) -> np.ndarray:
        return np.flatnonzero(self.active)

    def queued_agents(self) -> np.ndarray:
        return self.queue.agents()

    # ------------------------------------------------------------------ policy
    def check_request(self, duration, when_full) -> tuple:
        """(length in whole frames, policy) of a request, validated."""
        policy = self.when_full if when_full is None else when_full
        if policy not in WHEN_FULL:
            raise CrowdError(f"transition: when_full must be one of {WHEN_FULL}, got "
                             f"{policy!r}")
        try:
            d = float(duration)
        except (TypeError, ValueError):
            raise CrowdError(f"transition: duration must be a number of frames, got "
                             f"{duration!r}") from None
        if not (np.isfinite(d) and 0 <= d <= MAX_DURATION):
            raise CrowdError(f"transition: duration must be 0..{MAX_DURATION} frames, got "
                             f"{duration!r}")
        return int(round(d)), policy

    def request(self, agents, kind, ref, offsets, length, policy) -> TransitionResult:
        """Blend ``agents`` (k,) to ``(kind, ref)`` (``ref`` one index or (k,) indices)
        at ``offsets`` (k,) over ``length`` frames: agents already blending reuse their
        slot; free slots go first to the requests already waiting (FIFO), then to these
        agents; the rest wait (``"queue"``) or switch at once (``"cut"``). ``length`` 0
        cuts; with no slots at all (``NT = 0``) every request cuts, since nothing could
        serve a queue."""
        ref = np.broadcast_to(np.asarray(ref, np.int64), np.shape(agents))
        agents, first = np.unique(agents, return_index=True)
        offsets, ref = offsets[first], ref[first]
        self.queue.withdraw(agents)
        if self.count == 0:          # nothing could ever serve a queue: switch at once
            policy = "cut"
        if length == 0:
            self.serve_queue()       # first in, first out: the waiting go first
            self.cut(agents, kind, ref, offsets)
            empty = np.zeros(0, np.int64)
            return TransitionResult(empty, empty, empty, agents)
        # the waiting go first (FIFO), then these agents: agents already blending keep
        # their slot, the others take what is left; all start in one batch
        free = self.free_slots()
        waiting = self.queue.pop(min(free.size, len(self.queue)))
        w_slots, free = free[:waiting[0].size], free[waiting[0].size:]
        in_slot = self.agents.kind[agents] == TRANSITION
        reuse_agents = agents[in_slot]
        reuse_slots = self.agents.ref[reuse_agents]
        rest = agents[~in_slot]
        take = min(free.size, rest.size)
        all_agents = np.concatenate([reuse_agents, rest[:take]])
        all_slots = np.concatenate([reuse_slots, free[:take]]).astype(np.int64)
        overflow = rest[take:]
        if w_slots.size or all_slots.size:
            at = np.searchsorted(agents, all_agents)
            mine = (all_agents, kind, ref[at], offsets[at], length)
            self._begin(np.concatenate([w_slots, all_slots]),
                        *(np.concatenate([w, np.broadcast_to(m, all_agents.shape)])
                          for w, m in zip(waiting, mine)))
        queued = cut = np.zeros(0, np.int64)
        if overflow.size:
            at = np.searchsorted(agents, overflow)
            ov_off, ov_ref = offsets[at], ref[at]
            if policy == "queue":
                self.queue.push(overflow, kind, ov_ref, ov_off, length)
                queued = overflow
            else:
                self.cut(overflow, kind, ov_ref, ov_off)
                cut = overflow
        return TransitionResult(all_agents, all_slots, queued, cut)

    def cut(self, agents, kind, ref, offsets):
        """Switch ``agents`` to ``(kind, ref)`` now, without a blend."""
        in_slot = self.agents.kind[agents] == TRANSITION
        if in_slot.any():
            self.release(self.agents.ref[agents[in_slot]])
        self.agents.set_animation(agents, kind, ref, offsets if kind == STREAM else None)
        self.cuts += int(agents.size)

    def serve_queue(self) -> int:
        """Give free slots to queued requests (FIFO); their blend starts at the pose
        shown now, before the frame advances."""
        if not self.queue:
            return 0
        free = self.free_slots()
        n = min(free.size, len(self.queue))
        if n == 0:
            return 0
        agents, kind, ref, off, length = self.queue.pop(n)
        self._begin(free[:n], agents, kind, ref, off, length)    # all at once, in order
        return n

    def start(self, slots, agents, kind, ref, offset, length, start_pose, frame):
        """Fill ``slots`` (arrays of equal length) starting at ``frame``; the agents now
        play their slot."""
        self.active[slots] = True
        self.agent[slots] = agents
        self.target_kind[slots] = kind
        self.target_ref[slots] = ref
        self.target_offset[slots] = offset
        self.t0[slots] = frame
        self.length[slots] = length
        self.start_pose[slots] = start_pose
        self.served += len(slots)
        self.agents.set_animation(agents, TRANSITION, slots)

    def finish(self, slots, s) -> int:
        """Agents of ``slots`` whose ``S`` reached 1 become their target; slots freed.
        Returns how many finished."""
        done = slots[s >= 1.0]
        if done.size:
            agents = self.agent[done]
            st = self.target_kind[done] == STREAM
            self.agents.set_animation(agents[st], STREAM, self.target_ref[done[st]],
                                      self.target_offset[done[st]])
            self.agents.set_animation(agents[~st], UNIQUE, self.target_ref[done[~st]])
            self.release(done)
        return int(done.size)

    # -------------------------------------------------------------------- blend
    def partition(self) -> dict:
        """Active slots by when they can blend (paper s.4.4): ``"ready"`` ones read a
        target already in history (a stream at offset > 0); ``"waiting"`` ones need
        this frame's evaluation (offset 0 or a unique)."""
        act = self.active_slots()
        later = (self.target_kind[act] != STREAM) | (self.target_offset[act] == 0)
        return {"ready": act[~later], "waiting": act[later]}

    def evaluate(self, slots, frame, streams, uniques):
        """Blend ``slots`` for ``frame`` into :attr:`pose` (see :meth:`blended`); returns
        their ``S`` values."""
        if slots.size == 0:
            return np.zeros(0)
        self.pose[slots], s = self.blended(slots, frame, streams, uniques)
        return s

    def blended(self, slots, frame, streams, uniques) -> tuple:
        """``(poses (k, B, 10), S (k,))`` of ``slots`` blended for ``frame`` (targets from
        the :class:`~.pools.StreamPool` history and the :class:`~.pools.UniquePool`),
        stored nowhere."""
        kind = self.target_kind[slots]
        ref = self.target_ref[slots]
        target = np.empty((slots.size,) + self.pose.shape[1:], np.float32)
        st = kind == STREAM
        if st.any():
            target[st] = streams.poses(frame, ref[st], self.target_offset[slots[st]])
        un = kind == UNIQUE
        if un.any():
            target[un] = uniques.poses[ref[un]]
        s = self.weights(slots, frame)
        return sqt.blend2(self.start_pose[slots], target, s.astype(np.float32)), s

    def weights(self, slots, frame) -> np.ndarray:
        """``S = clip((frame - T0) / L, 0, 1)`` of ``slots`` (float64)."""
        return np.clip((frame - self.t0[slots]) / self.length[slots], 0.0, 1.0)

    def target_rows(self, slots, frame, streams, unique_base) -> np.ndarray:
        """Logical pose-texture row of each slot's target at ``frame``."""
        ref = self.target_ref[slots]
        return np.where(self.target_kind[slots] == STREAM,
                        streams.row(frame, ref, self.target_offset[slots]), unique_base + ref)

    def target_skeleton(self, slots, streams, uniques) -> np.ndarray:
        """(k,) int64 skeleton index of each slot's target."""
        ref = self.target_ref[slots]
        kind = self.target_kind[slots]
        out = np.zeros(slots.size, np.int64)
        out[kind == STREAM] = streams.skeleton[ref[kind == STREAM]]
        out[kind == UNIQUE] = uniques.skeleton[ref[kind == UNIQUE]]
        return out

    def describe(self, slots) -> dict:
        """Copies of the state of ``slots`` (k,): ``start_pose`` (k, B, 10), ``t0``,
        ``length``, ``target_kind``, ``target_ref``, ``target_offset`` (k,)."""
        return {"start_pose": self.start_pose[slots].copy(), "t0": self.t0[slots].copy(),
                "length": self.length[slots].copy(),
                "target_kind": self.target_kind[slots].copy(),
                "target_ref": self.target_ref[slots].copy(),
                "target_offset": self.target_offset[slots].copy()}

    def release(self, slots):
        self.active[slots] = False
        self.agent[slots] = -1
