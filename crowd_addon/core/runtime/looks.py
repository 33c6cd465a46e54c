"""Who looks at what, and the look stage a crowd runs (the turn itself is
:mod:`.look_at`'s).

:class:`AgentLooks` keeps four numbers per agent (target, start, blend, stop), so a
look costs nothing per frame on the CPU. :class:`LookStage` is a crowd's look-at: its
chains (one per skeleton with a look rig), targets and lags, the requests that start
and stop looks (checked before anything changes), and the targets in each agent's
model space. :func:`turn_rows` applies the looks to skinning rows: the CPU reference
the crowd (``Crowd.agent_rows``) and a recording (``Recording.pair_rows``) share.
"""

from __future__ import annotations

import math

import numpy as np

from ..base.errors import CrowdError
from .look_at import LookChain, agent_lags, apply_look, look_turns

__all__ = ["AgentLooks", "LookStage", "model_space", "seen_targets", "turn_rows"]

_NEVER = np.iinfo(np.int64).max // 4


class AgentLooks:
    """Who looks at what: per agent the look target (an index into the crowd's look
    targets, -1 none), the frame the look starts, its blend length (frames) and the
    frame it starts to end (:data:`_NEVER`: it stays). The weight at frame ``F`` ramps
    up over ``blend`` frames from ``start`` and down over ``blend`` frames from
    ``stop`` (:meth:`weights`), so a look costs nothing per frame on the CPU: only
    these four numbers change, when a look is started or stopped. ``version`` counts
    those changes (:meth:`look`, :meth:`look_away`, :meth:`reset`, :meth:`set_state`),
    so a reader (the recorder) compares the arrays only after one."""

    STATE = ("target", "start", "blend", "stop")

    def __init__(self, agents: int):
        self.target = np.full(agents, -1, np.int64)
        self.start = np.zeros(agents, np.int64)
        self.blend = np.zeros(agents, np.float64)
        self.stop = np.full(agents, _NEVER, np.int64)
        self.version = 0

    def reset(self):
        self.version += 1
        self.target[:] = -1
        self.start[:] = 0
        self.blend[:] = 0.0
        self.stop[:] = _NEVER

    def look(self, ids, target: int, frame: int, blend: float, hold: int = 0):
        """``ids`` look at target ``target`` from ``frame``, blending in over ``blend``
        frames; with ``hold > 0`` they start to look away ``hold`` frames later."""
        self.version += 1
        self.target[ids] = int(target)
        self.start[ids] = int(frame)
        self.blend[ids] = float(blend)
        self.stop[ids] = int(frame) + int(hold) if hold else _NEVER

    def look_away(self, ids, frame: int, blend: float):
        """``ids`` stop looking, blending out over ``blend`` frames from ``frame``
        (from the weight they have then)."""
        self.version += 1
        ids = np.asarray(ids, np.int64)
        ids = ids[self.target[ids] >= 0]
        w = self.weights(frame, ids)
        # a ramp down over ``blend`` frames that passes ``w`` at ``frame`` (the ramp up
        # moved back so it is over)
        blend = float(blend)
        self.blend[ids] = blend
        self.start[ids] = np.minimum(self.start[ids], frame - int(math.ceil(blend)))
        self.stop[ids] = frame - np.round((1.0 - w) * blend).astype(np.int64)

    def weights(self, frame: int, ids) -> np.ndarray:
        """(n,) 0..1: how far ``ids`` look at their target at ``frame`` (0 without
        one)."""
        ids = np.asarray(ids, np.int64)
        b = self.blend[ids]
        up = np.where(b > 0, (frame - self.start[ids]) / np.maximum(b, 1e-12),
                      (frame >= self.start[ids]).astype(np.float64))
        down = np.where(b > 0, (frame - self.stop[ids]) / np.maximum(b, 1e-12),
                        (frame >= self.stop[ids]).astype(np.float64))
        w = np.clip(up, 0.0, 1.0) * (1.0 - np.clip(down, 0.0, 1.0))
        return np.where(self.target[ids] >= 0, w, 0.0)

    def state(self) -> dict:
        return {k: getattr(self, k) for k in self.STATE}

    def set_state(self, state: dict, targets: int):
        self.version += 1
        for k in self.STATE:
            getattr(self, k)[...] = state[k]
        if not (((self.target >= -1) & (self.target < targets)).all()
                and (self.blend >= 0).all() and np.isfinite(self.blend).all()):
            raise ValueError("the agents' looks name a look target that does not exist")


def seen_targets(targets, target, frames) -> np.ndarray:
    """(n, 3) world points: where each agent saw its look target ``targets[target[i]]``
    at ``frames[i]`` (its frame less its lag; zero where ``target[i]`` is -1)."""
    out = np.zeros((len(target), 3))
    for t, tgt in enumerate(targets):
        m = target == t
        if m.any():
            out[m] = tgt.at(frames[m])
    return out


def model_space(points, position, heading, scale) -> np.ndarray:
    """(n, 3) world ``points`` in each agent's model space: its position, heading (about
    +Z) and scale undone."""
    d = points - position
    h = -np.asarray(heading, np.float64)
    c, s = np.cos(h), np.sin(h)
    local = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], 1)
    return local / np.asarray(scale)[:, None]


def turn_rows(rows, skeleton, weights, chains, targets_of) -> np.ndarray:
    """Skinning rows ``(n, B, 3, 4)`` with the looks applied (in place, and returned):
    rows ``i`` of weight above 0 whose skeleton ``skeleton[i]`` has a chain turn toward
    ``targets_of(pick)``, the (k, 3) model-space targets of rows ``pick``."""
    if not (weights > 0).any():
        return rows
    for sk, chain in enumerate(chains):
        pick = np.flatnonzero((weights > 0) & (skeleton == sk))
        if chain is None or not pick.size:
            continue
        turns = look_turns(rows[pick], chain, targets_of(pick), weights[pick])
        rows[pick] = apply_look(rows[pick], chain, turns).astype(rows.dtype)
    return rows


class LookStage:
    """A crowd's look-at: ``chains`` per skeleton (None: no look rig), the look
    ``targets`` by name, each agent's ``lags`` and ``looks`` (:class:`AgentLooks`)."""

    def __init__(self, config, skeleton_names, skeletons):
        rigs = config.look_rigs
        self.chains = tuple(LookChain(rigs[name], sk) if name in rigs else None
                            for name, sk in zip(skeleton_names, skeletons))
        self.target_names = tuple(config.look_targets)
        self.targets = tuple(config.look_targets.values())
        self.lags = agent_lags(config.agent_offset, config.look_lag, config.look_max_lag,
                               config.seed)
        self.looks = AgentLooks(self.lags.size)

    def rigged(self, ids, agent_skeleton) -> np.ndarray:
        """The ``ids`` whose character has a look rig."""
        has = np.array([c is not None for c in self.chains], bool)
        return ids[has[agent_skeleton[ids]]]

    def check_look(self, target, blend, hold) -> tuple:
        """``(target index, blend, hold)`` of a look request; CrowdError names a bad
        target (a name of the crowd's look targets), blend or hold."""
        if target not in self.target_names:
            raise CrowdError(f"look_at: unknown look target {target!r} (targets: "
                             f"{list(self.target_names)})")
        blend, hold = self.check_blend(blend), int(hold)
        if hold < 0:
            raise CrowdError(f"look_at: hold must be >= 0 frames, got {hold}")
        return self.target_names.index(target), blend, hold

    @staticmethod
    def check_blend(blend) -> float:
        try:
            b = float(blend)
        except (TypeError, ValueError):
            raise CrowdError(f"look: blend must be a number of frames, got {blend!r}") \
                from None
        if not (np.isfinite(b) and 0 <= b <= 2 ** 31 - 1):
            raise CrowdError(f"look: blend must be 0 .. 2**31 - 1 frames, got {blend!r}")
        return b

    def targets_model(self, ids, frame: int, agents) -> np.ndarray:
        """(n, 3) where ``ids`` see their targets at ``frame`` in their model space (the
        smoothed path read ``lag`` frames late; ``agents``: the AgentState)."""
        seen = seen_targets(self.targets, self.looks.target[ids], frame - self.lags[ids])
        return model_space(seen, agents.position[ids], agents.heading[ids],
                           agents.scale[ids])
