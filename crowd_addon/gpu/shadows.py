"""Sun shadows for the crowd in its scene: the sun's view of the scene and the crowd.

A shadow map is the depth the sun sees, through an orthographic view along its light
(:func:`sun_view`), fitted around the agents (their box, one proxy height up, with a
margin) and deep enough to hold every scene triangle that could cast into it. The
renderers draw it before each frame (:meth:`~.renderer.CrowdRenderer.render`): the
scene, then every agent the camera draws, each as the coarsest level of its proxy
(the 8-vertex card where there is one: it follows the root and the head, so a fan
standing up casts a longer shadow) -- a shadow costs one cheap draw per agent. Then
``crowd_frag.glsl`` dims the sun's light where the map says the sun is hidden.

The fragment stage reads the matrix from a 4 x 1 RGBA32F texture (its columns) rather
than a push constant: the draw program's push constants already fill the 128 bytes
every backend guarantees. :data:`LIT_VIEW` is the stand-in used without shadows (and
while the map itself is drawn): it sends every point outside the map, so all is lit.
"""

from __future__ import annotations

import numpy as np

from ..core.base.camera import look_at

__all__ = ["SHADOW_SIZE", "LIT_VIEW", "sun_view", "view_texels"]

#: Texels a side of the shadow map (2048: about 7 cm a texel over a 140 m bowl).
SHADOW_SIZE = 2048
#: A view-projection that puts every point outside the map (nothing in shadow).
LIT_VIEW = np.array([[0.0, 0, 0, 3], [0, 0, 0, 3], [0, 0, 0, 3], [0, 0, 0, 1]])


def sun_view(light, lo, hi, scene_bounds=None, margin: float = 1.0) -> np.ndarray:
    """The sun's view-projection (4, 4), OpenGL clip space: orthographic along
    ``light`` (x, y, z towards the sun, ...) framing the box ``lo .. hi`` (the agents'
    reach) plus ``margin`` metres, its depth range stretched over ``scene_bounds``
    ``(lo, hi)`` too so that scene casters between the sun and the box are kept."""
    d = np.asarray(light[:3], np.float64)
    d /= np.linalg.norm(d)
    lo, hi = np.asarray(lo, np.float64) - margin, np.asarray(hi, np.float64) + margin
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2
    up = (0.0, 0.0, 1.0) if abs(d[2]) < 0.99 else (0.0, 1.0, 0.0)
    view = look_at(centre + d * (radius + 1.0), centre, up)

    def corners(a, b):
        c = np.array(np.meshgrid(*zip(a, b))).reshape(3, -1).T
        return c @ view[:3, :3].T + view[:3, 3]
    box = corners(lo, hi)
    depth = box[:, 2]
    if scene_bounds is not None:
        depth = np.concatenate([depth, corners(*scene_bounds)[:, 2]])
    x0, y0 = box[:, :2].min(0)
    x1, y1 = box[:, :2].max(0)
    near, far = -depth.max() - 0.5, -depth.min() + 0.5      # camera looks down its -Z
    proj = np.eye(4)
    proj[0, 0], proj[0, 3] = 2 / (x1 - x0), -(x1 + x0) / (x1 - x0)
    proj[1, 1], proj[1, 3] = 2 / (y1 - y0), -(y1 + y0) / (y1 - y0)
    proj[2, 2], proj[2, 3] = -2 / (far - near), -(far + near) / (far - near)
    return proj @ view


def view_texels(view_projection) -> np.ndarray:
    """``(1, 4, 4)`` float32: the matrix's columns as the four texels the fragment
    stage reads (``shadow_view_tex``)."""
    return np.ascontiguousarray(np.asarray(view_projection, np.float64).T[None], np.float32)
