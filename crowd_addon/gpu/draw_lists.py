"""Which agents each instanced draw covers: one draw per (body, LOD).

A body is what an agent is drawn with: its character's mesh variant with the props
it carries (:mod:`crowd_addon.core.meshes.bodies`). Agents outside the camera's view (a
bounding sphere per body) are left out. An agent's LOD follows its projected height
in pixels (:func:`~crowd_addon.core.meshes.lod.projected_heights`: its body's height times
its scale over its depth times the view's focal length in pixels): LOD ``k`` once it
is shorter than ``lod_pixels[k - 1]`` (:func:`~crowd_addon.core.meshes.lod.switch_pixels`),
clamped to the levels its body has. Zooming in (a longer lens) or a taller viewport
makes agents taller, so close-ups keep their detail; a small or wide view (or an
orthographic one, zoomed out) gets the coarse levels sooner; a tall agent keeps its
detail further than a short one. The visible agents are
grouped by (body, LOD) in one flat list (an R32I texture,
``gpu_shaders/agents.glsl``); draw ``g`` reads its instances from ``base[g]``. The list
is rebuilt only when the camera, the viewport's height or the agents move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.base.errors import CrowdError
from ..core.meshes.lod import (REFERENCE_FOCAL_PX, check_lod_pixels, levels_from_pixels,
                               projected_heights)
from ..core.runtime.pose_storage import TextureRegion

__all__ = ["DrawGroup", "DrawLists", "lod_levels", "frustum_planes",
           "proxy_bounds", "view_distances", "view_depths", "REFERENCE_FOCAL_PX"]



def lod_levels(distances: np.ndarray, lod_distances, levels: np.ndarray) -> np.ndarray:
    """LOD index per agent: ``(N,)`` int, from distances ``(N,)`` in metres, the
    increasing thresholds ``lod_distances`` and the number of levels ``(N,)`` each
    agent's proxy has."""
    lod = np.searchsorted(np.asarray(lod_distances, np.float64), distances, side="right")
    return np.minimum(lod, np.asarray(levels) - 1)


def view_depths(points: np.ndarray, view_projection, pixels_high) -> tuple:
    """``(depths (N,), focal)``: clip ``w`` of ``points`` (N, 3) (the depth in front of
    the camera, 1 for an orthographic view) and the view's focal length in pixels (half
    the height times the projection's vertical scale)."""
    m = np.asarray(view_projection, np.float64)
    focal = 0.5 * float(pixels_high) * float(np.linalg.norm(m[1, :3]))
    if not focal > 0:
        raise CrowdError(f"LOD: the view has no vertical scale ({pixels_high} pixels high, "
                         f"view-projection row 1 = {m[1].tolist()})")
    return np.asarray(points, np.float64) @ m[3, :3] + m[3, 3], focal


def view_distances(points: np.ndarray, view_projection, pixels_high) -> np.ndarray:
    """``(N,)`` distances in metres at which ``points`` (N, 3) would look as big in the
    reference view as they do through ``view_projection`` (4, 4, OpenGL clip space)
    in a viewport ``pixels_high`` pixels high: clip ``w`` (the depth, or 1 for an
    orthographic view) times the reference focal length over this view's focal length
    in pixels (half the height times the projection's vertical scale)."""
    m = np.asarray(view_projection, np.float64)
    focal = 0.5 * float(pixels_high) * float(np.linalg.norm(m[1, :3]))
    if not focal > 0:
        raise CrowdError(f"LOD: the view has no vertical scale ({pixels_high} pixels high, "
                         f"view-projection row 1 = {m[1].tolist()})")
    w = np.asarray(points, np.float64) @ m[3, :3] + m[3, 3]
    return np.maximum(w, 0.0) * (REFERENCE_FOCAL_PX / focal)


def frustum_planes(view_projection: np.ndarray) -> np.ndarray:
    """(6, 4) planes ``(n, d)`` with unit ``n`` of a view-projection matrix; a point
    ``p`` is inside when ``n . p + d >= 0`` for all six (Gribb and Hartmann)."""
    m = np.asarray(view_projection, np.float64)
    planes = np.stack([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2],
                       m[3] - m[2]])
    return planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)


def proxy_bounds(extent: np.ndarray, margin: float = 1.5) -> tuple:
    """``(centre height, radius)`` in metres of a sphere holding a proxy whose
    bind-pose box is ``extent`` (2, 3), at any heading about +Z, with ``margin`` for
    poses that reach further than the bind pose."""
    ext = np.asarray(extent, np.float64)
    zc = float(ext[:, 2].mean())
    corners = np.array(np.meshgrid(ext[:, 0], ext[:, 1], ext[:, 2] - zc)).reshape(3, -1)
    return zc, float(np.linalg.norm(corners, axis=0).max()) * margin


@dataclass(frozen=True)
class DrawGroup:
    """Instances ``base .. base + count`` of the list: agents of ``body`` at ``lod``."""

    body: int
    lod: int
    base: int
    count: int


class DrawLists:
    """Visible agent ids grouped per (body, LOD), laid out as a flat int32 texture.

    Parameters
    ----------
    agent_body : (N,) int body index per agent.
    lod_counts : (K,) int LOD levels of each body (0: not drawn).
    bounds : (K, 2) float ``(centre height, radius)`` per body (:func:`proxy_bounds`).
    lod_pixels : decreasing thresholds in pixels (projected heights).
    max_width : texture width limit in texels.
    lod : False draws every agent at level 0, its full mesh.
    heights : (N,) each agent's height in metres (its body's bind-pose height times
        its scale); None: 1.8 m each.

    Attributes
    ----------
    groups : list of :class:`DrawGroup` after :meth:`rebuild`.
    lod : (N,) int LOD of each agent, ``-1`` where it is not drawn.
    """

    def __init__(self, agent_body, lod_counts, bounds, lod_pixels, max_width=4096,
                 lod=True, heights=None):
        self.agent_body = np.asarray(agent_body, np.int64)
        self.lod_counts = np.asarray(lod_counts, np.int64)
        self.bounds = np.asarray(bounds, np.float64).reshape(-1, 2)
        self.lod_pixels = np.asarray(check_lod_pixels(lod_pixels), np.float64)
        self.heights = np.full(self.agent_body.size, 1.8) if heights is None else \
            np.broadcast_to(np.asarray(heights, np.float64), self.agent_body.shape)
        self.levels = max(1, int(self.lod_counts.max(initial=1)))
        n = self.agent_body.size
        self.width = max(1, min(max_width, n))
        self.height = max(1, -(-n // self.width))
        self.image = np.zeros((self.height, self.width, 1), np.int32)
        self.agent_levels = self.lod_counts[self.agent_body]
        self.use_lod = bool(lod)
        self.groups = []
        self.lod = np.full(n, -1, np.int64)

    def rebuild(self, positions: np.ndarray, view_projection, pixels_high,
                cull: bool = True) -> list:
        """Regroup the agents at ``positions`` (N, 3) seen through ``view_projection``
        (4, 4) in a viewport ``pixels_high`` pixels high (LOD by projected height),
        leaving out those outside the view when ``cull``; returns the texture regions to
        upload. Agents whose body has no levels are never drawn."""
        pos = np.asarray(positions, np.float64)
        centre = pos.copy()
        centre[:, 2] += self.bounds[self.agent_body, 0]
        drawn = self.agent_levels > 0
        if cull:
            planes = frustum_planes(view_projection)
            dist = centre @ planes[:, :3].T + planes[:, 3]
            drawn &= (dist >= -self.bounds[self.agent_body, 1][:, None]).all(1)
        depth, focal = view_depths(centre, view_projection, pixels_high)
        self.pixels = projected_heights(self.heights, depth, focal)
        level = levels_from_pixels(self.pixels, self.lod_pixels, self.agent_levels) \
            if self.use_lod else np.zeros(drawn.size, np.int64)
        self.lod = np.where(drawn, level, -1)
        key = (self.agent_body * self.levels + self.lod)[drawn]
        key = key.astype(np.int16 if key.size and key.max() < 2 ** 15 else np.int64)
        order = np.flatnonzero(drawn)[np.argsort(key, kind="stable")]
        counts = np.bincount(key, minlength=self.lod_counts.size * self.levels)
        bases = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.groups = [DrawGroup(int(g // self.levels), int(g % self.levels), int(bases[g]),
                                 int(counts[g])) for g in np.flatnonzero(counts)]
        self.image.reshape(-1)[:order.size] = order
        rows = max(1, -(-order.size // self.width))
        return [TextureRegion(0, 0, self.width, rows, self.image[:rows])]

