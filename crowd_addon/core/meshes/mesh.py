"""Proxy meshes: the skinned character mesh an agent is drawn with, and its LODs.

A :class:`ProxyMesh` is plain arrays (float32 positions and normals in the bind
pose, in the skeleton's armature space; ``uint32`` triangles; per vertex up to
eight bone influences with weights that sum to 1, stored four wide, or eight wide
for a mesh where some vertex has more than four), the form both GPU backends and the
USD writer consume; :mod:`.levels` makes its cheaper versions for far agents. A mesh
may carry how it looks: texture coordinates per triangle corner and a :class:`Look` (material) per
triangle, which LODs keep for the triangles they keep.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError

__all__ = ["ProxyMesh", "Look", "tint_weight", "tinted", "vertex_normals",
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
