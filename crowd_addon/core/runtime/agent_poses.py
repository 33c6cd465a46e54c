"""The poses agents show: now (a stream's history at the agent's offset, a unique's
pose, a slot's blend) and at the sub-frame samples a crowd keeps for writers
(``Crowd(..., substeps=N)``: every stream and unique evaluated at ``F + k / N`` too,
the streams' kept for the last M frames like the history).
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from ..base.errors import CrowdError
from .agents import STREAM, TRANSITION, UNIQUE

__all__ = ["SubSamples", "current_poses"]


def current_poses(agents, frame, state, streams, uniques, skinning) -> np.ndarray:
    """Local poses ``(n, B, 10)`` ``agents`` show at ``frame`` (``state``: the
    AgentState; ``skinning``: the mode, which holds the slots' blended poses)."""
    out = np.empty((agents.size,) + uniques.poses.shape[1:], np.float32)
    kind, ref, off = state.kind[agents], state.ref[agents], state.offset[agents]
    m = kind == STREAM
    out[m] = streams.poses(frame, ref[m], off[m])
    m = kind == UNIQUE
    out[m] = uniques.poses[ref[m]]
    m = kind == TRANSITION
    if m.any():
        out[m] = skinning.slot_poses(ref[m])
    return out


class SubSamples:
    """The sub-frame samples: ``streams`` ``(M, N-1, S, B, 10)`` (the last M frames,
    by history slice) and ``uniques`` ``(N-1, U, B, 10)`` (this frame's)."""

    def __init__(self, substeps: int, max_offset: int, streams: int, uniques: int,
                 bones: int):
        self.count = int(substeps)
        n = self.count - 1
        self.streams = np.zeros((max_offset, n, streams, bones, sqt.WIDTH), np.float32)
        self.uniques = np.zeros((n, uniques, bones, sqt.WIDTH), np.float32)

    def store(self, slice_, poses_at) -> None:
        """Keep the samples of the frame at history slice ``slice_``;
        ``poses_at(k / N)`` gives the ``(S + U, B, 10)`` roots at ``F + k / N``."""
        s = self.streams.shape[2]
        for k in range(1, self.count):
            poses = poses_at(k / self.count)
            self.streams[slice_, k - 1] = poses[:s]
            self.uniques[k - 1] = poses[s:]

    def check(self, sub) -> int:
        """``sub`` as an int in 0..N-1 (CrowdError otherwise)."""
        if isinstance(sub, bool) or not isinstance(sub, (int, np.integer)) \
                or not 0 <= sub < self.count:
            raise CrowdError(f"sub-frame sample must be 0..{self.count - 1} (the crowd "
                             f"keeps {self.count} per frame), got {sub!r}")
        return int(sub)

    def agent_poses(self, agents, k: int, frame: int, state, slots, streams) -> np.ndarray:
        """Local poses ``(n, B, 10)`` ``agents`` show at ``frame + k / N`` (``k`` in
        1..N-1): what they play now, at that time (a transition's weight too)."""
        out = np.empty((agents.size,) + self.uniques.shape[2:], np.float32)
        kind, ref, off = state.kind[agents], state.ref[agents], state.offset[agents]
        slot = np.where(kind == TRANSITION, ref, 0)
        tr = kind == TRANSITION
        kind = np.where(tr, slots.target_kind[slot], kind)
        ref = np.where(tr, slots.target_ref[slot], ref)
        off = np.where(tr, slots.target_offset[slot], off)
        m = kind == STREAM
        out[m] = self.streams[streams.slice(frame, off[m]), k - 1, ref[m]]
        m = kind == UNIQUE
        out[m] = self.uniques[k - 1, ref[m]]
        if tr.any():
            s = slot[tr]
            w = np.clip((frame + k / self.count - slots.t0[s]) / slots.length[s], 0.0, 1.0)
            out[tr] = sqt.blend2(slots.start_pose[s], out[tr], w.astype(np.float32))
        return out
