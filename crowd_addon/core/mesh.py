"""Proxy meshes: the skinned character mesh an agent is drawn with, and its LODs.

A :class:`ProxyMesh` is plain arrays (float32 positions and normals in the bind
pose, in the skeleton's armature space; ``uint32`` triangles; per vertex up to
eight bone influences with weights that sum to 1, stored four wide, or eight wide
for a mesh where some vertex has more than four), the form both GPU backends and the
USD writer consume. :func:`build_lods` makes cheaper versions for far
agents by half-edge collapses (:mod:`.simplify`) that keep the mesh's own vertices
(and so their influences exactly), so an LOD deforms like the full mesh. A mesh may
carry how it looks: texture coordinates per triangle corner and a :class:`Look` (material) per
triangle, which LODs keep for the triangles they keep.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .errors import CrowdError

__all__ = ["ProxyMesh", "Look", "tint_weight", "tinted", "vertex_normals", "build_lods",
           "INFLUENCES", "MAX_INFLUENCES"]

#: Influence columns of a mesh whose vertices have at most four bones (the GPU vertex
#: format's first ``uvec4``/``vec4`` pair).
INFLUENCES = 4
#: Most influences a vertex keeps: meshes with a vertex of five to eight bones store
#: eight columns (a second attribute pair on the GPU); past eight, the strongest eight.
MAX_INFLUENCES = 8
_WIDTHS = (INFLUENCES, MAX_INFLUENCES)


@dataclass(frozen=True)
class Look:
    """A material of a proxy mesh as exports draw it: ``name``, ``color`` the base
    colour (r, g, b, a) in 0..1 (linear), and ``texture`` an image file for the base
    colour (``""`` for none), read through the mesh's texture coordinates."""

    name: str
    color: tuple = (0.8, 0.8, 0.8, 1.0)
    texture: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise CrowdError(f"look {self.name!r}: a name is needed")
        try:
            color = tuple(float(c) for c in self.color)
        except (TypeError, ValueError):
            raise CrowdError(f"look {self.name!r}: color must be 4 numbers (r, g, b, a), "
                             f"got {self.color!r}") from None
        if len(color) != 4 or not all(np.isfinite(color)) or min(color) < 0 or max(color) > 1:
            raise CrowdError(f"look {self.name!r}: color must be 4 numbers in 0..1 "
                             f"(r, g, b, a), got {self.color!r}")
        if not isinstance(self.texture, str):
            raise CrowdError(f"look {self.name!r}: texture must be a file path or \"\", "
                             f"got {self.texture!r}")
        object.__setattr__(self, "color", color)


def tint_weight(base) -> np.ndarray:
    """How much an agent's colour tints a material of linear colour ``base`` (..., 3):
    ``clamp(1 - 4 * saturation)``, saturation as HSV's (``(max - min) / max``): grey
    and white take the tint fully, saturation 0.25 and above (skin, dyed cloth) not at
    all. The GPU preview's rule (``agent_tint`` in gpu_shaders/crowd_vertex.glsl), which
    Render Crowd's materials and the USD export follow too."""
    base = np.asarray(base, np.float64)
    high, low = base.max(-1), base.min(-1)
    return np.clip(1.0 - 4.0 * (high - low) / np.maximum(high, 1e-4), 0.0, 1.0)


def tinted(base, tint) -> np.ndarray:
    """Material colour ``base`` (3,) tinted by agents' colours ``tint`` (..., 3):
    ``mix(base, base * tint, tint_weight(base))``."""
    base = np.asarray(base, np.float64)[:3]
    w = tint_weight(base)
    return base * (1.0 - w) + base * np.asarray(tint, np.float64) * w


@dataclass(frozen=True, eq=False)
class ProxyMesh:
    """A skinned triangle mesh bound to one skeleton (validated on construction).

    Parameters
    ----------
    name : str
    skeleton : the skeleton's name.
    positions : (V, 3) float32 bind-pose positions (metres, armature space).
    triangles : (T, 3) uint32 vertex indices.
    bone_indices : (V, K) uint16 bone index per influence (0 where unused), K = 4 or
        8 (:data:`INFLUENCES`, :data:`MAX_INFLUENCES`); eight columns whose last four
        weigh 0 everywhere are stored as four.
    bone_weights : (V, K) float32 weights, descending, summing to 1.
    normals : (V, 3) float32 unit normals; computed from the triangles when None.
    bone_count : bones of the skeleton, to validate ``bone_indices`` (None: unchecked).
    notes : remarks for the user about how the mesh was made (``from_influences``
        names the vertices that had more than eight influences), like
        ``BakeResult.notes``.
    uvs : (T, 3, 2) float32 texture coordinates of each triangle's corners, or None.
    material : (T,) uint16 index into ``looks`` per triangle, or None (all the first).
    looks : the mesh's :class:`Look` s (empty: no material).

    Build from any number of influences per vertex with :meth:`from_influences`.
    """

    name: str
    skeleton: str
    positions: np.ndarray
    triangles: np.ndarray
    bone_indices: np.ndarray
    bone_weights: np.ndarray
    normals: np.ndarray = None
    bone_count: int | None = None
    notes: tuple = ()
    uvs: np.ndarray = None
    material: np.ndarray = None
    looks: tuple = ()

    def __post_init__(self):
        what = f"mesh {self.name!r}"
        pos = np.ascontiguousarray(self.positions, np.float32)
        if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
            raise CrowdError(f"{what}: positions must be (V, 3) with V >= 1, got "
                             f"{np.shape(self.positions)}")
        v = pos.shape[0]
        _finite(pos, what, "positions")
        tri = np.asarray(self.triangles)
        if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] == 0:
            raise CrowdError(f"{what}: triangles must be (T, 3) with T >= 1, got {tri.shape}")
        if not np.issubdtype(tri.dtype, np.integer):
            raise CrowdError(f"{what}: triangles must be integers, got {tri.dtype}")
        if tri.min() < 0 or tri.max() >= v:
            bad = int(np.argmax((tri < 0).any(1) | (tri >= v).any(1)))
            raise CrowdError(f"{what}: triangle {bad} {tri[bad].tolist()} refers to a vertex "
                             f"outside 0..{v - 1}")
        idx = np.asarray(self.bone_indices)
        w = np.ascontiguousarray(self.bone_weights, np.float32)
        if idx.shape != w.shape or idx.shape not in ((v, k) for k in _WIDTHS):
            raise CrowdError(f"{what}: bone_indices and bone_weights must be ({v}, 4) or "
                             f"({v}, 8), got {idx.shape} and {w.shape} (use "
                             "ProxyMesh.from_influences)")
        _finite(w, what, "bone_weights")
        if w.shape[1] > INFLUENCES and not w[:, INFLUENCES:].any():
            idx, w = idx[:, :INFLUENCES], np.ascontiguousarray(w[:, :INFLUENCES])
        if idx.min() < 0 or (self.bone_count is not None and idx.max() >= self.bone_count):
            bad = int(np.argmax((idx < 0).any(1) | (idx >= (self.bone_count or 1 << 30)).any(1)))
            raise CrowdError(f"{what}: vertex {bad} uses bone index {idx[bad].tolist()}, "
                             f"outside 0..{(self.bone_count or 0) - 1}")
        sums = w.sum(1)
        if (w < 0).any() or not np.allclose(sums, 1.0, atol=1e-4):
            bad = int(np.argmax((w < 0).any(1) | ~np.isclose(sums, 1.0, atol=1e-4)))
            raise CrowdError(f"{what}: vertex {bad} has weights {w[bad].tolist()}; weights "
                             "must be >= 0 and sum to 1 (use ProxyMesh.from_influences)")
        normals = vertex_normals(pos, tri) if self.normals is None else \
            np.ascontiguousarray(self.normals, np.float32)
        if normals.shape != pos.shape:
            raise CrowdError(f"{what}: normals must be {pos.shape}, got {normals.shape}")
        _finite(normals, what, "normals")
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "triangles", np.ascontiguousarray(tri, np.uint32))
        object.__setattr__(self, "bone_indices", np.ascontiguousarray(idx, np.uint16))
        object.__setattr__(self, "bone_weights", w)
        object.__setattr__(self, "normals", normals)
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        self._check_looks(what, tri.shape[0])

    def _check_looks(self, what, t):
        looks = tuple(self.looks)
        if not all(isinstance(k, Look) for k in looks):
            raise CrowdError(f"{what}: looks must be Look objects, got {looks!r}")
        names = [k.name for k in looks]
        if len(set(names)) != len(names):
            raise CrowdError(f"{what}: two looks are named the same ({names})")
        if self.uvs is not None:
            uvs = np.ascontiguousarray(self.uvs, np.float32)
            if uvs.shape != (t, 3, 2):
                raise CrowdError(f"{what}: uvs must be ({t}, 3, 2) (per triangle corner), "
                                 f"got {uvs.shape}")
            if not np.isfinite(uvs).all():
                bad = int(np.argmax(~np.isfinite(uvs).reshape(t, -1).all(1)))
                raise CrowdError(f"{what}: uvs of triangle {bad} are not finite")
            object.__setattr__(self, "uvs", uvs)
        if self.material is not None:
            mat = np.asarray(self.material)
            if mat.shape != (t,) or not np.issubdtype(mat.dtype, np.integer):
                raise CrowdError(f"{what}: material must be ({t},) integers (a look per "
                                 f"triangle), got {mat.dtype} {mat.shape}")
            if mat.size and (mat.min() < 0 or mat.max() >= max(len(looks), 1)):
                bad = int(np.argmax((mat < 0) | (mat >= len(looks))))
                raise CrowdError(f"{what}: triangle {bad} uses look {int(mat[bad])}, but the "
                                 f"mesh has {len(looks)} look(s)")
            object.__setattr__(self, "material", np.ascontiguousarray(mat, np.uint16))
        object.__setattr__(self, "looks", looks)

    def looks_of(self, triangles) -> dict:
        """What a mesh made of ``triangles`` (indices of this mesh's) keeps of how it
        looks: ``uvs``, ``material`` and ``looks`` keyword arguments for ProxyMesh."""
        return {"uvs": None if self.uvs is None else self.uvs[triangles],
                "material": None if self.material is None else self.material[triangles],
                "looks": self.looks}

    @property
    def vertex_count(self) -> int:
        return int(self.positions.shape[0])

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])

    @property
    def extent(self) -> np.ndarray:
        """(2, 3) float32 bind-pose bounding box (min, max)."""
        return np.stack([self.positions.min(0), self.positions.max(0)])

    @property
    def influences(self) -> int:
        """Influence columns: 4, or 8 when some vertex has five to eight bones."""
        return int(self.bone_indices.shape[1])

    @classmethod
    def from_influences(cls, name, skeleton, positions, triangles, indices, weights,
                        normals=None, bone_count=None, **looks) -> "ProxyMesh":
        """Keep each vertex's influences (its eight strongest) renormalised to sum 1.

        ``indices``/``weights`` are (V, K) for any K (pad unused entries with weight 0).
        The mesh stores four columns when no vertex has more than four influences of
        positive weight, else eight. Vertices with more than eight keep their eight
        strongest: :attr:`notes` then says how many (the mesh deforms slightly
        differently from a skinning that blends them all, as Blender's does). A vertex
        with no positive weight is an error naming it: a skinned crowd has no sensible
        place for it (Blender would leave it at the object origin's rest). ``looks``:
        the ``uvs``, ``material`` and ``looks`` fields.
        """
        idx = np.asarray(indices, np.int64)
        w = np.asarray(weights, np.float64)
        if idx.ndim != 2 or idx.shape != w.shape:
            raise CrowdError(f"mesh {name!r}: indices and weights must both be (V, K), got "
                             f"{idx.shape} and {w.shape}")
        _finite(w, f"mesh {name!r}", "weights")
        if (w < 0).any():
            bad = int(np.argmax((w < 0).any(1)))
            raise CrowdError(f"mesh {name!r}: vertex {bad} has a negative weight")
        used = (w > 0).sum(1)
        most = int(used.max()) if used.size else 0
        width = INFLUENCES if most <= INFLUENCES else MAX_INFLUENCES
        notes = ()
        if most > MAX_INFLUENCES:
            cut = int((used > MAX_INFLUENCES).sum())
            notes = (f"mesh {name!r}: {cut} of {used.size} vertices have more than "
                     f"{MAX_INFLUENCES} bone influences (up to {most}); each keeps its "
                     f"{MAX_INFLUENCES} strongest, renormalised, so they deform slightly "
                     "differently",)
        if idx.shape[1] < width:
            pad = width - idx.shape[1]
            idx = np.pad(idx, ((0, 0), (0, pad)))
            w = np.pad(w, ((0, 0), (0, pad)))
        order = np.argsort(-w, axis=1, kind="stable")[:, :width]
        top_w = np.take_along_axis(w, order, 1)
        top_i = np.take_along_axis(idx, order, 1)
        total = top_w.sum(1)
        if (total <= 0).any():
            bad = np.flatnonzero(total <= 0)
            raise CrowdError(f"mesh {name!r}: {bad.size} vertices have no bone weight "
                             f"(first: vertex {int(bad[0])}); weight every vertex to a bone")
        top_w /= total[:, None]
        top_i = np.where(top_w > 0, top_i, 0)
        return cls(name, skeleton, positions, triangles, top_i, top_w.astype(np.float32),
                   normals, bone_count, notes, **looks)


def _finite(a, what, field):
    if not np.isfinite(a).all():
        bad = int(np.argmax(~np.isfinite(a).reshape(a.shape[0], -1).all(1)))
        raise CrowdError(f"{what}: {field} of vertex {bad} is not finite")


def vertex_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(V, 3) float32 area-weighted unit vertex normals (+Z where a vertex has none)."""
    p = np.asarray(positions, np.float64)
    t = np.asarray(triangles, np.int64)
    face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, t[:, k], face)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 1e-12, n / np.maximum(length, 1e-12), (0.0, 0.0, 1.0))
    return n.astype(np.float32)


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

