"""A proxy mesh's levels of detail: the decimated levels (:mod:`.simplify`), the far
levels (a box per body part, then with small parts joined) and the card, made from a
:class:`~.mesh.ProxyMesh`. :func:`.lod_check.fit_levels` makes a configuration's
levels with these and checks each; :mod:`.lod` says which one an agent is drawn with.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..base.errors import CrowdError
from .mesh import ProxyMesh

__all__ = ["CARD", "MIN_LOD_TRIANGLES", "build_lods", "decimated", "far_level",
           "far_levels_start", "far_name", "card_lod", "parts_lod", "BOX_SCALE"]

#: Automatic LODs keep at least this many triangles: a body is not decimated below a
#: shape that still reads as one (a 72-triangle body once became a 4-triangle
#: tetrahedron), and a body already this light keeps its triangles at every level.
MIN_LOD_TRIANGLES = 32

CARD = "card"
"""A ``build_lods`` / ``CrowdConfig.add_mesh`` level: the :func:`card_lod` of the mesh."""


def build_lods(mesh: ProxyMesh, ratios=(0.25, 0.06)) -> list:
    """``[mesh, lod1, lod2, ...]`` unchecked: each LOD keeps about ``ratio`` of the
    triangles; each :data:`CARD` entry (last only) adds the far level,
    :func:`parts_lod`. (``CrowdConfig.add_mesh`` makes its levels with
    :func:`.lod_check.fit_levels`, which checks each at its switch size.)

    Each level is the level before simplified by skinning-aware half-edge collapses
    (:func:`.simplify.simplify`: cheapest first by plane distance plus how far a
    collapse across differing bone weights moves when the joint bends; material
    borders kept) down to ``ratio`` of the mesh's triangles. Every vertex of a level is
    a vertex of the mesh with its own position, normal and influences (all of them: a
    mesh stored eight wide gives eight-wide LODs), so a level deforms like the mesh.
    LODs never have more triangles than the level before, nor fewer than
    :data:`MIN_LOD_TRIANGLES`: a level whose target is below it aims at it, and where
    nothing can be collapsed the level is a copy of the level before (named as its own
    level).
    """
    first = far_levels_start(mesh, ratios)
    lods = [mesh]
    for k, ratio in enumerate(ratios, start=1):
        if k - 1 >= first:
            lods.append(far_level(mesh, lods[-1], name=far_name(mesh, k - 1 - first)))
        else:
            lods.append(decimated(mesh, lods[-1], ratio, np.inf, f"{mesh.name}.lod{k}"))
    return lods


def far_levels_start(mesh: ProxyMesh, lods) -> int:
    """The index of the first :data:`CARD` entry of ``lods`` (its length when none);
    raises CrowdError naming an entry that is neither a ratio nor a far level last."""
    lods = tuple(lods)
    first = next((k for k, e in enumerate(lods) if isinstance(e, str)), len(lods))
    for k, entry in enumerate(lods):
        if (isinstance(entry, str) and entry != CARD) or \
                (k > first and not isinstance(entry, str)):
            raise CrowdError(f"mesh {mesh.name!r}: LOD {entry!r} must be a triangle ratio "
                             f"in (0, 1) or {CARD!r} (the far levels, last)")
    return first


def far_name(mesh: ProxyMesh, far: int) -> str:
    """The name of ``mesh``'s far level ``far`` (0: ``<mesh>.card``, then
    ``<mesh>.joined.card``, ``<mesh>.joined2.card``...)."""
    if far == 0:
        return f"{mesh.name}.{CARD}"
    return f"{mesh.name}.joined{far if far > 1 else ''}.{CARD}"


def decimated(mesh: ProxyMesh, prev: ProxyMesh, ratio, max_error: float, name: str):
    """The level after ``prev`` keeping about ``ratio`` of ``mesh``'s triangles (at least
    :data:`MIN_LOD_TRIANGLES`), collapses costing at most ``max_error`` metres; a copy
    of ``prev`` named ``name`` where nothing collapses."""
    from .simplify import simplify
    if not 0 < ratio < 1:
        raise CrowdError(f"mesh {mesh.name!r}: LOD ratio {ratio} must be in (0, 1)")
    target = max(MIN_LOD_TRIANGLES, int(round(mesh.triangle_count * ratio)))
    if prev.triangle_count <= target:     # light enough already: keep its triangles
        return replace(prev, name=name)
    return replace(simplify(prev, target, max_error, name), name=name)


def far_level(mesh: ProxyMesh, prev: ProxyMesh, join_share: float = 0.0,
              name: str | None = None) -> ProxyMesh:
    """A :data:`CARD` level of ``mesh`` after ``prev``: :func:`parts_lod` with parts
    under ``join_share`` joined to a neighbour, or ``prev`` renamed where that is no
    lighter (a light body); named ``name`` (default ``<mesh>.card``)."""
    name = name or f"{mesh.name}.{CARD}"
    card = parts_lod(mesh, name, join_share=join_share)
    if card.triangle_count >= prev.triangle_count:
        card = replace(prev, name=name)
    return card


def card_lod(mesh: ProxyMesh, name: str | None = None) -> ProxyMesh:
    """The farthest LOD: two crossed vertical quads (8 vertices, 4 triangles, one bone a
    vertex), what a character a dozen pixels tall needs.

    The quads stand on the mesh's vertical axis (median x, y of the bind pose; armature
    space is Z up) from its lowest to its highest point. Each is as wide as keeps the
    mesh's silhouette area seen across it (half the summed |projected triangle areas|,
    a closed mesh showing each point twice), so a card covers about the pixels the
    body would. The lower corners follow bone 0, the skeleton's root (bones are stored
    parents first): the ground under the agent for a rig with a root bone, the hips
    for a mocap skeleton. The upper corners follow the bone that weighs most in the
    highest tenth of the height (the head). So the card turns, walks and sits down
    with the body, and with one influence a vertex the shader fetches three texels
    for it, not twelve: a quarter less time for a 65k-agent frame of cards.
    """
    p = mesh.positions.astype(np.float64)
    cx, cy = np.median(p[:, 0]), np.median(p[:, 1])
    z0, z1 = float(p[:, 2].min()), float(p[:, 2].max())
    height = max(z1 - z0, 1e-3)
    t = mesh.triangles.astype(np.int64)
    twice = np.abs(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])).sum(0)
    hx, hy = (max(twice[k] / 4 / (2 * height), 0.02 * height) for k in (1, 0))
    pos = np.array([[cx - hx, cy, z0], [cx + hx, cy, z0], [cx + hx, cy, z1], [cx - hx, cy, z1],
                    [cx, cy - hy, z0], [cx, cy + hy, z0], [cx, cy + hy, z1], [cx, cy - hy, z1]])
    top = p[:, 2] >= z1 - 0.1 * height
    head = int(np.argmax(np.bincount(mesh.bone_indices[top].ravel(),
                                     mesh.bone_weights[top].ravel())))
    bones = np.where(pos[:, 2] > z0, head, 0)[:, None]
    look = {}
    if mesh.looks:   # the look covering most of the upper half: torso and head, what a
        # far agent shows (over the seat in front, too)
        area = np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
        area = area * (p[t].mean(1)[:, 2] > (z0 + z1) / 2)
        mat = np.zeros(t.shape[0], np.int64) if mesh.material is None else mesh.material
        main = int(np.argmax(np.bincount(mat, area, len(mesh.looks))))
        look = {"material": np.full(4, main), "looks": mesh.looks}
    return ProxyMesh.from_influences(
        name or f"{mesh.name}.card", mesh.skeleton, pos,
        np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]), bones, np.ones((8, 1)),
        None, mesh.bone_count, **look)


#: a part's box is this share of the part's extent along each of its principal axes:
#: a box as large as the part's bounding box sticks out at its corners (a round limb
#: seen across its diagonal), by up to 4 px on a 30 px tall fan; at 0.85 the fans'
#: boxes stay within the silhouette check's pixel at 18-40 px
BOX_SCALE = 0.85

# a box's corners (s0, s1, s2) in {-1, 1}^3 are numbered 4 (s0 > 0) + 2 (s1 > 0) + (s2 > 0)
_BOX_CORNERS = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)]) * 2 - 1
_BOX_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                       [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def parts_lod(mesh: ProxyMesh, name: str | None = None, min_share: float = 0.004,
              join_share: float = 0.0) -> ProxyMesh:
    """The farthest LOD: a box per body part (8 vertices, 12 triangles) for each bone
    that carries a share of at least ``min_share`` of the mesh's surface, in the look
    covering most of that part.

    A part is the triangles whose first vertex's strongest bone is that bone. Its box
    stands along the part's principal axes (bind pose), :data:`BOX_SCALE` of the
    part's extent along each. Each corner takes the influences of the part's vertex
    nearest to it (so the boxes of a bent elbow stay joined, as the mesh's blended
    joint does), and a normal leaning out of the corner equally along the box's three
    edges (smoothly interpolated over the faces): lit like a rounded part (its top brighter, its underside darker), where the
    former crossed quads (flat, shaded by whichever side faced the camera) drew the
    far crowd 0.026 darker than the full meshes did. A box is closed and faces out,
    so the renderer culls its back faces. So a far agent keeps its colours (shirt,
    skin, hair, trousers: the agent's palette and tint reach each part's look), its
    pose (its arms follow the arms) and its shading. A mesh with no part above the
    share falls back to :func:`card_lod`. ``join_share``: a part carrying less than that
    share is first joined to the neighbouring part it shares most vertices with,
    smallest first (a toe to its foot, a hand to its forearm): fewer, longer boxes for
    agents a dozen pixels tall (:func:`.lod_check.fit_levels` tries them).
    """
    p = mesh.positions.astype(np.float64)
    t = mesh.triangles.astype(np.int64)
    area = 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]),
                                axis=1)
    bone = _joined_parts(t, mesh.bone_indices[t[:, 0], 0].astype(np.int64), area, join_share)
    share = np.bincount(bone, area) / max(area.sum(), 1e-12)
    mat = np.zeros(t.shape[0], np.int64) if mesh.material is None else \
        mesh.material.astype(np.int64)
    pos, normals, idx, wts, tris, looks = [], [], [], [], [], []
    for b in np.flatnonzero(share >= min_share):
        verts = np.unique(t[bone == b])
        v = p[verts]
        centre = v.mean(0)
        axes = np.linalg.svd(v - centre, full_matrices=False)[2]       # rows: principal axes
        if axes.shape[0] < 3:                                           # a single vertex
            continue
        proj = (v - centre) @ axes.T
        lo, hi = proj.min(0), proj.max(0)
        mid = centre + ((lo + hi) / 2) @ axes
        half = np.maximum(BOX_SCALE * (hi - lo) / 2, 1e-3)
        corners = mid + (_BOX_CORNERS * half) @ axes
        out = _BOX_CORNERS @ axes
        faces = _BOX_FACES.copy()
        a, c, d = (corners[faces[:, k]] for k in range(3))
        inward = (np.cross(c - a, d - a) * ((a + c + d) / 3 - mid)).sum(1) < 0
        faces[inward] = faces[inward][:, ::-1]
        near = verts[np.argmin(((corners[:, None] - v[None]) ** 2).sum(2), 1)]
        tris.append(faces + 8 * len(pos))
        pos.append(corners)
        normals.append(out / np.linalg.norm(out, axis=1, keepdims=True))
        idx.append(mesh.bone_indices[near])
        wts.append(mesh.bone_weights[near])
        looks.append(int(np.argmax(np.bincount(mat[bone == b], area[bone == b]))))
    if not pos:
        return card_lod(mesh, name)
    look = {"material": np.repeat(looks, len(_BOX_FACES)), "looks": mesh.looks} \
        if mesh.looks else {}
    return ProxyMesh.from_influences(
        name or f"{mesh.name}.{CARD}", mesh.skeleton, np.concatenate(pos),
        np.concatenate(tris), np.concatenate(idx), np.concatenate(wts),
        np.concatenate(normals), mesh.bone_count, **look)


def _joined_parts(t, part, area, join_share: float) -> np.ndarray:
    """``part`` (T,) with every part carrying less than ``join_share`` of the surface
    joined to the neighbouring part with most triangles on its vertices, smallest first,
    until none is left that small (or with a neighbour)."""
    part = part.copy()
    if join_share <= 0:
        return part
    total = max(float(area.sum()), 1e-12)
    while True:
        share = np.bincount(part, area) / total
        present = np.unique(part)
        for b in present[np.argsort(share[present])].tolist():
            if share[b] >= join_share:
                return part
            touching = np.isin(t, np.unique(t[part == b])).any(1) & (part != b)
            if touching.any():
                part[part == b] = int(np.argmax(np.bincount(part[touching])))
                break
        else:
            return part

