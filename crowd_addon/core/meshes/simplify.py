"""Skinning-aware mesh simplification: the automatic LODs' decimation.

Half-edge collapses ordered by a quadric error (Garland and Heckbert's plane
quadrics, each vertex's accumulated over the triangles it has absorbed) plus a
skinning term: moving vertex ``u`` onto its neighbour ``v`` costs the squared distance
of ``v`` to ``u``'s planes and ``(SKIN_SPREAD * d * w)^2``, where ``d`` is the edge's
length and ``w`` half the L1 difference of the two vertices' bone weights. Removing a
ring where an elbow's weights blend so costs as much as the elbow would move when it
bends (a weight difference of 1 across 3 cm costs like 6 cm of surface), and a ring in
the middle of a forearm, where every vertex follows the same bone, costs only its
shape.

A collapse keeps ``v`` as it is (position, normal, influences): every vertex of a level
is a vertex of the full mesh with its own influences, so a level deforms like the full
mesh there. Borders keep their lines: a vertex on a material border or an open edge
moves only along it, costing its distance from the border's line (constraint planes
through each border edge), and one on a non-manifold edge or where borders meet is
never removed, so shirt and skin meet where they met. Creases (a flat part's rim, folded
back on itself) charge the same constraint planes without holding their vertices: its
triangles' planes coincide and leave a point free to slide within them, which would
let the flat part's ends slide inwards for nothing. A collapse is refused when it would
pinch the surface (the two vertices share neighbours beyond their common triangles) or
turn a triangle over.

:func:`simplify` returns the mesh after collapsing, cheapest first, until the next
collapse would take it below a triangle count or cost more than a given error: the
lightest level that stays within a size on screen (``CrowdConfig.add_mesh`` gives half a
pixel at the level's switch height, the silhouette check then judges the result).
Pure Python on the collapse queue: about 0.1 s for the 1,152-triangle fan.
"""

from __future__ import annotations

import heapq

import numpy as np

__all__ = ["simplify", "SKIN_SPREAD"]

#: how far (in edge lengths) a collapse across differing weights is taken to move
#: the surface when the joint bends (a weight difference of 1 moves a vertex about
#: twice the edge's length at a right angle)
SKIN_SPREAD = 2.0
#: an edge whose two triangles' normals part by more than this is a crease, whose line
#: a collapse is charged for leaving: a surface folded back on itself (a flat part's
#: rim, 180 degrees), where the triangles' own planes coincide and pin nothing; a box's
#: corners (90) are pinned by their three planes already, and charging the fan's caps
#: (90) and tube sides (45) made its 45 px level stray 2 px at 526 triangles where it
#: passed at 478
_CREASE_DEG = 120.0
#: a collapse must keep each remaining triangle's normal within ~70 degrees of its own
_FLIP_COS = 0.35


def _plane_quadrics(p, t):
    """(V, 4, 4) sums of the plane quadrics of each vertex's triangles (unweighted: a
    point's cost is the sum of its squared distances to the planes, at least the
    largest of them, so its square root bounds the distance in metres)."""
    n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    area = np.linalg.norm(n, axis=1)
    unit = n / np.maximum(area, 1e-20)[:, None]
    plane = np.c_[unit, -(unit * p[t[:, 0]]).sum(1)]
    q = (area > 1e-20)[:, None, None] * plane[:, :, None] * plane[:, None, :]
    out = np.zeros((p.shape[0], 4, 4))
    for k in range(3):
        np.add.at(out, t[:, k], q)
    return out


def _borders(mesh, p, t):
    """``(locked, border, quadrics)``: vertices never removed ((V,) bool: on a
    non-manifold edge, or where three or more border edges meet), the border edges
    (a set of sorted vertex pairs: open edges and edges between two materials) and
    the constraint quadrics (V, 4, 4) of the borders and of the creases (edges whose two
    triangles' normals part by more than :data:`_CREASE_DEG`, or one has no area: a
    flat part's rim, its two sides folded back on each other): for each such edge and each
    triangle on it, the plane through the edge perpendicular to the triangle, so a
    vertex moved off the line costs its distance from it (a flat arm's ends cannot
    slide inwards for free, as its one plane would let them)."""
    v = p.shape[0]
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    tri_of = np.tile(np.arange(t.shape[0]), 3)
    key = np.sort(edges, 1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    locked = np.zeros(v, bool)
    locked[key[counts[inverse] > 2].ravel()] = True
    on_border = counts[inverse] == 1
    face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    unit_face = face / np.maximum(np.linalg.norm(face, axis=1), 1e-20)[:, None]
    first = np.full(counts.size, -1)
    np.maximum.at(first, inverse, tri_of)          # one triangle of each edge...
    bend = np.full(counts.size, 1.0)
    np.minimum.at(bend, inverse, (unit_face[tri_of] * unit_face[first[inverse]]).sum(1))
    flat = np.zeros(counts.size, bool)             # beside a triangle of no area: a fold
    np.logical_or.at(flat, inverse, np.linalg.norm(face, axis=1)[tri_of] <= 1e-12)
    crease = (counts[inverse] == 2) & ((bend[inverse] < np.cos(np.radians(_CREASE_DEG)))
                                       | flat[inverse])
    if mesh.material is not None:
        mat = np.asarray(mesh.material, np.int64)[tri_of]
        lo = np.full(counts.size, np.iinfo(np.int64).max)
        hi = np.full(counts.size, -1)
        np.minimum.at(lo, inverse, mat)
        np.maximum.at(hi, inverse, mat)
        on_border |= (lo != hi)[inverse]
    border = {tuple(e) for e in key[on_border].tolist()}
    ends = np.zeros(v, np.int64)
    for a, b in border:
        ends[a] += 1
        ends[b] += 1
    locked |= ends > 2
    lines = on_border | crease
    e = edges[lines]
    side = np.cross(p[e[:, 1]] - p[e[:, 0]], face[tri_of[lines]])
    length = np.linalg.norm(side, axis=1)
    unit = side / np.maximum(length, 1e-20)[:, None]
    plane = np.c_[unit, -(unit * p[e[:, 0]]).sum(1)]
    q = (length > 1e-20)[:, None, None] * plane[:, :, None] * plane[:, None, :]
    quad = np.zeros((v, 4, 4))
    for k in range(2):
        np.add.at(quad, e[:, k], q)
    return locked, border, quad


def simplify(mesh, target_triangles: int, max_error: float = np.inf, name: str | None = None):
    """``mesh`` (a :class:`~.mesh.ProxyMesh`) with half-edge collapses applied, cheapest
    first (see the module docstring), until the next would take it below
    ``target_triangles`` triangles or cost more than ``max_error`` (metres, the square
    root of the cost); named ``name``. The mesh itself when nothing collapses."""
    from .mesh import ProxyMesh

    p = mesh.positions.astype(np.float64)
    t = mesh.triangles.astype(np.int64)
    nv = p.shape[0]
    quad = _plane_quadrics(p, t)
    locked, border, border_quad = _borders(mesh, p, t)
    quad += border_quad
    on_border = np.zeros(nv, bool)
    on_border[[x for e in border for x in e]] = True
    w = np.zeros((nv, int(mesh.bone_indices.max()) + 1))
    np.add.at(w, (np.repeat(np.arange(nv), mesh.bone_indices.shape[1]),
                  mesh.bone_indices.astype(np.int64).ravel()),
              mesh.bone_weights.astype(np.float64).ravel())
    tris = [list(row) for row in t.tolist()]
    alive_tri = [True] * len(tris)
    vert_tris = [set() for _ in range(nv)]
    for k, row in enumerate(tris):
        for a in row:
            vert_tris[a].add(k)
    alive = [True] * nv
    stamp = [0] * nv
    limit = float(max_error) ** 2 if np.isfinite(max_error) else np.inf

    def neighbours(a):
        out = set()
        for k in vert_tris[a]:
            out.update(tris[k])
        out.discard(a)
        return out

    def cost(u, v):
        h = np.append(p[v], 1.0)
        geo = float(h @ (quad[u] + quad[v]) @ h)
        spread = SKIN_SPREAD * 0.5 * float(np.abs(w[u] - w[v]).sum()) \
            * float(np.linalg.norm(p[u] - p[v]))
        return max(geo, 0.0) + spread * spread

    def push(u):
        if locked[u] or not alive[u]:
            return
        for v in neighbours(u):
            heapq.heappush(heap, (cost(u, v), u, v, stamp[u], stamp[v]))

    def valid(u, v) -> bool:
        if on_border[u] and (min(u, v), max(u, v)) not in border:
            return False                                # a border vertex moves along it
        shared = vert_tris[u] & vert_tris[v]
        third = set()
        for k in shared:
            third.update(tris[k])
        third -= {u, v}
        if neighbours(u) & neighbours(v) != third:       # would pinch the surface
            return False
        for k in vert_tris[u] - shared:
            a, b, c = (p[x] for x in tris[k])
            old = np.cross(b - a, c - a)
            a2, b2, c2 = (p[v if x == u else x] for x in tris[k])
            new = np.cross(b2 - a2, c2 - a2)
            na, nb = np.linalg.norm(old), np.linalg.norm(new)
            if nb <= 1e-12 * max(na, 1e-12) or float(old @ new) < _FLIP_COS * na * nb:
                return False
        return True

    heap = []
    for u in range(nv):
        push(u)
    count = len(tris)
    while heap and count - 2 >= target_triangles:
        c, u, v, su, sv = heapq.heappop(heap)
        if not (alive[u] and alive[v]) or su != stamp[u] or sv != stamp[v]:
            continue
        if c > limit:
            break
        if not valid(u, v):
            continue
        shared = vert_tris[u] & vert_tris[v]
        for k in shared:
            alive_tri[k] = False
            for x in tris[k]:
                if x != u:
                    vert_tris[x].discard(k)
        count -= len(shared)
        for k in vert_tris[u] - shared:
            tris[k] = [v if x == u else x for x in tris[k]]
            vert_tris[v].add(k)
        vert_tris[u] = set()
        alive[u] = False
        if on_border[u]:                                # its border edges now end at v
            for e in [e for e in border if u in e]:
                border.discard(e)
                x = e[0] if e[1] == u else e[1]
                if x != v:
                    border.add((min(x, v), max(x, v)))
        quad[v] += quad[u]
        ring = neighbours(v)
        for x in ring | {v}:
            stamp[x] += 1
        for x in ring | {v}:
            push(x)
    kept = np.flatnonzero(alive_tri)
    if kept.size == len(tris):
        return mesh
    tri = np.array([tris[k] for k in kept], np.int64)
    used = np.unique(tri)
    remap = np.full(nv, -1, np.int64)
    remap[used] = np.arange(used.size)
    return ProxyMesh(name or mesh.name, mesh.skeleton, mesh.positions[used], remap[tri],
                     mesh.bone_indices[used], mesh.bone_weights[used], mesh.normals[used],
                     mesh.bone_count, **mesh.looks_of(kept))
