"""Look-at: an agent's head (and neck, optionally chest) turned toward a point, per
agent, on top of the pose it plays, so the streams stay shared and the aim is each
agent's own.

The stage works on the pose texture rows an agent is drawn with (the skinning
matrices ``S_j = model_j @ inverse_bind_j``, the GPU's data), so the CPU reference here
and the shader compute the same thing from the same inputs:

1. The target in the agent's model space (its world transform undone) and the look
   chain's last bone (the head): its pivot, the bind position of the bone's head
   carried by ``S_head``, and its forward, ``S_head``'s rotation applied to the
   character's forward axis (the head faces the character's forward at rest).
2. Yaw about model +Z and pitch out of the horizontal plane of the direction from the
   head's pivot to the target, each clamped to the rig's limits **relative to the
   body** (a target behind the agent turns the head as far as the limit, no further),
   then the turn from the head's current yaw and pitch, scaled by the agent's look
   weight (0: the animation as it is).
3. That turn ``Q`` (pitch about the head's horizontal right axis, then yaw about +Z,
   so ``Q`` takes the head's forward to the clamped direction exactly) is shared along
   the chain: bone ``k`` turns by ``Q ** share_k`` (the same axis, that fraction of the
   angle) about its pivot, as moved by the bones before it. The shares sum to 1, so the
   head ends exactly at ``Q``'s direction; the head's pivot moves a little with the
   neck, so a target closer than about 2 m may be missed by over a degree.
4. Every bone below a chain bone (the head's children too) moves with it:
   ``S'_j = A_j @ S_j``, ``A_j`` the product of the chain's turns down to the deepest
   chain bone above ``j``.

Each agent sees the target late and smoothed, so a stand does not snap as one: the
target's path is smoothed once (:meth:`LookTarget.smoothed`, an exponential moving
average with time constant ``smoothing`` frames) and agent ``i`` reads it at
``F - lag_i`` (:func:`agent_lags`: by default its animation offset, which already
spreads a stand's timing over M frames, or a seeded delay). Who looks at what, and
the stage a crowd runs, are in :mod:`.looks`.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from ..base.bounds import finite
from ..base.errors import CrowdError
from ..base.skeleton import Skeleton

__all__ = ["LookRig", "LookTarget", "LookChain", "agent_lags", "look_turns", "look_angles",
           "turns_of", "apply_look", "head_direction"]

_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class LookRig:
    """How a character looks at things.

    bones : the look chain, parent first (e.g. ``("neck", "head")``; a chest first
        adds the upper body); the last bone is the one aimed.
    shares : each bone's share of the turn (summing to 1; default: equal).
    yaw_limit, pitch_limit : the most the head turns from the body's forward, in
        radians (sideways about +Z, up and down).
    forward : the character's forward axis in its model space at rest (Blender's
        front view: -Y).
    """

    bones: tuple
    shares: tuple = ()
    yaw_limit: float = math.radians(75.0)
    pitch_limit: float = math.radians(40.0)
    forward: tuple = (0.0, -1.0, 0.0)

    def __post_init__(self):
        bones = tuple(str(b) for b in self.bones)
        if not bones or any(not b.strip() for b in bones) or len(set(bones)) != len(bones):
            raise CrowdError(f"look rig: bones must be distinct bone names, got {self.bones!r}")
        object.__setattr__(self, "bones", bones)
        shares = tuple(self.shares) or tuple(1.0 / len(bones) for _ in bones)
        shares = tuple(finite(s, "look rig: share") for s in shares)
        if len(shares) != len(bones) or min(shares) < 0 or abs(sum(shares) - 1.0) > 1e-6:
            raise CrowdError(f"look rig: shares must be one per bone, >= 0, summing to 1, "
                             f"got {self.shares!r} for bones {bones}")
        object.__setattr__(self, "shares", shares)
        for key, top in (("yaw_limit", math.pi), ("pitch_limit", math.pi / 2)):
            v = finite(getattr(self, key), f"look rig: {key}")
            if not 0 <= v <= top:
                raise CrowdError(f"look rig: {key} must be in 0..{top:.4f} radians, got {v:g}")
            object.__setattr__(self, key, v)
        f = np.asarray([finite(v, "look rig: forward") for v in
                        np.asarray(self.forward, dtype=object).reshape(-1)], np.float64)
        if f.shape != (3,) or abs(f[2]) > 1e-6 or np.hypot(f[0], f[1]) < 1e-6:
            raise CrowdError(f"look rig: forward must be a horizontal 3-vector, got "
                             f"{self.forward!r}")
        object.__setattr__(self, "forward", tuple(float(x) for x in f / np.linalg.norm(f)))


@dataclass(frozen=True, eq=False)
class LookTarget:
    """A point to look at: its world positions at frames ``first, first + 1, ...``
    (held before and after), smoothed with time constant ``smoothing`` frames (0: not
    smoothed) before the agents read it."""

    name: str
    first: int
    positions: np.ndarray
    smoothing: float = 4.0

    def __post_init__(self):
        what = f"look target {self.name!r}"
        if not str(self.name).strip():
            raise CrowdError("look target: the name must not be empty")
        first = finite(self.first, f"{what}: first")
        if first != int(first):
            raise CrowdError(f"{what}: first must be a whole frame, got {self.first!r}")
        object.__setattr__(self, "first", int(first))
        p = np.asarray(self.positions, np.float64)
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] == 0:
            raise CrowdError(f"{what}: positions must be (frames, 3), got {p.shape}")
        if not np.isfinite(p).all():
            raise CrowdError(f"{what}: a position is not finite (frame "
                             f"{self.first + int(np.argmax(~np.isfinite(p).all(1)))})")
        p = p.copy()
        p.flags.writeable = False
        object.__setattr__(self, "positions", p)
        s = finite(self.smoothing, f"{what}: smoothing")
        if s < 0:
            raise CrowdError(f"{what}: smoothing must be >= 0 frames, got {s:g}")
        object.__setattr__(self, "smoothing", s)
        object.__setattr__(self, "_smoothed", None)

    def smoothed(self) -> np.ndarray:
        """(T, 3) the path the agents read: ``s[0] = p[0]``, ``s[t] = s[t-1] + a (p[t] -
        s[t-1])`` with ``a = 1 - exp(-1 / smoothing)`` (a first-order lag: a step
        is 63 % followed after ``smoothing`` frames)."""
        if self._smoothed is None:
            p = self.positions
            if self.smoothing <= 0 or p.shape[0] == 1:
                s = p.copy()
            else:
                a = 1.0 - math.exp(-1.0 / self.smoothing)
                s = np.empty_like(p)
                s[0] = p[0]
                for t in range(1, p.shape[0]):          # once per target, not per frame
                    s[t] = s[t - 1] + a * (p[t] - s[t - 1])
            s.flags.writeable = False
            object.__setattr__(self, "_smoothed", s)
        return self._smoothed

    def at(self, frames) -> np.ndarray:
        """(n, 3) the smoothed path at ``frames`` (held beyond both ends)."""
        s = self.smoothed()
        i = np.clip(np.asarray(frames, np.int64) - self.first, 0, s.shape[0] - 1)
        return s[i]


def agent_lags(offsets, mode="offset", max_lag: int = 12, seed: int = 0) -> np.ndarray:
    """(n,) frames each agent sees the target late: ``"offset"``, its animation offset
    (a stand's offsets already spread its timing over M frames), or ``"seeded"``, a
    delay in ``0 .. max_lag`` from a hash of the seed and the agent's id."""
    offsets = np.asarray(offsets, np.int64)
    if mode == "offset":
        return offsets.copy()
    if mode != "seeded":
        raise CrowdError(f"look lag: mode must be 'offset' or 'seeded', got {mode!r}")
    if int(max_lag) < 0:
        raise CrowdError(f"look lag: max_lag must be >= 0, got {max_lag!r}")
    ids = np.arange(offsets.size, dtype=np.uint64)
    x = ids * np.uint64(0x9E3779B97F4A7C15) + np.uint64(zlib.crc32(f"look{seed}".encode()))
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(31))) * np.uint64(0xBF58476D1CE4E5B9)
    return ((x >> np.uint64(33)) % np.uint64(int(max_lag) + 1)).astype(np.int64)


class LookChain:
    """A :class:`LookRig` bound to a skeleton: the chain's bone indices, the bind
    positions of their heads (the pivots at rest) and, per bone of the skeleton, how
    many chain bones lie at or above it (``depth``: 0 for bones the look leaves
    alone)."""

    def __init__(self, rig: LookRig, skeleton: Skeleton):
        missing = [b for b in rig.bones if b not in skeleton.bone_names]
        if missing:
            raise CrowdError(f"look rig of skeleton {skeleton.name!r}: no bone named "
                             f"{', '.join(map(repr, missing))}")
        self.rig, self.skeleton = rig, skeleton
        self.index = np.array([skeleton.bone_index(b) for b in rig.bones], np.int64)
        parents = skeleton.parents
        for a, b in zip(self.index[:-1], self.index[1:]):
            p = int(b)
            while p >= 0 and p != a:
                p = int(parents[p])
            if p != a:
                raise CrowdError(f"look rig of skeleton {skeleton.name!r}: "
                                 f"{skeleton.bone_names[a]!r} is not above "
                                 f"{skeleton.bone_names[b]!r} (the chain goes parent first)")
        bind = np.linalg.inv(skeleton.inverse_bind)
        self.pivots = bind[self.index, :3, 3].copy()           # (K, 3) bind positions
        depth = np.zeros(skeleton.bone_count, np.int64)
        for j in range(skeleton.bone_count):                   # parents precede children
            p = int(parents[j])
            inherited = depth[p] if p >= 0 else 0
            own = np.flatnonzero(self.index == j)
            depth[j] = own[0] + 1 if own.size else inherited
        self.depth = depth
        self.shares = np.asarray(rig.shares, np.float64)
        self.forward = np.asarray(rig.forward, np.float64)
        self.left = np.cross(_Z, self.forward)


def _yaw_pitch(v, forward, left):
    yaw = np.arctan2(v @ left, v @ forward)
    pitch = np.arctan2(v[..., 2], np.hypot(v @ left, v @ forward))
    return yaw, pitch


def _axis_angle(axis, angle) -> np.ndarray:
    """(n, 3, 3) rotations about unit ``axis`` (n, 3) by ``angle`` (n,)."""
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    return np.stack([np.stack([t * x * x + c, t * x * y - s * z, t * x * z + s * y], -1),
                     np.stack([t * x * y + s * z, t * y * y + c, t * y * z - s * x], -1),
                     np.stack([t * x * z - s * y, t * y * z + s * x, t * z * z + c], -1)], -2)


def head_direction(rows, chain: LookChain) -> tuple:
    """``(pivot, forward)`` (n, 3) each: where the chain's last bone is and where it
    faces, in model space, for skinning rows ``rows`` (n, B, 3, 4)."""
    s = np.asarray(rows, np.float64)[:, chain.index[-1]]
    pivot = s[:, :, :3] @ chain.pivots[-1] + s[:, :, 3]
    f = s[:, :, :3] @ chain.forward
    return pivot, f / np.linalg.norm(f, axis=-1, keepdims=True)


def look_turns(rows, chain: LookChain, targets, weights) -> np.ndarray:
    """(n, K, 3, 4) each chain bone's turn about its (moved) pivot, in model space, for
    agents drawn with skinning rows ``rows`` (n, B, 3, 4) looking at ``targets`` (n, 3,
    in their model space) with ``weights`` (n,) 0..1 (module doc, steps 1-3)."""
    dyaw, dpitch = look_angles(rows, chain, targets, weights)
    return turns_of(rows, chain, dyaw, dpitch)


def look_angles(rows, chain: LookChain, targets, weights) -> tuple:
    """``(dyaw, dpitch)`` (n,) each: the head's turn (module doc, step 2), weighted."""
    rows = np.asarray(rows, np.float64)
    pivot, f = head_direction(rows, chain)
    d = np.asarray(targets, np.float64) - pivot
    d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)
    fwd, left = chain.forward, chain.left
    yaw_f, pitch_f = _yaw_pitch(f, fwd, left)
    yaw_d, pitch_d = _yaw_pitch(d, fwd, left)
    rig = chain.rig
    yaw_d = np.clip(yaw_d, -rig.yaw_limit, rig.yaw_limit)
    pitch_d = np.clip(pitch_d, -rig.pitch_limit, rig.pitch_limit)
    w = np.clip(np.asarray(weights, np.float64), 0.0, 1.0)
    dyaw = w * (np.mod(yaw_d - yaw_f + np.pi, 2 * np.pi) - np.pi)
    dpitch = w * (pitch_d - pitch_f)
    return dyaw, dpitch


def turns_of(rows, chain: LookChain, dyaw, dpitch) -> np.ndarray:
    """:func:`look_turns` of the head's turn ``(dyaw, dpitch)`` (:func:`look_angles`;
    Render Crowd passes them quantised: docs/gpu.md)."""
    rows = np.asarray(rows, np.float64)
    n, k = rows.shape[0], chain.index.size
    f = head_direction(rows, chain)[1]
    left = chain.left
    dyaw, dpitch = np.asarray(dyaw, np.float64), np.asarray(dpitch, np.float64)
    # Q = yaw about +Z after pitch about the head's horizontal right axis
    right = np.cross(f, _Z)
    norm = np.linalg.norm(right, axis=-1, keepdims=True)
    right = np.where(norm > 1e-9, right / np.maximum(norm, 1e-12), left)
    q = _axis_angle(np.broadcast_to(_Z, (n, 3)), dyaw) @ _axis_angle(right, dpitch)
    # Q as axis and angle, shared along the chain
    angle = np.arccos(np.clip((np.trace(q, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    axis = np.stack([q[:, 2, 1] - q[:, 1, 2], q[:, 0, 2] - q[:, 2, 0],
                     q[:, 1, 0] - q[:, 0, 1]], -1)
    anorm = np.linalg.norm(axis, axis=-1, keepdims=True)
    axis = np.where(anorm > 1e-12, axis / np.maximum(anorm, 1e-12), _Z)
    turns = np.zeros((n, k, 3, 4))
    moved = np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3))   # chain so far
    for i in range(k):
        s = rows[:, chain.index[i]]
        p = s[:, :, :3] @ chain.pivots[i] + s[:, :, 3]             # this bone's pivot
        p = np.einsum("nij,nj->ni", moved[0], p) + moved[1]         # as moved above it
        r = _axis_angle(axis, angle * chain.shares[i])
        turns[:, i, :, :3] = r
        turns[:, i, :, 3] = p - np.einsum("nij,nj->ni", r, p)
        moved = (np.einsum("nij,njk->nik", r, moved[0]),
                 np.einsum("nij,nj->ni", r, moved[1]) + turns[:, i, :, 3])
    return turns


def apply_look(rows, chain: LookChain, turns, only=None) -> np.ndarray:
    """``rows`` (n, B, 3, 4) with the chain's ``turns`` (:func:`look_turns`) applied:
    each bone at or below chain bone ``k`` is moved by the turns of chain bones
    ``0 .. k`` (float64 copy). ``only``: bone indices to move (the rest are copied as
    they are), for a reader that needs a few bones' looked rows."""
    out = np.array(rows, np.float64)
    n, k = out.shape[0], chain.index.size
    acc = np.zeros((n, k, 3, 4))                    # A after chain bone i
    r, t = np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3))
    for i in range(k):
        tr, tt = turns[:, i, :, :3], turns[:, i, :, 3]
        r, t = np.einsum("nij,njk->nik", tr, r), np.einsum("nij,nj->ni", tr, t) + tt
        acc[:, i, :, :3], acc[:, i, :, 3] = r, t
    bones = np.flatnonzero(chain.depth > 0)
    if only is not None:
        bones = np.intersect1d(bones, np.asarray(only, np.int64))
    if bones.size:
        a = acc[:, chain.depth[bones] - 1]          # (n, J, 3, 4)
        s = out[:, bones]                               # (n, J, 3, 4)
        new = np.empty_like(s)
        new[..., :3] = a[..., :3] @ s[..., :3]
        new[..., 3] = np.einsum("njab,njb->nja", a[..., :3], s[..., 3]) + a[..., 3]
        out[:, bones] = new
    return out
