"""The silhouette check of LOD levels: does a level, skinned over its character's
poses, draw the body the full mesh draws at the size it is switched in at?

Each level and the full mesh are skinned (paper Eq. 1, :func:`.skinning.skin_vertices`)
over sampled poses, and their silhouettes rasterised (a small numpy rasteriser,
orthographic, from a few horizontal view directions) at the level's switch size: the
full mesh's height in that pose spans that many pixels. A level's departure is the
pixels where the two silhouettes differ over the full silhouette's outline length:
about how far, in pixels, its outline strays from the full mesh's. A level that tears
(vertices of two body parts merged, so a raised arm drags a wedge of torso up with it)
departs by many pixels; :func:`fit_levels` refuses it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..base.skinning import skin_vertices, skinning_matrices

__all__ = ["silhouette", "departure", "fit_levels", "clip_poses",
           "BUDGET_PX", "ERROR_PIXELS", "JOIN_SHARES"]

#: the largest departure (pixels of outline) a level may have at its switch size
BUDGET_PX = 1.0
#: the share of the full silhouette's outline (in pixels) that may stray further
SLACK = 0.02
VIEWS = (0.0, 60.0, 120.0)       # degrees about +Z
#: the collapse error bounds :func:`fit_levels` tries for a decimated level, in pixels
#: at its switch height, coarsest first: the first whose level passes the check wins
ERROR_PIXELS = (1.0, 0.5, 0.25)
#: the shares of the surface under which a far level's parts are joined to a neighbour
#: (:func:`~.levels.parts_lod`), tried coarsest first: the fan's 22 boxes become 5 at
#: 0.15, 10 at 0.045, 15 at 0.025; 0 keeps a box for every part
JOIN_SHARES = (0.15, 0.1, 0.045, 0.025, 0.0)
_WIN = 6                         # the window of a small triangle, pixels


def silhouette(points, triangles, frame, pixels: int) -> np.ndarray:
    """``(pixels + 2, W)`` bool coverage of ``triangles`` over ``points`` (V, 2) (u, z),
    in ``frame`` = (u0, z0, scale): pixel centres at ``u0 + (i + 0.5) / scale``.

    Each triangle is tested against the pixel centres of its own bounding box: small
    ones (most of a body at the sizes levels switch at) all at once in a fixed
    :data:`_WIN` x :data:`_WIN` window, the few larger ones one by one."""
    u0, z0, s = frame
    q = (np.asarray(points, np.float64) - (u0, z0)) * s
    h = int(pixels) + 2
    w = int(np.ceil(q[:, 0].max(initial=1.0))) + 2
    out = np.zeros((h, w), bool)
    a, b, d = (q[np.asarray(triangles, np.int64)[:, k]] for k in range(3))
    lo = np.floor(np.minimum(np.minimum(a, b), d) - 0.5).astype(np.int64) + 1
    hi = np.floor(np.maximum(np.maximum(a, b), d) - 0.5).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, (w - 1, h - 1))
    span = hi - lo
    keep = (span >= 0).all(1)
    small = keep & (span < _WIN).all(1)

    def cover(A, B, D, x, y):
        def edge(p, r):
            return (r[..., 0] - p[..., 0]) * (y - p[..., 1]) - \
                (r[..., 1] - p[..., 1]) * (x - p[..., 0])
        e0, e1, e2 = edge(A, B), edge(B, D), edge(D, A)
        return ((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0))

    if small.any():
        off = np.arange(_WIN)
        x = lo[small, 0][:, None, None] + off[None, None, :]
        y = lo[small, 1][:, None, None] + off[None, :, None]
        inside = cover(a[small][:, None, None], b[small][:, None, None],
                       d[small][:, None, None], x + 0.5, y + 0.5)
        inside &= (x <= hi[small, 0][:, None, None]) & (y <= hi[small, 1][:, None, None])
        out[np.broadcast_to(y, inside.shape)[inside], np.broadcast_to(x, inside.shape)[inside]] = True
    for t in np.flatnonzero(keep & ~small):
        ys, xs = np.mgrid[lo[t, 1]:hi[t, 1] + 1, lo[t, 0]:hi[t, 0] + 1]
        out[ys, xs] |= cover(a[t], b[t], d[t], xs + 0.5, ys + 0.5)
    return out


def _outline(mask) -> int:
    m = np.pad(mask, 1)
    inner = m[1:-1, 1:-1] & m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
    return int((mask & ~inner).sum())


def _dilate(mask):
    m = np.pad(mask, 1)
    out = m[1:-1, 1:-1] | m[:-2, 1:-1] | m[2:, 1:-1] | m[1:-1, :-2] | m[1:-1, 2:]
    out |= m[:-2, :-2] | m[:-2, 2:] | m[2:, :-2] | m[2:, 2:]
    return out


def _stray(fa, fb, slack: int, most: int = 32) -> int:
    """How far, in pixels (chessboard), ``fb``'s pixels stray outside ``fa``: the
    smallest ``d`` such that at most ``slack`` pixels of ``fb`` lie more than ``d``
    from ``fa`` (``most`` at most)."""
    out = fb & ~fa
    grown = fa
    d = 0
    while int(out.sum()) > slack and d < most:
        grown = _dilate(grown)
        out &= ~grown
        d += 1
    return d


def departure(level, full, skeleton, poses, pixels: float) -> float:
    """How far, in pixels, ``level``'s silhouette strays from ``full``'s (either way)
    at worst over ``poses`` (n, B, 10) local SQT and :data:`VIEWS`, the full mesh
    ``pixels`` tall in each pose: the distance beyond which no more than
    :data:`SLACK` of the full silhouette's outline (and at least one pixel) lies --
    a few stray pixels of rasterisation are forgiven, an arm left hanging or a wedge
    of torso dragged up is not (it strays by its length)."""
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
            top = int(np.ceil((max(flat[0][:, 1].max(), flat[1][:, 1].max()) - frame[1]) * s))
            fa = silhouette(flat[0], full.triangles, frame, top)
            fb = silhouette(flat[1], level.triangles, frame, top)
            w = max(fa.shape[1], fb.shape[1])
            fa = np.pad(fa, ((0, 0), (0, w - fa.shape[1])))
            fb = np.pad(fb, ((0, 0), (0, w - fb.shape[1])))
            slack = max(1, int(SLACK * _outline(fa)))
            worst = max(worst, _stray(fa, fb, slack), _stray(fb, fa, slack))
    return float(worst)


def fit_levels(mesh, lods, skeleton, poses, switch_px, budget_px: float = BUDGET_PX):
    """``(levels, notes)``: ``mesh`` and its automatic levels ``lods`` (triangle ratios,
    then optionally one or more :data:`~.levels.CARD`), each the lightest that passes
    the check.

    A decimated level ``k`` (:func:`~.levels.decimated`, from the level before) is tried
    with its collapses bounded by each of :data:`ERROR_PIXELS` in turn, as pixels of
    the mesh's bind height at its switch size ``switch_px[k - 1]``; the first whose
    :func:`departure` there is within ``budget_px`` is kept. A far level
    (:func:`~.levels.far_level`, named ``<mesh>.card``, then ``<mesh>.joined.card``,
    ``<mesh>.joined2.card``...) is tried with its small parts joined at each of
    :data:`JOIN_SHARES` in turn, and never heavier than the level before. A level
    none of whose tries passes is refused: the level before is used under its name,
    with a note. ``budget_px`` infinite: no check, the first (decimated) or last (far)
    try."""
    from .levels import decimated, far_level, far_levels_start, far_name
    lods = tuple(lods)
    first_card = far_levels_start(mesh, lods)
    height = max(float(np.ptp(mesh.positions[:, 2])), 1e-6)
    check = bool(np.isfinite(budget_px))
    levels, notes = [mesh], []
    for k, entry in enumerate(lods, start=1):
        px = float(switch_px[min(k - 1, len(switch_px) - 1)])
        far = k - 1 - first_card
        name = f"{mesh.name}.lod{k}" if far < 0 else far_name(mesh, far)
        if far >= 0:
            tries = [lambda j=j: far_level(mesh, levels[-1], j, name)
                     for j in (JOIN_SHARES if check else JOIN_SHARES[-1:])]
        else:
            tries = [lambda e=e: decimated(mesh, levels[-1], entry, e * height / px, name)
                     for e in (ERROR_PIXELS if check else ERROR_PIXELS[:1])]
        chosen, worst = None, np.inf
        for make in tries:
            level = make()
            same = level.triangle_count == levels[-1].triangle_count    # nothing collapsed
            d = departure(level, mesh, skeleton, poses, px) if check and not same else 0.0
            if d <= budget_px:
                chosen = level
                break
            worst = min(worst, d)
        if chosen is None:
            notes.append(f"LOD {k} {name!r} refused: its silhouette departs from the full "
                         f"mesh by {worst:.2f} px at {px:.0f} px tall (budget "
                         f"{budget_px:g} px); the level before is used")
            chosen = replace(levels[-1], name=name)
        levels.append(chosen)
    return levels, notes


def clip_poses(skeleton, clips, per_clip: int = 4, most: int = 16) -> np.ndarray:
    """``(n, B, 10)`` poses of ``skeleton`` to check levels over: its bind pose and
    ``per_clip`` evenly spaced keys of each clip that matches it (by bone names, or
    by bone count without them), at most ``most`` in all."""
    from ..base.errors import CrowdError
    bind = np.asarray(skeleton.bind_pose, np.float64)
    poses = [bind[None]]
    for clip in clips:
        try:
            order = clip.bone_order(skeleton)
        except CrowdError:
            continue
        keys = np.asarray(clip.keys, np.float64)
        if order is not None:
            keys = keys[:, order]
        pick = np.unique(np.linspace(0, keys.shape[0] - 1, per_clip).round().astype(int))
        poses.append(keys[pick])
    out = np.concatenate(poses)
    if out.shape[0] > most:
        out = out[np.unique(np.linspace(0, out.shape[0] - 1, most).round().astype(int))]
    return out
