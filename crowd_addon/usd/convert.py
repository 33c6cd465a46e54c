"""numpy -> ``pxr.Vt`` arrays, the one place that knows USD's memory layouts.

Two conventions differ between ``core`` and USD and are converted only here:

- quaternions: ``core`` stores ``(w, x, y, z)`` (docs/architecture.md); ``Gf.Quatf`` keeps
  the imaginary part first in memory, so ``Vt.QuatfArray`` buffers are
  ``(x, y, z, w)`` (its constructor ``Gf.Quatf(w, x, y, z)`` is real-first);
- matrices: ``core`` uses column vectors (``p' = M @ p``, translation in the last
  column); ``Gf.Matrix4d`` uses row vectors (translation in the last row), so every
  matrix is transposed.
"""

from __future__ import annotations

import numpy as np
from pxr import Vt

from ..core.base import pose as sqt

__all__ = ["sqt_components", "translations", "rotations", "scales", "matrices", "vec3f",
           "ints", "floats"]

#: core (w, x, y, z) -> Gf.Quatf memory order (x, y, z, w)
_QUAT_MEMORY_ORDER = [1, 2, 3, 0]


def sqt_components(pose: np.ndarray) -> tuple:
    """Split local SQT poses into USD's SkelAnimation value layouts (no copies to Vt yet).

    Parameters
    ----------
    pose : (..., B, 10) float32 local SQT (scale, quaternion (w, x, y, z), translation).

    Returns
    -------
    (translations, rotations, scales): C-contiguous ``(..., B, 3)`` float32,
    ``(..., B, 4)`` float32 in ``Gf.Quatf`` memory order ``(x, y, z, w)``, and
    ``(..., B, 3)`` float16 (``half3``, UsdSkel's scale type).
    """
    p = np.asarray(pose, np.float32)
    translations = np.ascontiguousarray(p[..., sqt.TRANS])
    rotations = np.ascontiguousarray(p[..., sqt.ROT][..., _QUAT_MEMORY_ORDER])
    scales = np.ascontiguousarray(p[..., sqt.SCALE].astype(np.float16))
    return translations, rotations, scales


def translations(a: np.ndarray) -> Vt.Vec3fArray:
    """``(B, 3)`` float32 -> ``float3[]``."""
    return Vt.Vec3fArray.FromNumpy(a)


def rotations(a: np.ndarray) -> Vt.QuatfArray:
    """``(B, 4)`` float32 in memory order ``(x, y, z, w)`` -> ``quatf[]``."""
    return Vt.QuatfArray.FromNumpy(a)


def scales(a: np.ndarray) -> Vt.Vec3hArray:
    """``(B, 3)`` float16 -> ``half3[]``."""
    return Vt.Vec3hArray.FromNumpy(a)


def matrices(m: np.ndarray) -> Vt.Matrix4dArray:
    """``(n, 4, 4)`` column-vector matrices -> ``matrix4d[]`` (transposed, float64)."""
    return Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(
        np.swapaxes(np.asarray(m, np.float64), -1, -2)))


def vec3f(a: np.ndarray) -> Vt.Vec3fArray:
    """``(n, 3)`` -> ``float3[]`` / ``point3f[]`` / ``normal3f[]``."""
    return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(a, np.float32))


def ints(a: np.ndarray) -> Vt.IntArray:
    """Any integer array -> flat ``int[]``."""
    return Vt.IntArray.FromNumpy(np.ascontiguousarray(np.asarray(a).reshape(-1), np.int32))


def floats(a: np.ndarray) -> Vt.FloatArray:
    """Any float array -> flat ``float[]``."""
    return Vt.FloatArray.FromNumpy(np.ascontiguousarray(np.asarray(a).reshape(-1),
                                                        np.float32))
