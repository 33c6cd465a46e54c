"""Skeletons: bone names, parent indices, bind (rest) pose, inverse bind matrices."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import pose as sqt
from .errors import CrowdError
from .quaternion import normalize_if_needed

__all__ = ["Skeleton", "local_to_model", "affine_inverse"]


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A bone hierarchy with its bind pose.

    Parameters
    ----------
    name : str
    bone_names : sequence of str, unique.
    parents : (B,) int; ``-1`` for roots. Parents precede children (``parents[i] < i``);
        use :meth:`from_parent_names` for bones in any order.
    bind_pose : (B, 10) local SQT of the rest pose (relative to the parent bone).
        Rotations are normalised; zero or non-finite values are rejected.
    inverse_bind : optional (B, 4, 4) inverse bind matrices; by default the inverse
        of the bind pose's model matrices.
    """

    name: str
    bone_names: tuple
    parents: np.ndarray
    bind_pose: np.ndarray
    inverse_bind: np.ndarray = None
    bind_model: np.ndarray = field(init=False)
    levels: tuple = field(init=False, repr=False)

    def __post_init__(self):
        if not str(self.name).strip():
            raise CrowdError(f"skeleton: the name must not be empty, got {self.name!r}")
        names = tuple(str(n) for n in self.bone_names)
        if not names:
            raise CrowdError(f"skeleton {self.name!r}: it has no bones")
        seen = {}
        for i, n in enumerate(names):
            if not n:
                raise CrowdError(f"skeleton {self.name!r}: bone {i} has an empty name")
            if n in seen:
                raise CrowdError(f"skeleton {self.name!r}: duplicate bone name {n!r} "
                                 f"(bones {seen[n]} and {i})")
            seen[n] = i
        parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        if parents.shape[0] != len(names):
            raise CrowdError(f"skeleton {self.name!r}: {parents.shape[0]} parents for "
                             f"{len(names)} bones")
        for i, p in enumerate(parents):
            if p < -1 or p >= len(names):
                raise CrowdError(f"skeleton {self.name!r}: bone {names[i]!r} has parent "
                                 f"index {p}, outside -1..{len(names) - 1}")
            if p >= i:
                cycle = _find_cycle(parents, i)
                if cycle:
                    raise CrowdError(f"skeleton {self.name!r}: cycle in parents: "
                                     + " -> ".join(names[c] for c in cycle))
                raise CrowdError(f"skeleton {self.name!r}: bone {names[i]!r} comes before "
                                 f"its parent {names[p]!r}; parents must precede children "
                                 "(Skeleton.from_parent_names orders them)")
        bind = _validated_pose(self.bind_pose, len(names), f"skeleton {self.name!r} bind pose",
                               names)
        object.__setattr__(self, "bone_names", names)
        object.__setattr__(self, "parents", parents.astype(np.int32))
        object.__setattr__(self, "bind_pose", bind)
        levels = _levels(parents)
        object.__setattr__(self, "levels", levels)
        model = local_to_model(sqt.pose_to_matrices(bind)[None], self)[0]
        object.__setattr__(self, "bind_model", model)
        if self.inverse_bind is None:
            inv = affine_inverse(model)
        else:
            inv = np.asarray(self.inverse_bind, dtype=np.float64)
            if inv.shape != (len(names), 4, 4) or not np.isfinite(inv).all():
                raise CrowdError(f"skeleton {self.name!r}: inverse_bind must be finite "
                                 f"({len(names)}, 4, 4), got {inv.shape}")
            flat = np.abs(np.linalg.det(inv[:, :3, :3])) < 1e-12
            if flat.any():         # nothing could undo it (a USD client inverts it)
                raise CrowdError(f"skeleton {self.name!r}: inverse_bind of bone "
                                 f"{names[int(np.argmax(flat))]!r} is singular (it flattens "
                                 "the bone's space)")
        object.__setattr__(self, "inverse_bind", inv)

    @property
    def bone_count(self) -> int:
        return len(self.bone_names)

    def bone_index(self, name: str) -> int:
        try:
            return self.bone_names.index(name)
        except ValueError:
            raise CrowdError(f"skeleton {self.name!r} has no bone {name!r}") from None

    @classmethod
    def from_parent_names(cls, name, bone_names, parent_names, bind_pose, inverse_bind=None):
        """Build from bones in any order; ``parent_names[i]`` is ``None`` for roots.

        Bones are reordered depth-first (parents before children, siblings in the
        given order); the bind pose rows follow. Cycles and unknown parents raise.
        """
        bone_names = [str(n) for n in bone_names]
        parent_names = list(parent_names)
        if len(parent_names) != len(bone_names):
            raise CrowdError(f"skeleton {name!r}: {len(parent_names)} parent names for "
                             f"{len(bone_names)} bones")
        if np.shape(bind_pose)[:1] != (len(bone_names),):
            raise CrowdError(f"skeleton {name!r} bind pose: expected {len(bone_names)} rows, "
                             f"got shape {np.shape(bind_pose)}")
        index = {n: i for i, n in enumerate(bone_names)}
        if len(index) != len(bone_names):
            dup = next(n for n in bone_names if bone_names.count(n) > 1)
            raise CrowdError(f"skeleton {name!r}: duplicate bone name {dup!r}")
        parents = []
        for n, p in zip(bone_names, parent_names):
            if p is None:
                parents.append(-1)
            elif p not in index:
                raise CrowdError(f"skeleton {name!r}: bone {n!r} has unknown parent {p!r}")
            else:
                parents.append(index[p])
        parents = np.array(parents)
        children = {i: [] for i in range(-1, len(bone_names))}
        for i, p in enumerate(parents):
            children[int(p)].append(i)
        order, stack = [], list(reversed(children[-1]))
        while stack:
            i = stack.pop()
            order.append(i)
            stack.extend(reversed(children[i]))
        if len(order) != len(bone_names):
            missing = sorted(set(range(len(bone_names))) - set(order))
            cycle = _find_cycle(parents, missing[0]) or missing
            raise CrowdError(f"skeleton {name!r}: cycle in parents: "
                             + " -> ".join(bone_names[c] for c in cycle))
        new_index = np.empty(len(order), np.int64)
        new_index[order] = np.arange(len(order))
        new_parents = [-1 if parents[o] < 0 else int(new_index[parents[o]]) for o in order]
        bind = np.asarray(bind_pose)[order]
        inv = None if inverse_bind is None else np.asarray(inverse_bind)[order]
        return cls(name, [bone_names[o] for o in order], new_parents, bind, inv)


def local_to_model(local: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """Model-space matrices from local matrices, one pass per hierarchy depth level.

    Parameters
    ----------
    local : (n, B, 4, 4) local bone matrices (any float dtype).

    Returns
    -------
    (n, B, 4, 4) model matrices, same dtype.
    """
    model = np.array(local, copy=True)
    for bones, parents in skeleton.levels:
        model[:, bones] = model[:, parents] @ local[:, bones]
    return model


def _levels(parents: np.ndarray) -> tuple:
    depth = np.zeros(len(parents), np.int64)
    for i, p in enumerate(parents):
        if p >= 0:
            depth[i] = depth[p] + 1
    out = []
    for d in range(1, int(depth.max()) + 1 if len(depth) else 1):
        bones = np.flatnonzero(depth == d)
        out.append((bones, parents[bones].astype(np.int64)))
    return tuple(out)


def _find_cycle(parents, start):
    seen, path, i = set(), [], start
    while i >= 0 and i not in seen:
        seen.add(i)
        path.append(i)
        i = int(parents[i])
    if i >= 0:
        return path[path.index(i):] + [i]
    return None


def _validated_pose(values, bones, what, names=None) -> np.ndarray:
    """Check a ``(bones, 10)`` SQT array: finite, non-zero rotations (normalised)."""
    p = np.asarray(values, dtype=np.float64)
    if p.shape != (bones, sqt.WIDTH):
        raise CrowdError(f"{what}: expected shape ({bones}, {sqt.WIDTH}), got {p.shape}")
    bad = ~np.isfinite(p).all(axis=-1)
    if bad.any():
        b = int(np.flatnonzero(bad)[0])
        raise CrowdError(f"{what}: non-finite value at bone "
                         f"{names[b] if names else b!r}")
    qn = np.linalg.norm(p[:, sqt.ROT], axis=-1)
    if (qn < 1e-6).any():
        b = int(np.flatnonzero(qn < 1e-6)[0])
        raise CrowdError(f"{what}: zero rotation quaternion at bone "
                         f"{names[b] if names else b!r}")
    out = np.asarray(values).astype(np.float32)
    out[:, sqt.ROT] = normalize_if_needed(p[:, sqt.ROT])
    return out


def affine_inverse(m: np.ndarray) -> np.ndarray:
    """Inverses of affine 4x4 matrices ``(..., 4, 4)`` (last row ``0 0 0 1``): the 3x3
    part by its adjugate (rows ``c1 x c2``, ``c2 x c0``, ``c0 x c1`` of its columns over
    the determinant), the translation undone by it. Whole-array numpy, no LAPACK call
    (``np.linalg.inv`` wakes the BLAS threads: milliseconds for a handful of bones on a
    busy machine)."""
    m = np.asarray(m, np.float64)
    a = m[..., :3, :3]
    c0, c1, c2 = a[..., :, 0], a[..., :, 1], a[..., :, 2]
    rows = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=-2)
    det = np.einsum("...i,...i->...", c0, rows[..., 0, :])
    inv3 = rows / det[..., None, None]
    out = np.zeros(m.shape, np.float64)
    out[..., :3, :3] = inv3
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", inv3, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out
