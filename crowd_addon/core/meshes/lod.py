"""Which level of detail an agent is drawn with: by its projected height in pixels.

An agent's projected height is its body's height (the full mesh's bind-pose bounding
height times the agent's scale) over its depth in front of the camera times the
view's focal length in pixels (:func:`projected_heights`). LOD ``k`` is drawn once the
agent is shorter than ``lod_pixels[k - 1]`` pixels (:func:`levels_from_pixels`), so
the level depends on how big the agent is drawn, whatever the output size, lens or
body size; and each automatic level is checked (:mod:`.lod_check`) at the size it is
switched in at.

``CrowdConfig.lod_distances``, when set, says the same thresholds the older way:
distances in metres at which a :data:`REFERENCE_HEIGHT_M` tall agent crosses them in
the reference view (1080 pixels high, 40 degree vertical field of view:
:data:`REFERENCE_FOCAL_PX`); :func:`switch_pixels` turns them into pixels.
"""

from __future__ import annotations

import numpy as np

from ..base.errors import CrowdError

__all__ = ["DEFAULT_LOD_PIXELS", "REFERENCE_FOCAL_PX", "REFERENCE_HEIGHT_M", "MAX_LOD_LEVELS",
           "check_lod_pixels", "check_lod_distances", "pixels_from_distances",
           "switch_pixels", "projected_heights", "levels_from_pixels", "agent_heights"]

REFERENCE_FOCAL_PX = 540.0 / np.tan(np.radians(20.0))
"""Focal length in pixels of the reference view of ``lod_distances``: 1080 pixels high,
40 degrees vertical field of view (~1484 px)."""
REFERENCE_HEIGHT_M = 1.8
"""The agent height ``lod_distances`` are converted to pixel thresholds with."""
DEFAULT_LOD_PIXELS = (90.0, 45.0, 30.0, 15.0)
"""LOD 1 below 90 px tall, LOD 2 below 45 px, the far level (a box per body part,
:func:`.levels.parts_lod`) below 30 px, and the far level with its small parts joined
(fewer boxes, :func:`.lod_check.fit_levels`) below 15 px (what the default distances
30, 60, 90, 180 m give a 1.8 m agent in the reference view). The far level switched in
at 18 px until its crossed quads were replaced by boxes lit like round parts: at 30 px
the quads cost 0.034 of image error, the boxes stay within the silhouette check's
pixel there. The fan's boxes joined into 15 stray 2 px at 20-30 px and 1 px at 15 px:
the 65k demo's fans, three quarters of them below 15 px at 960x540, each draw 120
vertices instead of 176."""
MAX_LOD_LEVELS = 8
"""The most thresholds (levels after the full mesh) a configuration may name."""


def _thresholds(values, what: str, unit: str, order: str) -> tuple:
    try:
        v = np.asarray(values, np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise CrowdError(f"{what}: must be a list of numbers, got {values!r}") from None
    if v.size == 0 or v.size > MAX_LOD_LEVELS:
        raise CrowdError(f"{what}: must name 1 to {MAX_LOD_LEVELS} thresholds (one per level "
                         f"after the full mesh), got {v.size}")
    step = np.diff(v) if order == "increasing" else -np.diff(v)
    if not (np.isfinite(v).all() and (v > 0).all() and (step > 0).all()):
        raise CrowdError(f"{what}: must be strictly {order} {unit} > 0, got {v.tolist()}")
    return tuple(float(x) for x in v)


def check_lod_pixels(values, what: str = "lod_pixels") -> tuple:
    """``values`` as a tuple of floats: 1 to :data:`MAX_LOD_LEVELS` strictly decreasing
    projected heights in pixels > 0; CrowdError otherwise."""
    return _thresholds(values, what, "pixels", "decreasing")


def check_lod_distances(values, what: str = "lod_distances") -> tuple:
    """``values`` as a tuple of floats: 1 to :data:`MAX_LOD_LEVELS` strictly increasing
    distances in metres > 0; CrowdError otherwise."""
    return _thresholds(values, what, "metres", "increasing")


def pixels_from_distances(distances, height: float = REFERENCE_HEIGHT_M) -> tuple:
    """The pixel thresholds a ``height`` tall agent crosses at ``distances`` metres in
    the reference view."""
    d = check_lod_distances(distances)
    return tuple(float(height * REFERENCE_FOCAL_PX / x) for x in d)


def switch_pixels(config) -> tuple:
    """The pixel thresholds of ``config``: its ``lod_distances`` converted when set
    (:func:`pixels_from_distances`), else its ``lod_pixels``."""
    if getattr(config, "lod_distances", None) is not None:
        return pixels_from_distances(config.lod_distances)
    return check_lod_pixels(config.lod_pixels)


def projected_heights(heights, depths, focal_px) -> np.ndarray:
    """``(N,)`` projected heights in pixels: ``heights`` (metres) over ``depths`` (in
    front of the camera, metres; 1 for an orthographic view) times ``focal_px`` (the
    view's focal length in pixels). At or behind the camera: infinitely tall."""
    d = np.asarray(depths, np.float64)
    with np.errstate(divide="ignore"):
        return np.where(d > 0, np.asarray(heights, np.float64) * float(focal_px)
                        / np.where(d > 0, d, 1.0), np.inf)


def levels_from_pixels(pixels, lod_pixels, levels) -> np.ndarray:
    """``(N,)`` LOD per agent from its projected height ``pixels`` (N,): the number of
    thresholds ``lod_pixels`` (decreasing) it is shorter than, clamped to the levels
    ``(N,)`` its body has."""
    t = -np.asarray(lod_pixels, np.float64)
    lod = np.searchsorted(t, -np.asarray(pixels, np.float64), side="left")
    return np.minimum(lod, np.asarray(levels) - 1)


def agent_heights(bodies, agent_body, scales=None) -> np.ndarray:
    """``(N,)`` each agent's height in metres: its body's full mesh's bind-pose bounding
    height (``bodies[k][0]``, a mesh or its buffers with an ``extent``; a body with no levels: :data:`REFERENCE_HEIGHT_M`) times
    its scale (``scales`` (N,); None or empty: 1)."""
    def height(m):
        e = getattr(m, "extent", None)        # (2, 3) bind-pose box, where kept
        if e is not None:
            return float(np.asarray(e)[1, 2] - np.asarray(e)[0, 2])
        p = np.asarray(m.positions)
        return float(np.ptp(p[:, 2])) if len(p) else REFERENCE_HEIGHT_M

    h = np.array([height(b[0]) if len(b) else REFERENCE_HEIGHT_M for b in bodies] or
                 [REFERENCE_HEIGHT_M])
    h = np.where(h > 0, h, REFERENCE_HEIGHT_M)
    out = h[np.asarray(agent_body, np.int64)]
    s = None if scales is None else np.asarray(scales, np.float64).reshape(-1)
    return out * s if s is not None and s.size == out.size else out
