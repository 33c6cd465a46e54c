"""Local poses as packed SQT arrays and the blend kernels every controller uses.

A local pose of ``B`` bones is a float32 array ``(B, 10)``: scale ``[0:3]``,
rotation quaternion ``(w, x, y, z)`` ``[3:7]``, translation ``[7:10]``, each
relative to the parent bone (Blender's ``pose_bone`` matrix_basis composed with
the rest pose, see ``skeleton``). Batches are ``(n, B, 10)``.

Blending is done on local SQT (docs/architecture.md, Conventions): scale and translation lerp,
rotation nlerp on the shortest arc.
"""

from __future__ import annotations

import numpy as np

from . import quaternion as quat

__all__ = [
    "WIDTH", "SCALE", "ROT", "TRANS", "identity_pose", "make_pose", "blend2",
    "blend_weighted", "additive_delta", "apply_additive", "pose_to_matrices", "records",
    "from_records", "next_key_deltas",
]

WIDTH = 10
SCALE = slice(0, 3)
ROT = slice(3, 7)
TRANS = slice(7, 10)

_IDENTITY = np.array([1, 1, 1, 1, 0, 0, 0, 0, 0, 0], np.float32)


_RECORD = np.dtype((np.void, WIDTH * 4))


def records(poses: np.ndarray) -> np.ndarray:
    """A ``(..., B)`` view of float32 SQT poses ``(..., B, 10)`` as one 40-byte record
    per bone. The poses' last axis must be contiguous, the bones need not be (a pose
    texture's bones are 12 floats apart): gathers and scatters through it copy whole
    bones at a time, several times faster than float by float on a padded layout."""
    return poses.view(np.uint8).view(_RECORD)[..., 0]


def from_records(rec: np.ndarray) -> np.ndarray:
    """The float32 poses ``(..., B, 10)`` of contiguous records (e.g. a gather from
    :func:`records`), a view."""
    return rec.view(np.float32).reshape(rec.shape + (WIDTH,))


def identity_pose(shape) -> np.ndarray:
    """Identity SQT poses shaped ``shape + (10,)`` (float32)."""
    shape = (shape,) if np.isscalar(shape) else tuple(shape)
    return np.broadcast_to(_IDENTITY, shape + (WIDTH,)).copy()


def make_pose(scale=None, rotation=None, translation=None, bones=None) -> np.ndarray:
    """Pack separate ``(..., 3)``, ``(..., 4)``, ``(..., 3)`` arrays into SQT float32."""
    parts = [p for p in (scale, rotation, translation) if p is not None]
    lead = np.asarray(parts[0]).shape[:-1] if parts else (bones,)
    out = identity_pose(lead)
    if scale is not None:
        out[..., SCALE] = scale
    if rotation is not None:
        out[..., ROT] = rotation
    if translation is not None:
        out[..., TRANS] = translation
    return out


def blend2(a: np.ndarray, b: np.ndarray, w, out: np.ndarray | None = None) -> np.ndarray:
    """Two-way blend (paper Eq. 2): ``a + (b - a) * w`` on SQT, nlerp rotations.

    Parameters
    ----------
    a, b : (..., B, 10) float32
    w : scalar, (...,) or (..., B) weights of ``b`` (0 gives ``a``, 1 gives ``b``).

    Quaternion components are processed one at a time (``(..., B)`` strided views):
    numpy's inner loop then runs over bones instead of over 4 components, which is
    several times faster on the packed layout.
    """
    w = np.asarray(w, dtype=a.dtype)
    if w.ndim < a.ndim - 1:
        w = w.reshape(w.shape + (1,) * (a.ndim - 1 - w.ndim))
    if out is None:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape), a.dtype)
    np.subtract(b, a, out=out)
    neg = dot_rotations(a, b) < 0
    if neg.any():
        # shortest arc: blend toward -q_b where the quaternions point apart
        for c in (3, 4, 5, 6):
            np.subtract(np.negative(b[..., c]), a[..., c], out=out[..., c], where=neg)
    out *= w[..., None]
    out += a
    normalize_rotations(out)
    return out


def dot_rotations(a, b):
    """(...,) dot products of the rotation quaternions of SQT poses ``a`` and ``b``."""
    d = a[..., 3] * b[..., 3]
    for c in (4, 5, 6):
        d += a[..., c] * b[..., c]
    return d


def normalize_rotations(p: np.ndarray) -> np.ndarray:
    """Normalise the rotation quaternions of SQT poses ``p`` in place."""
    inv = dot_rotations(p, p)
    np.sqrt(inv, out=inv)
    np.divide(1.0, inv, out=inv)
    for c in (3, 4, 5, 6):
        p[..., c] *= inv
    return p


def blend_weighted(poses: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """N-way blend: weighted sum of ``k`` poses, rotations sign-aligned per bone to the
    heaviest child's (never to a child that does not contribute).

    Parameters
    ----------
    poses : (n, k, B, 10) float32
    weights : (n, k) or (n, k, B); per pose (and bone) weights, which must sum to
        a positive value for every bone (normalised here).

    Returns
    -------
    (n, B, 10) float32
    """
    w = np.asarray(weights, dtype=poses.dtype)
    if w.ndim == 2:
        return _blend_per_node(poses, w)
    total = w.sum(axis=1, keepdims=True)
    w = w / np.where(total > 0, total, 1)
    heaviest = np.argmax(np.broadcast_to(w, poses.shape[:3]), axis=1)    # (n, B)
    ref = np.take_along_axis(poses, heaviest[:, None, :, None], axis=1)  # (n, 1, B, 10)
    wq = np.where(dot_rotations(poses, ref) < 0, -w, w)                             # (n, k, B)
    out = np.einsum("nkbc,nkb->nbc", poses, np.broadcast_to(w, poses.shape[:3]))
    for c in (3, 4, 5, 6):
        out[..., c] = np.einsum("nkb,nkb->nb", poses[..., c], wq)
    return normalize_rotations(out)


def _blend_per_node(poses, w):
    """:func:`blend_weighted` with one weight per child (``w`` (n, k)): a weighted sum
    of each node's children as one small matrix product per node, the children's
    rotations first flipped (in a copy, only when some point away) onto the heaviest
    child's hemisphere."""
    n, k = w.shape
    total = w.sum(axis=1, keepdims=True)
    w = w / np.where(total > 0, total, 1)
    ref = poses[np.arange(n), np.argmax(w, axis=1)][:, None]                 # (n, 1, B, 10)
    away = dot_rotations(poses, ref) < 0                                             # (n, k, B)
    if away.any():
        poses = poses.copy()
        rot = poses[..., ROT]
        np.negative(rot, out=rot, where=away[..., None])
    out = np.matmul(w[:, None, :], poses.reshape(n, k, -1)).reshape(poses.shape[:1] +
                                                                     poses.shape[2:])
    return normalize_rotations(out)


def _qmul(a, b, out, conj_a=False):
    """Hamilton product of the rotations of SQT poses into ``out[..., ROT]`` (of ``a``'s
    conjugate with ``conj_a``), component by component."""
    aw, ax, ay, az = (a[..., c] for c in (3, 4, 5, 6))
    if conj_a:
        ax, ay, az = -ax, -ay, -az
    quat.multiply_parts((aw, ax, ay, az), [b[..., c] for c in (3, 4, 5, 6)],
                        out=[out[..., c] for c in (3, 4, 5, 6)])
    return out


def additive_delta(pose: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Additive delta of ``pose`` against ``reference`` (both ``(..., B, 10)``).

    ``scale = s / s_ref``, ``rotation = q_ref^-1 * q``, ``translation = t - t_ref``,
    so that ``apply_additive(reference, delta, 1) == pose``.
    """
    out = np.empty(np.broadcast_shapes(pose.shape, reference.shape), pose.dtype)
    np.subtract(pose, reference, out=out)                  # translation (scale redone)
    out[..., SCALE] = pose[..., SCALE] / reference[..., SCALE]
    return _qmul(reference, pose, out, conj_a=True)


def apply_additive(base: np.ndarray, delta: np.ndarray, w) -> np.ndarray:
    """Layer an additive ``delta`` on ``base`` with weight ``w`` (scalar or ``(..., B)``).

    ``rotation = q_base * nlerp(identity, q_delta, w)``, ``translation = t + w * dt``,
    ``scale = s * lerp(1, ds, w)``.
    """
    w = np.asarray(w, dtype=base.dtype)
    shape = np.broadcast_shapes(base.shape, delta.shape)
    wb = np.broadcast_to(w, shape[:-1])                    # (..., B)
    # weighted delta: scale and translation lerp from identity, rotation nlerp from
    # identity on the shortest arc
    scaled = delta * wb[..., None]
    scaled[..., SCALE] += 1 - wb[..., None]
    sign = np.where(delta[..., 3] < 0, -1, 1).astype(base.dtype)
    for c in (4, 5, 6):
        scaled[..., c] *= sign
    scaled[..., 3] = (1 - wb) + wb * delta[..., 3] * sign
    normalize_rotations(scaled)
    out = np.empty(shape, base.dtype)
    np.add(base, scaled, out=out)                          # translation (rest redone)
    out[..., SCALE] = base[..., SCALE] * scaled[..., SCALE]
    _qmul(base, scaled, out)
    return normalize_rotations(out)


def pose_to_matrices(pose: np.ndarray) -> np.ndarray:
    """4x4 affine matrices ``(..., 4, 4)`` (T @ R @ S) of SQT poses, in float64."""
    p = np.asarray(pose, dtype=np.float64)
    m = np.zeros(p.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat.to_matrix(p[..., ROT]) * p[..., None, SCALE]
    m[..., :3, 3] = p[..., TRANS]
    m[..., 3, 3] = 1
    return m


def next_key_deltas(keys, start, frames) -> np.ndarray:
    """Per key of packed clip ``keys`` (clips of ``frames`` keys from rows ``start``,
    the clip bank's layout), the key after it in its clip (the last key: itself),
    its rotation negated where it points away from this key's, minus this key: the
    shortest-arc nlerp of :func:`blend2` toward the next key is ``key + f *
    delta`` (normalised), without the sign test and the subtraction (the same float32
    operations, done once)."""
    nxt = np.empty_like(keys)
    nxt[:-1] = keys[1:]
    nxt[-1] = keys[-1]
    last = start + frames - 1
    nxt[last] = keys[last]
    rot = slice(3, 7)
    away = dot_rotations(keys, nxt) < 0            # the test blend2 makes
    nxt[..., rot] = np.where(away[..., None], -nxt[..., rot], nxt[..., rot])
    return np.subtract(nxt, keys, out=nxt)
