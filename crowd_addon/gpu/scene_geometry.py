"""The scene around the crowd, as the renderers draw it: :class:`SceneGeometry`.

Stands, pitch, walls and props of a Blender scene become one list of world-space
triangles, three corners each with a normal and a linear RGB colour (the object's
material). The renderers draw it before the agents through the same camera, with
the same light and into the same depth buffer (:data:`~.programs.SCENE_DRAW`), so
the crowd sits in its scene: a fan behind a wall is hidden, the stands are lit by
the same sun as the fans. :func:`crowd_addon.blender.scene_geometry.scene_geometry`
makes one from a scene; anything else that can give triangles can too.

:func:`sun_light` turns a sun's direction into the renderers' ``light`` tuple.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.base.errors import CrowdError

__all__ = ["SceneGeometry", "sun_light", "DEFAULT_AMBIENT"]

#: The share of light that is ambient when a scene gives none (the renderers' default).
DEFAULT_AMBIENT = 0.35


@dataclass(frozen=True)
class SceneGeometry:
    """Triangles in world space (metres, Z up).

    ``positions``, ``normals``, ``colors``: ``(3 T, 3)`` float32, corner ``3 t + k`` of
    triangle ``t``; colours are linear RGB in 0..1, normals unit length (the renderer
    flips them towards the viewer, so winding does not matter). ``objects``: the
    names of the objects the triangles came from, for reports.
    """

    positions: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    objects: tuple = ()

    def __post_init__(self):
        arrays = {}
        for name in ("positions", "normals", "colors"):
            a = np.ascontiguousarray(getattr(self, name), np.float32)
            if a.ndim != 2 or a.shape[1] != 3:
                raise CrowdError(f"scene geometry: {name} must be (corners, 3), got "
                                 f"shape {a.shape}")
            if not np.isfinite(a).all():
                raise CrowdError(f"scene geometry: {name} holds NaN or infinite values")
            arrays[name] = a
        n = arrays["positions"].shape[0]
        if n % 3 or any(a.shape[0] != n for a in arrays.values()):
            raise CrowdError(f"scene geometry: positions, normals and colors must have the "
                             f"same number of corners, a multiple of 3 (got "
                             f"{[a.shape[0] for a in arrays.values()]})")
        for name, a in arrays.items():
            object.__setattr__(self, name, a)
        object.__setattr__(self, "objects", tuple(self.objects))

    @property
    def triangle_count(self) -> int:
        return self.positions.shape[0] // 3

    def bounds(self):
        """``(lo, hi)`` float64 corners of the box around every triangle."""
        if not self.triangle_count:
            raise CrowdError("scene geometry: no triangles")
        return self.positions.min(0).astype(np.float64), self.positions.max(0).astype(
            np.float64)

    def interleaved(self) -> np.ndarray:
        """``(3 T, 9)`` float32: position, normal, colour per corner (36 bytes)."""
        return np.ascontiguousarray(np.hstack([self.positions, self.normals, self.colors]))


def sun_light(direction, ambient: float = DEFAULT_AMBIENT) -> tuple:
    """The renderers' ``light`` ``(x, y, z, ambient)`` for a sun shining along
    ``direction`` (3 numbers, from the sun towards the ground: a Blender sun lamp's
    local -Z): the light vector points back towards the sun."""
    d = -np.asarray(direction, np.float64).reshape(-1)
    norm = np.linalg.norm(d) if d.shape == (3,) else 0.0
    if not (np.isfinite(norm) and norm > 1e-12):
        raise CrowdError(f"sun direction must be 3 finite numbers, not all 0; got "
                         f"{direction!r}")
    if not 0.0 <= float(ambient) <= 1.0:
        raise CrowdError(f"ambient light must be in 0..1, got {ambient}")
    d /= norm
    return (float(d[0]), float(d[1]), float(d[2]), float(ambient))
