"""A crowd shot simulated once and kept, for writers (USD) and anything else that
needs every agent at every frame of a shot without running the crowd again.

:func:`~.recorder.record`, or a :class:`~.recorder.Recorder` stepped one frame at a
time (a modal timer), runs a :class:`~.crowd.Crowd` over ``first .. last`` reading
only ``crowd.view`` and keeps: the stream heads' local poses at frames ``first - (M - 1) .. last`` (the pose
history unrolled: offset ``O`` shows the head of ``F - O``), the uniques' poses at
each frame, per agent *segments* of what it plays from a frame on (a stream at an
offset, a unique, or a transition with its StartP, ``t0``, ``L`` and target; only
agents ``view.agent_changes`` reports are looked at, and only a different animation
makes a segment), agent transforms and their changes, the events fired and the tags
the stream heads crossed. :meth:`Recording.agent_poses` rebuilds any pose at any shot
frame from these alone, as the crowd computes it (a transition shows
``blend2(StartP, target, clip((F - t0) / L, 0, 1))``). Nothing costs per agent per
frame beyond vectorised work on changed agents. Record a crowd built with
``skinning="gpu"``: only local poses are needed, so no CPU skinning runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..base import pose as sqt
from ..runtime.agents import STREAM, TRANSITION, UNIQUE
from ..base.errors import CrowdError

__all__ = ["Recording"]

#: A transition's fields kept besides StartP (``FrameView.transitions`` keys).
TARGET_FIELDS = ("t0", "length", "target_kind", "target_ref", "target_offset")


@dataclass(frozen=True)
class Recording:
    """A recorded shot ``first .. last`` (inclusive, ``T`` frames) of ``N`` agents,
    ``S`` streams, ``U`` uniques, poses of ``B`` bones. Read-only.

    config : the crowd's CrowdConfig. max_offset : M. stream_skeleton (S,),
    agent_skeleton (N,) : int64 indices into ``list(config.skeletons)``.
    stream_poses : (T + M - 1, S, B, 10) float32 heads at :attr:`stream_frames`;
    unique_poses : (T, U, B, 10) float32 uniques at :attr:`frames`.
    segment_* (K,) : what agents play from ``segment_frame`` on, sorted by (agent,
    frame), every agent from ``first``: kind STREAM (``ref`` stream at ``offset``),
    UNIQUE (``ref`` unique) or TRANSITION (``ref`` a row of: ``start_pose`` (K2, B, 10)
    float32 StartP, ``t0``, ``length``, ``target_kind``/``_ref``/``_offset`` (K2,)).
    position (N, 3), heading (N,) float32 and color (N, 3) float32 RGB at ``first``;
    scale (N,) float32 body scales and palette (N, 4, 3) float32 palette colours
    (constant);
    move_* (K3,): a new position
    and heading from ``move_frame`` on, sorted by (agent, frame).
    events : ``(name, frame, agent ids)`` per event fired while recording, in order.
    stream_events : ``(stream, name, frame)`` (k,) arrays of the tags the heads
    crossed at :attr:`stream_frames`, in frame order.
    seconds : wall-clock seconds spent in the recorder.
    substeps : samples per frame ``N`` (the crowd's); with ``N > 1``
    ``stream_subposes`` (T + M - 1, N - 1, S, B, 10) and ``unique_subposes`` (T, N - 1,
    U, B, 10) hold the heads and uniques at ``F + k / N``, ``k = 1 .. N - 1``, so every
    time of :attr:`times` (from ``first`` to ``last + (N - 1) / N``) has its poses.
    look_* (K4,) : each agent's look (:class:`~.look_at.AgentLooks`: ``target``
    (-1: none), ``start``, ``blend``, ``stop``) from ``look_frame`` on, sorted by
    (agent, frame): a row at ``first`` for every agent with a target, then one per
    agent whose look changed (a look started or stopped); no row: no look.
    look_lags (N,) : frames each agent reads its target late; look_targets : the
    :class:`~.look_at.LookTarget` s ``look_target`` indexes; look_chains : per
    skeleton its :class:`~.look_at.LookChain` or None. :meth:`agent_rows` rebuilds
    ``Crowd.agent_rows`` (looks applied), :meth:`looked_pair_poses` the same turn as
    local poses (the chain joints' rotations).
    """

    config: object
    first: int
    last: int
    fps: float
    max_offset: int
    stream_names: tuple
    unique_names: tuple
    stream_skeleton: np.ndarray
    agent_skeleton: np.ndarray
    stream_poses: np.ndarray
    unique_poses: np.ndarray
    segment_agent: np.ndarray
    segment_frame: np.ndarray
    segment_kind: np.ndarray
    segment_ref: np.ndarray
    segment_offset: np.ndarray
    start_pose: np.ndarray
    t0: np.ndarray
    length: np.ndarray
    target_kind: np.ndarray
    target_ref: np.ndarray
    target_offset: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    color: np.ndarray
    move_agent: np.ndarray
    move_frame: np.ndarray
    move_position: np.ndarray
    move_heading: np.ndarray
    events: tuple
    stream_events: tuple
    seconds: float
    substeps: int = 1
    stream_subposes: np.ndarray | None = None
    unique_subposes: np.ndarray | None = None
    scale: np.ndarray | None = None
    palette: np.ndarray | None = None
    look_agent: np.ndarray | None = None
    look_frame: np.ndarray | None = None
    look_target: np.ndarray | None = None
    look_start: np.ndarray | None = None
    look_blend: np.ndarray | None = None
    look_stop: np.ndarray | None = None
    look_lags: np.ndarray | None = None
    look_targets: tuple = ()
    look_chains: tuple = ()

    @property
    def palettes(self) -> np.ndarray:
        """(N, 4, 3) float32 each agent's palette colours (-1: none; constant)."""
        return np.full((self.agent_count, 4, 3), -1.0, np.float32) if self.palette is None \
            else self.palette

    @property
    def scales(self) -> np.ndarray:
        """(N,) float32 each agent's body scale (set once; ones when not recorded)."""
        return np.ones(self.agent_count, np.float32) if self.scale is None else self.scale

    @property
    def agent_count(self) -> int:
        return int(self.agent_skeleton.size)

    @property
    def frames(self) -> np.ndarray:
        """(T,) int64 shot frames ``first .. last``."""
        return np.arange(self.first, self.last + 1)

    @property
    def times(self) -> np.ndarray:
        """(T * N,) float64 sample times: each shot frame, then its ``N - 1`` sub-frame
        samples ``F + k / N`` (just the frames when ``substeps`` is 1)."""
        n = self.substeps
        return (self.frames[:, None] + np.arange(n) / n).reshape(-1)

    @property
    def stream_frames(self) -> np.ndarray:
        """(T + M - 1,) int64 frames of the :attr:`stream_poses` rows."""
        return np.arange(self.first - self.max_offset + 1, self.last + 1)

    @cached_property
    def static(self) -> np.ndarray:
        """(N,) bool: plays one (stream, offset) at every frame of the shot."""
        count = np.bincount(self.segment_agent, minlength=self.agent_count)
        return (count == 1) & (self.segment_kind[np.cumsum(count) - 1] == STREAM)

    @cached_property
    def unique_skeleton(self) -> np.ndarray:
        """(U,) int64 skeleton index of each unique."""
        names = list(self.config.skeletons)
        return np.array([names.index(d.skeleton) for d in self.config.uniques], np.int64)

    @cached_property
    def moving(self) -> np.ndarray:
        """(N,) bool: position or heading changed during the shot."""
        return np.bincount(self.move_agent, minlength=self.agent_count) > 0

    def playing(self, frames, agents=None) -> tuple:
        """``(kind, ref, offset)`` of the segments ``agents`` (default all) play at
        ``frames``: (k,) arrays for one frame, (T, k) for a (T,) array of frames."""
        frame, agents, shape = self._pairs(frames, agents)
        seg = self._find(0, frame, agents)
        return tuple(a[seg].reshape(shape) for a in (self.segment_kind, self.segment_ref,
                                                     self.segment_offset))

    def agent_poses(self, frames, agents=None) -> np.ndarray:
        """Local poses ``agents`` (default all) showed at ``frames``, as the crowd
        computed them: ``(k, B, 10)`` float32 for one frame, ``(T, k, B, 10)`` for a
        (T,) array of frames. Frames may be any of :attr:`times` (sub-frame samples)."""
        times = np.asarray(frames, np.float64)
        whole = np.floor(times)
        sub = np.rint((times - whole) * self.substeps)
        if not np.allclose(whole + sub / self.substeps, times, rtol=0, atol=1e-9):
            raise CrowdError(f"recording: {frames} is not a sample time (whole frames and "
                             f"{self.substeps} samples a frame)")
        frame, pairs, shape = self._pairs(whole.astype(np.int64), agents)
        per_frame = pairs.size // whole.size if whole.size else 0
        out = self.pair_poses(frame, pairs, np.repeat(sub.astype(np.int64).reshape(-1),
                                                      per_frame))
        return out.reshape(shape + out.shape[1:])

    def pair_poses(self, frame, agent, sub=None) -> np.ndarray:
        """``(n, B, 10)`` float32 pose of each ``(frame[i], agent[i])`` pair ((n,) int64
        arrays, frames inside the shot), at ``frame[i] + sub[i] / N`` when ``sub`` ((n,)
        int64 in 0..N-1) is given."""
        sub = np.zeros(frame.shape, np.int64) if sub is None else np.asarray(sub, np.int64)
        seg = self._find(0, frame, agent)
        kind, ref = self.segment_kind[seg], self.segment_ref[seg]
        out = self._poses(frame, sub, kind, ref, self.segment_offset[seg])
        m = np.flatnonzero(kind == TRANSITION)
        if m.size:
            t, f = ref[m], frame[m]
            target = self._poses(f, sub[m], self.target_kind[t], self.target_ref[t],
                                 self.target_offset[t])
            s = np.clip((f + sub[m] / self.substeps - self.t0[t]) / self.length[t], 0.0, 1.0)
            out[m] = sqt.blend2(self.start_pose[t], target, s.astype(np.float32))
        return out

    def agent_transforms(self, frames, agents=None) -> tuple:
        """``(position (..., k, 3) float32, heading (..., k) float32)`` of ``agents`` at
        ``frames`` (one frame, or a (T,) array of frames)."""
        frame, agents, shape = self._pairs(frames, agents)
        pos, head = self.pair_transforms(frame, agents)
        return pos.reshape(shape + (3,)), head.reshape(shape)

    def pair_transforms(self, frame, agent) -> tuple:
        """``(position (n, 3), heading (n,))`` float32 of each ``(frame[i], agent[i])``."""
        pos, head = self.position[agent], self.heading[agent]
        if self.move_agent.size:
            i = self._find(1, frame, agent)
            hit = (i >= 0) & (self.move_agent[np.maximum(i, 0)] == agent)
            pos[hit], head[hit] = self.move_position[i[hit]], self.move_heading[i[hit]]
        return pos, head

    # -------------------------------------------------------------------- looks
    @property
    def has_looks(self) -> bool:
        """Some agent had a look target during the shot."""
        return self.look_agent is not None and bool((self.look_target >= 0).any())

    def look_state(self, frame, agent) -> tuple:
        """``(target, start, blend, stop)`` (n,) of each ``(frame[i], agent[i])`` pair:
        the agent's look then (:class:`~.looks.AgentLooks`; target -1: none)."""
        from ..runtime.looks import AgentLooks
        frame, agent = np.asarray(frame, np.int64), np.asarray(agent, np.int64)
        looks = AgentLooks(frame.size)
        if self.has_looks:
            i = self._find(2, frame, agent)
            hit = np.flatnonzero((i >= 0) & (self.look_agent[np.maximum(i, 0)] == agent))
            for k in looks.STATE:
                getattr(looks, k)[hit] = getattr(self, f"look_{k}")[i[hit]]
        return looks

    def look_weights(self, frame, agent) -> np.ndarray:
        """(n,) float64 0..1: how far each ``(frame[i], agent[i])`` looked at its
        target (core's :meth:`~.looks.AgentLooks.weights`)."""
        frame = np.asarray(frame, np.int64)
        return self.look_state(frame, agent).weights(frame, np.arange(frame.size))

    @cached_property
    def looking(self) -> np.ndarray:
        """(N,) bool: the agent's look weight is above 0 at some shot frame."""
        out = np.zeros(self.agent_count, bool)
        if self.has_looks:
            ids = np.unique(self.look_agent[self.look_target >= 0])
            frame, agent, _ = self._pairs(self.frames, ids)
            w = self.look_weights(frame, agent).reshape(self.frames.size, ids.size)
            out[ids] = (w > 0).any(0)
        return out

    def look_targets_model(self, frame, agent, looks=None) -> np.ndarray:
        """(n, 3) where each ``(frame[i], agent[i])`` saw its look target, in the
        agent's model space (core's ``Crowd.look_targets_model``)."""
        from ..runtime.looks import model_space, seen_targets
        looks = self.look_state(frame, agent) if looks is None else looks
        seen = seen_targets(self.look_targets, looks.target, frame - self.look_lags[agent])
        pos, head = self.pair_transforms(frame, agent)
        return model_space(seen, pos, head, self.scales[agent])

    def agent_rows(self, frames, agents=None) -> np.ndarray:
        """Skinning rows ``agents`` were drawn with at ``frames`` (whole frames), looks
        applied: ``(k, B, 3, 4)`` float32 for one frame, ``(T, k, B, 3, 4)`` for a
        (T,) array (core's ``Crowd.agent_rows``; bones past an agent's skeleton are
        zero)."""
        frame, pairs, shape = self._pairs(frames, agents)
        out = self.pair_rows(frame, pairs)
        return out.reshape(shape + out.shape[1:])

    def pair_rows(self, frame, agent) -> np.ndarray:
        """``(n, B, 3, 4)`` float32 skinning rows of ``(frame[i], agent[i])`` pairs,
        looks applied."""
        from ..base.skinning import skinning_matrices
        from ..runtime.looks import turn_rows
        poses = self.pair_poses(frame, agent)
        rows = np.zeros(poses.shape[:2] + (3, 4), np.float32)
        skeletons = list(self.config.skeletons.values())
        skel = self.agent_skeleton[agent]
        for k in np.unique(skel).tolist():
            m, sk = skel == k, skeletons[k]
            rows[m, :sk.bone_count] = skinning_matrices(poses[m], sk)[:, :, :3, :]
        w = self.look_weights(frame, agent)
        return turn_rows(rows, skel, w, self.look_chains,
                         lambda pick: self.look_targets_model(frame[pick], agent[pick]))

    def looked_pair_poses(self, frame, agent, sub=None) -> np.ndarray:
        """:meth:`pair_poses` with each pair's look turned into its local pose: the
        chain joints' rotations become ``parent_model'^-1 @ model'`` of the looked
        model matrices (their translations and scales, and every other joint, are left
        as they are: the turn is about each chain joint's own pivot, and the bones below
        move with it). At ``frame[i] + sub[i] / N`` the look is that of ``frame[i]``."""
        from ..base import quaternion as quat
        from ..runtime.look_at import apply_look, look_turns
        from ..base.skinning import model_matrices, with_ancestors
        poses = self.pair_poses(frame, agent, sub)
        if not self.has_looks:
            return poses
        frame = np.asarray(frame, np.int64)
        w = self.look_weights(frame, agent)
        skeletons = list(self.config.skeletons.values())
        skel = self.agent_skeleton[agent]
        for k, chain in enumerate(self.look_chains):
            pick = np.flatnonzero((w > 0) & (skel == k))
            if chain is None or not pick.size:
                continue
            sk = skeletons[k]
            local = poses[pick, :sk.bone_count]
            # only the chain's bones and those above them: the turns read the chain,
            # the local rotations below read the chain and its parents (a third of the
            # fan's 23 bones; all of them cost the 65k demo's export 10 s)
            need = with_ancestors(chain.index, sk)
            rows = np.zeros((pick.size, sk.bone_count, 3, 4))
            rows[:, need] = (model_matrices(local, sk, need)
                             @ sk.inverse_bind[need])[:, :, :3, :]
            turns = look_turns(rows, chain, self.look_targets_model(frame[pick],
                                                                    agent[pick]), w[pick])
            looked = apply_look(rows, chain, turns, only=need)
            bind = np.linalg.inv(sk.inverse_bind)
            for j in chain.index.tolist():
                m = np.tile(np.eye(4), (pick.size, 1, 1))
                m[:, :3, :] = looked[:, j]
                m = m @ bind[j]
                p = int(sk.parents[j])
                if p >= 0:
                    mp = np.tile(np.eye(4), (pick.size, 1, 1))
                    mp[:, :3, :] = looked[:, p]
                    m = np.linalg.inv(mp @ bind[p]) @ m
                r = m[:, :3, :3] / local[:, j, None, sqt.SCALE].astype(np.float64)
                q = quat.from_matrix(r)
                old = local[:, j, sqt.ROT].astype(np.float64)
                q = np.where(((q * old).sum(-1) < 0)[:, None], -q, q)     # nearer sign
                poses[pick, j, sqt.ROT] = q.astype(np.float32)
        return poses

    # ------------------------------------------------------------------ lookups
    def _pairs(self, frames, agents) -> tuple:
        """Flat (frame, agent) pairs of ``frames`` x ``agents`` and their shape."""
        agents = np.arange(self.agent_count) if agents is None else \
            np.asarray(agents, np.int64).reshape(-1)
        f = np.asarray(frames, np.int64)
        if f.size and (f.min() < self.first or f.max() > self.last):
            raise CrowdError(f"recording: frame {frames} is outside the shot "
                             f"{self.first}-{self.last}")
        shape = f.shape + agents.shape
        return np.repeat(f.reshape(-1), agents.size), np.tile(agents, f.size), shape

    @cached_property
    def _keys(self) -> tuple:
        """Ascending search keys of the segments and of the moves."""
        span = self.last - self.first + 1
        looks = self.look_agent * span + self.look_frame - self.first \
            if self.look_agent is not None else np.zeros(0, np.int64)
        return (self.segment_agent * span + self.segment_frame - self.first,
                self.move_agent * span + self.move_frame - self.first, looks)

    def _find(self, table, frame, agents) -> np.ndarray:
        """Per (frame, agent) pair, the index of the agent's last segment (``table`` 0),
        move (1) or look (2) at or before ``frame``; one of an earlier agent, or -1, if
        none."""
        key = agents * (self.last - self.first + 1) + frame - self.first
        return np.searchsorted(self._keys[table], key, "right") - 1

    def _poses(self, frame, sub, kind, ref, offset) -> np.ndarray:
        """(n, B, 10) poses of streams ``ref`` at ``offset`` (kind STREAM) and uniques
        ``ref`` (UNIQUE) at ``frame + sub / N`` ((n,) arrays); rows of other kinds are
        unset."""
        out = np.empty((kind.size,) + self.stream_poses.shape[2:], np.float32)
        row = frame - self.first
        for k in np.unique(sub).tolist():
            at = sub == k
            st, un = at & (kind == STREAM), at & (kind == UNIQUE)
            srow = row[st] - offset[st] + self.max_offset - 1
            if k == 0:
                out[st] = self.stream_poses[srow, ref[st]]
                out[un] = self.unique_poses[row[un], ref[un]]
            else:
                out[st] = self.stream_subposes[srow, k - 1, ref[st]]
                out[un] = self.unique_subposes[row[un], k - 1, ref[un]]
        return out
