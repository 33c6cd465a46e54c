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

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from . import pose as sqt
from .agents import STREAM, UNIQUE

__all__ = ["TransitionSlots", "TransitionResult", "POLICIES"]

POLICIES = ("queue", "cut")


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
    """Slot arrays (all ``(NT, ...)``) and the request queue.

    Attributes
    ----------
    active : (NT,) bool.
    agent : (NT,) int64 agent per slot.
    target_kind, target_ref, target_offset : (NT,) the animation blended to.
    t0, length : (NT,) start frame and length L in frames.
    start_pose : (NT, B, 10) float32 StartP.
    pose : (NT, B, 10) float32 the slot's current pose P.
    """

    def __init__(self, count, bones):
        self.count = int(count)
        n = self.count
        self.active = np.zeros(n, bool)
        self.agent = np.full(n, -1, np.int64)
        self.target_kind = np.zeros(n, np.int8)
        self.target_ref = np.zeros(n, np.int64)
        self.target_offset = np.zeros(n, np.int64)
        self.t0 = np.zeros(n, np.int64)
        self.length = np.ones(n, np.int64)
        self.start_pose = sqt.identity_pose((n, bones))
        self.pose = sqt.identity_pose((n, bones))
        # agent id -> (kind, ref, offset, length); FIFO order
        self.queue = OrderedDict()
        self.served = 0
        self.cuts = 0

    def free_slots(self) -> np.ndarray:
        return np.flatnonzero(~self.active)

    def active_slots(self) -> np.ndarray:
        return np.flatnonzero(self.active)

    def queued_agents(self) -> np.ndarray:
        return np.fromiter(self.queue.keys(), np.int64, len(self.queue))

    def start(self, slots, agents, kind, ref, offset, length, start_pose, frame):
        """Fill ``slots`` (arrays of equal length) starting at ``frame``."""
        self.active[slots] = True
        self.agent[slots] = agents
        self.target_kind[slots] = kind
        self.target_ref[slots] = ref
        self.target_offset[slots] = offset
        self.t0[slots] = frame
        self.length[slots] = length
        self.start_pose[slots] = start_pose
        self.pose[slots] = start_pose
        self.served += len(slots)

    def evaluate(self, slots, frame, stream_history, max_offset, unique_poses):
        """Blend ``slots`` for ``frame``; returns their ``S`` values.

        ``stream_history`` is the (M, S, B, 10) local-pose ring; the target of a
        streamed slot is ``history[(frame - O_B) mod M, B]``.
        """
        if slots.size == 0:
            return np.zeros(0)
        kind = self.target_kind[slots]
        ref = self.target_ref[slots]
        target = np.empty((slots.size,) + self.pose.shape[1:], np.float32)
        st = kind == STREAM
        if st.any():
            sl = (frame - self.target_offset[slots[st]]) % max_offset
            target[st] = stream_history[sl, ref[st]]
        un = kind == UNIQUE
        if un.any():
            target[un] = unique_poses[ref[un]]
        s = self.weights(slots, frame)
        self.pose[slots] = sqt.blend2(self.start_pose[slots], target, s.astype(np.float32))
        return s

    def weights(self, slots, frame) -> np.ndarray:
        """``S = clip((frame - T0) / L, 0, 1)`` of ``slots`` (float64)."""
        return np.clip((frame - self.t0[slots]) / self.length[slots], 0.0, 1.0)

    def target_rows(self, slots, frame, streams, max_offset, unique_base) -> np.ndarray:
        """Logical pose-texture row of each slot's target at ``frame``."""
        ref = self.target_ref[slots]
        stream_row = ((frame - self.target_offset[slots]) % max_offset) * streams + ref
        return np.where(self.target_kind[slots] == STREAM, stream_row, unique_base + ref)

    def release(self, slots):
        self.active[slots] = False
        self.agent[slots] = -1
