"""Quaternion math on numpy arrays, ``(w, x, y, z)`` order like Blender's mathutils.

Every function takes arrays shaped ``(..., 4)`` (and ``(..., 3)`` for vectors,
``(..., 3, 3)`` for matrices) and broadcasts over the leading axes. The dtype of
the inputs is kept (float32 in the runtime, float64 in tests and baking).
:func:`multiply_parts` is the one Hamilton product: it works on the four components
as separate arrays (component-major layouts such as ``(4, F, B)`` or strided views
of packed poses), and :func:`multiply` is it on ``(..., 4)`` arrays.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "identity", "normalize", "normalize_if_needed", "multiply", "multiply_parts", "conjugate",
    "rotate", "nlerp", "slerp", "to_matrix", "from_matrix",
]


def identity(shape=(), dtype=np.float32) -> np.ndarray:
    """Identity quaternions shaped ``shape + (4,)``."""
    q = np.zeros(tuple(np.atleast_1d(shape)) + (4,) if shape != () else (4,), dtype)
    q[..., 0] = 1.0
    return q


def normalize_if_needed(q: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """``q`` as float32, normalising only quaternions whose length is off by more
    than ``tol``, so stored unit float32 data round-trips bit for bit."""
    q64 = np.asarray(q, np.float64)
    n = np.sqrt(np.sum(q64 * q64, axis=-1, keepdims=True))
    off = np.abs(n - 1) > tol
    return np.where(off, q64 / np.where(n > 0, n, 1), q64).astype(np.float32)


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions of ``q``; zero quaternions stay zero (callers validate)."""
    n = np.sqrt(np.sum(q * q, axis=-1, keepdims=True))
    return q / np.where(n > 0, n, 1)


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``) of ``(..., 4)``
    arrays: :func:`multiply_parts` on their components."""
    return np.stack(multiply_parts(np.moveaxis(a, -1, 0), np.moveaxis(b, -1, 0)), axis=-1)


def multiply_parts(a, b, out=None) -> tuple:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``) of quaternions given
    as their four components ``(w, x, y, z)``.

    Parameters
    ----------
    a, b : sequences of 4 arrays (or an array whose first axis has length 4, e.g.
        ``(4, F, B)``) that broadcast against each other; any float dtype, kept.
    out : optional sequence of 4 writable arrays (e.g. the strided ``[..., c]`` views
        of packed poses) that receive the components.

    Returns
    -------
    The 4 component arrays of the product (``out``'s when given), as a tuple.
    Component-wise, the inner loops run over the leading axes instead of over 4
    components, which is several times faster than on ``(..., 4)`` arrays.
    """
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    parts = (aw * bw - ax * bx - ay * by - az * bz,
             aw * bx + ax * bw + ay * bz - az * by,
             aw * by - ax * bz + ay * bw + az * bx,
             aw * bz + ax * by - ay * bx + az * bw)
    if out is None:
        return parts
    for dst, part in zip(out, parts):
        dst[...] = part
    return tuple(out)


def conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion)."""
    return q * np.array([1, -1, -1, -1], q.dtype)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)``."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def nlerp(a: np.ndarray, b: np.ndarray, t) -> np.ndarray:
    """Normalised lerp on the shortest arc; ``t`` broadcasts against ``(...)``."""
    t = np.asarray(t, dtype=a.dtype)[..., None]
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1, 1).astype(a.dtype)
    return normalize(a + (b * sign - a) * t)


def slerp(a: np.ndarray, b: np.ndarray, t) -> np.ndarray:
    """Spherical interpolation on the shortest arc (falls back to nlerp when close)."""
    t = np.asarray(t, dtype=np.float64)[..., None]
    a64 = a.astype(np.float64)
    b64 = b.astype(np.float64)
    d = np.sum(a64 * b64, axis=-1, keepdims=True)
    b64 = np.where(d < 0, -b64, b64)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    close = s < 1e-6
    safe = np.where(close, 1.0, s)
    wa = np.where(close, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(close, t, np.sin(t * theta) / safe)
    return normalize(wa * a64 + wb * b64).astype(a.dtype)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack([
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    ], axis=-1)
    return m.reshape(q.shape[:-1] + (3, 3))


def from_matrix(m: np.ndarray) -> np.ndarray:
    """Unit quaternions (``w >= 0``) of rotation matrices ``(..., 3, 3)``.

    Uses the numerically stable branch on the largest diagonal term.
    """
    m = np.asarray(m)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,), dtype=np.result_type(m.dtype, np.float32))
    # branch w
    s = np.sqrt(np.maximum(1.0 + tr, 1e-30)) * 2
    qw = np.stack([0.25 * s, (m[..., 2, 1] - m[..., 1, 2]) / s,
                   (m[..., 0, 2] - m[..., 2, 0]) / s, (m[..., 1, 0] - m[..., 0, 1]) / s], -1)
    s = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-30)) * 2
    qx = np.stack([(m[..., 2, 1] - m[..., 1, 2]) / s, 0.25 * s,
                   (m[..., 0, 1] + m[..., 1, 0]) / s, (m[..., 0, 2] + m[..., 2, 0]) / s], -1)
    s = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 1e-30)) * 2
    qy = np.stack([(m[..., 0, 2] - m[..., 2, 0]) / s, (m[..., 0, 1] + m[..., 1, 0]) / s,
                   0.25 * s, (m[..., 1, 2] + m[..., 2, 1]) / s], -1)
    s = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 1e-30)) * 2
    qz = np.stack([(m[..., 1, 0] - m[..., 0, 1]) / s, (m[..., 0, 2] + m[..., 2, 0]) / s,
                   (m[..., 1, 2] + m[..., 2, 1]) / s, 0.25 * s], -1)
    q[...] = np.choose(k[..., None], [qw, qx, qy, qz])
    q = normalize(q)
    return np.where(q[..., :1] < 0, -q, q)
