"""The silhouette check of LOD levels: does a level, skinned over its character's
poses, draw the body the full mesh draws at the size it is switched in at?

Each level and the full mesh are skinned (paper Eq. 1, :func:`.skinning.skin_vertices`)
over sampled poses, and their silhouettes rasterised (a small numpy rasteriser,
orthographic, from a few horizontal view directions) at the level's switch size: the
full mesh's height in that pose spans that many pixels. A level's departure is the
pixels where the two silhouettes differ over the full silhouette's outline length:
about how far, in pixels, its outline strays from the full mesh's. A level that tears
(vertices of two body parts merged, so a raised arm drags a wedge of torso up with it)
departs by many pixels; :func:`check_levels` refuses it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .skinning import skin_vertices, skinning_matrices

__all__ = ["silhouette", "departure", "check_levels", "BUDGET_PX"]

#: the largest departure (pixels of outline) a level may have at its switch size
BUDGET_PX = 1.0
VIEWS = (0.0, 60.0, 120.0)       # degrees about +Z


def silhouette(points, triangles, frame, pixels: int) -> np.ndarray:
    """``(pixels, W)`` bool coverage of ``triangles`` over ``points`` (V, 2) (u, z),
    in ``frame`` = (u0, z0, scale): pixel centres at ``u0 + (i + 0.5) / scale``."""
    u0, z0, s = frame
    q = (np.asarray(points, np.float64) - (u0, z0)) * s
    h = int(pixels) + 2
    w = int(np.ceil(q[:, 0].max(initial=1.0))) + 2
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    c = np.c_[xs.ravel(), ys.ravel()]
    a, b, d = (q[np.asarray(triangles, np.int64)[:, k]] for k in range(3))
    out = np.zeros(c.shape[0], bool)
    for lo in range(0, a.shape[0], 256):
        A, B, D = a[lo:lo + 256, None], b[lo:lo + 256, None], d[lo:lo + 256, None]

        def edge(p, r):
            return (r[..., 0] - p[..., 0]) * (c[None, :, 1] - p[..., 1]) - \
                (r[..., 1] - p[..., 1]) * (c[None, :, 0] - p[..., 0])
        e0, e1, e2 = edge(A, B), edge(B, D), edge(D, A)
        inside = ((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0))
        out |= inside.any(0)
    return out.reshape(h, w)


def _outline(mask) -> int:
    m = np.pad(mask, 1)
    inner = m[1:-1, 1:-1] & m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
    return int((mask & ~inner).sum())


def departure(level, full, skeleton, poses, pixels: float) -> float:
    """The largest departure in pixels (differing pixels over the full silhouette's
    outline) of ``level`` from ``full`` over ``poses`` (n, B, 10) local SQT and
    :data:`VIEWS`, the full mesh ``pixels`` tall."""
    rows = skinning_matrices(np.asarray(poses, np.float64), skeleton)
    a = skin_vertices(full.positions, full.bone_indices, full.bone_weights, rows)
    b = skin_vertices(level.positions, level.bone_indices, level.bone_weights, rows)
    worst = 0.0
    for n in range(rows.shape[0]):
        for deg in VIEWS:
            t = np.radians(deg)
            flat = [np.c_[p[:, 0] * np.cos(t) + p[:, 1] * np.sin(t), p[:, 2]]
                    for p in (a[n], b[n])]
            lo = np.minimum(flat[0].min(0), flat[1].min(0))
            s = float(pixels) / max(float(np.ptp(flat[0][:, 1])), 1e-6)
            frame = (lo[0] - 1.0 / s, lo[1] - 1.0 / s, s)
            fa = silhouette(flat[0], full.triangles, frame, pixels)
            fb = silhouette(flat[1], level.triangles, frame, pixels)
            w = max(fa.shape[1], fb.shape[1])
            fa = np.pad(fa, ((0, 0), (0, w - fa.shape[1])))
            fb = np.pad(fb, ((0, 0), (0, w - fb.shape[1])))
            worst = max(worst, float((fa ^ fb).sum()) / max(_outline(fa), 1))
    return worst


def check_levels(levels, skeleton, poses, switch_px, budget_px: float = BUDGET_PX):
    """``(levels, notes)``: ``levels`` (full mesh first) with each level ``k >= 1``
    whose :func:`departure` at ``switch_px[k - 1]`` pixels exceeds ``budget_px``
    refused: replaced by the level before it (under its own name), with a note."""
    out, notes = [levels[0]], []
    for k, level in enumerate(levels[1:], start=1):
        px = float(switch_px[min(k - 1, len(switch_px) - 1)])
        d = departure(level, levels[0], skeleton, poses, px)
        if d > budget_px:
            notes.append(f"LOD {k} {level.name!r} refused: its silhouette departs from the "
                         f"full mesh by {d:.2f} px at {px:.0f} px tall (budget "
                         f"{budget_px:g} px); the level before is used")
            level = replace(out[-1], name=level.name)
        out.append(level)
    return out, notes
