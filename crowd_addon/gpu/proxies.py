"""Proxy meshes as vertex arrays for the skinning program's inputs.

A core :class:`~crowd_addon.core.meshes.mesh.ProxyMesh` becomes one
:class:`ProxyBuffers` per LOD: named attribute arrays matching the ``vertex_in``
names of :data:`~.programs.CROWD_DRAW` (``pos``, ``nor`` float32 ``(V, 3)``,
``bone_idx`` uint16 ``(V, 4)``, ``bone_w`` float32 ``(V, 4)``, ``col`` uint8 ``(V,
4)``: the base colour of the vertex's material, and in alpha the agent palette
column that colours that material (255: none; the form Blender's
``GPUVertBuf.attr_fill`` takes), ``look_depth`` uint32 ``(V,)``: its influences'
look chain depths, packed (:func:`look_depths`), an interleaved copy for moderngl,
and uint32 triangle indices. A mesh stored eight influences wide (some vertex has five to
eight bones) adds ``bone_idx2``/``bone_w2``, influences 5..8, declared by the
program only then (:func:`~.programs.for_influences`); four-wide meshes keep a
56-byte vertex.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.base.errors import CrowdError

__all__ = ["ProxyBuffers", "proxy_buffers", "vertex_colors", "crowd_proxies", "look_depths",
           "copies_per_instance",
           "INTERLEAVED_FORMAT", "WIDE_FORMAT"]

#: (attribute, moderngl format, bytes) of :meth:`ProxyBuffers.interleaved`, in order:
#: meshes of up to four influences a vertex (56 bytes a vertex) ...
INTERLEAVED_FORMAT = (("pos", "3f", 12), ("nor", "3f", 12), ("bone_idx", "4u2", 8),
                      ("bone_w", "4f", 16), ("col", "4f1", 4), ("look_depth", "u4", 4))
#: ... and of five to eight (influences 5..8 after them: 80 bytes a vertex).
WIDE_FORMAT = INTERLEAVED_FORMAT + (("bone_idx2", "4u2", 8), ("bone_w2", "4f", 16))
_NUMPY = {"3f": ("<f4", (3,)), "4u2": ("<u2", (4,)), "4f": ("<f4", (4,)),
          "4f1": ("u1", (4,)), "u4": ("<u4", ())}


def copies_per_instance(vertex_count: int, target: int = 1024, limit: int = 64) -> int:
    """Mesh copies one instance draws (``gpu_shaders/crowd_vert.glsl``): enough that
    an instance has about ``target`` vertices, at most ``limit``, at least 1."""
    return int(np.clip(target // max(1, vertex_count), 1, limit))


@dataclass(frozen=True, eq=False)
class ProxyBuffers:
    """Vertex and index arrays of one proxy mesh level."""

    name: str
    attributes: dict
    indices: np.ndarray

    @property
    def vertex_count(self) -> int:
        return int(self.attributes["pos"].shape[0])

    @property
    def index_count(self) -> int:
        return int(self.indices.size)

    @property
    def extent(self) -> np.ndarray:
        """(2, 3) float32 bind-pose bounding box (min, max) in metres."""
        p = self.attributes["pos"]
        return np.stack([p.min(0), p.max(0)])

    @property
    def format(self) -> tuple:
        """:data:`INTERLEAVED_FORMAT`, or :data:`WIDE_FORMAT` with eight influences."""
        return WIDE_FORMAT if "bone_w2" in self.attributes else INTERLEAVED_FORMAT

    @property
    def influences(self) -> int:
        """Influences the shader blends (1..8), its ``INFLUENCES``: up to the last
        column of positive weight of any vertex (weights are stored strongest first,
        so this is the most bones a vertex uses)."""
        w = self.attributes["bone_w"]
        if "bone_w2" in self.attributes:
            w = np.concatenate([w, self.attributes["bone_w2"]], 1)
        used = np.flatnonzero((w > 0).any(0))
        return int(used[-1]) + 1 if used.size else 1

    @property
    def closed(self) -> bool:
        """Whether the surface is closed and faces outwards, so its back faces are
        never seen and a draw may cull them (llvmpipe then skips rasterising half the
        triangles): every edge between welded positions (seams split vertices) is run
        once each way by the triangles, and the enclosed volume is positive
        (counter-clockwise front faces). A card, a flag or any open part: False.
        Non-manifold edges (a vertex-clustered level folds in places: four triangles
        on an edge) are allowed: with no border there is no hole to see a back face
        through; culling them changes no pixel of the 65k stadium's frames."""
        tri = np.asarray(self.indices, np.int64).reshape(-1, 3)
        if tri.shape[0] < 4:
            return False
        pos = np.asarray(self.attributes["pos"], np.float64)
        _, weld = np.unique(np.round(pos, 6), axis=0, return_inverse=True)
        t = weld.reshape(-1)[tri]
        keep = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
        tri, t = tri[keep], t[keep]                 # collapsed triangles draw nothing
        n = int(weld.max()) + 1
        edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        code = edges[:, 0] * n + edges[:, 1]
        back = edges[:, 1] * n + edges[:, 0]
        if not np.isin(back, code).all():           # a border: the inside shows
            return False
        a, b, c = (pos[tri[:, k]] for k in range(3))
        return float(np.einsum("ij,ij->", a, np.cross(b, c))) > 0.0

    def batched(self, copies: int) -> "ProxyBuffers":
        """``copies`` back-to-back copies of this mesh in one set of arrays (copy ``k``'s
        vertices at ``k * V``), for drawing several agents per instance."""
        attrs = {k: np.ascontiguousarray(np.tile(v, (copies,) + (1,) * (v.ndim - 1)))
                 for k, v in self.attributes.items()}
        offsets = (np.arange(copies, dtype=np.int64) * self.vertex_count)[:, None]
        indices = (self.indices[None].astype(np.int64) + offsets).astype(np.uint32).reshape(-1)
        return ProxyBuffers(self.name, attrs, indices)

    def interleaved(self) -> np.ndarray:
        """(V,) structured array in :attr:`format` order (56 bytes a vertex, 80 with
        eight influences)."""
        fmt = self.format
        out = np.empty(self.vertex_count, np.dtype([(n, *_NUMPY[f]) for n, f, _ in fmt]))
        for name, _, _ in fmt:
            out[name] = self.attributes[name]
        return out


def vertex_colors(mesh, palette_materials=()) -> np.ndarray:
    """``(V, 4)`` uint8 of each vertex of a ProxyMesh: RGB its material's base colour
    (:class:`~crowd_addon.core.meshes.mesh.Look` colour; a vertex shared by triangles of
    several materials takes the last triangle's), white without looks (the agent's
    colour alone then: gpu_shaders/crowd_vertex.glsl); alpha the column of the agent
    palette colouring that material (its place in ``palette_materials``, material
    names), 255 where none does."""
    out = np.full((mesh.vertex_count, 4), 255, np.uint8)
    if mesh.looks:
        colors = np.array([look.color for look in mesh.looks], np.float64)
        material = np.zeros(mesh.triangles.shape[0], np.int64) if mesh.material is None \
            else np.asarray(mesh.material, np.int64)
        per_triangle = np.rint(np.clip(colors[material], 0, 1) * 255).astype(np.uint8)
        names = list(palette_materials)
        column = np.array([names.index(k.name) if k.name in names else 255
                           for k in mesh.looks], np.uint8)
        per_triangle[:, 3] = column[material]
        out[mesh.triangles.reshape(-1)] = np.repeat(per_triangle, 3, axis=0)
    return out


def look_depths(bone_indices, depth=None) -> np.ndarray:
    """``(V,)`` uint32: each influence's look chain depth packed four bits apiece
    (influence ``i`` in bits ``4i .. 4i + 3``; ``depth``: the chain depth of each bone
    of the skeleton, :attr:`~crowd_addon.core.runtime.look_at.LookChain.depth`, None:
    no look rig), so the vertex stage knows without a texel fetch which influences a
    look turns (``gpu_shaders/look_at.glsl``); 0 for a vertex the look leaves."""
    idx = np.asarray(bone_indices, np.int64)
    out = np.zeros(idx.shape[0], np.uint32)
    if depth is None:
        return out
    depth = np.asarray(depth, np.int64)
    if depth.max(initial=0) > 15:
        raise CrowdError(f"a look chain {int(depth.max())} bones deep: the GPU packs at "
                         "most 15")
    d = np.where(idx < depth.size, depth[np.minimum(idx, depth.size - 1)], 0)
    for i in range(d.shape[1]):
        out |= (d[:, i].astype(np.uint32) << np.uint32(4 * i))
    return out


def proxy_buffers(mesh, palette_materials=(), depth=None) -> ProxyBuffers:
    """Vertex arrays of a :class:`~crowd_addon.core.meshes.mesh.ProxyMesh` (already validated:
    4 or 8 influences a vertex, strongest first, summing to 1); ``palette_materials``
    as :func:`vertex_colors`; ``depth`` its skeleton's look chain depth per bone
    (:func:`look_depths`; None: no look rig)."""
    idx, w = mesh.bone_indices, mesh.bone_weights
    attrs = {"pos": np.ascontiguousarray(mesh.positions, np.float32),
             "nor": np.ascontiguousarray(mesh.normals, np.float32),
             "bone_idx": np.ascontiguousarray(idx[:, :4], np.uint16),
             "bone_w": np.ascontiguousarray(w[:, :4], np.float32),
             "col": vertex_colors(mesh, palette_materials),
             "look_depth": look_depths(idx, depth)}
    if idx.shape[1] > 4:
        attrs["bone_idx2"] = np.ascontiguousarray(idx[:, 4:8], np.uint16)
        attrs["bone_w2"] = np.ascontiguousarray(w[:, 4:8], np.float32)
    return ProxyBuffers(mesh.name, attrs, np.ascontiguousarray(mesh.triangles, np.uint32)
                        .reshape(-1))


def crowd_proxies(view) -> list:
    """Per body of ``view.bodies`` (a crowd's ``FrameView``: each mesh variant and set
    of props in use, :mod:`crowd_addon.core.meshes.bodies`), its LOD list of
    :class:`ProxyBuffers`. A character that agents use but that has no proxy mesh
    (``CrowdConfig.add_mesh``) is an error naming it."""
    out = []
    for body in view.bodies:
        sk = view.skeletons[body.skeleton]
        if not body.levels:
            raise CrowdError(f"skeleton {sk.name!r}: its agents need a proxy mesh to be "
                             "drawn (CrowdConfig.add_mesh)")
        for m in body.levels:
            if int(m.bone_indices.max()) >= sk.bone_count:
                raise CrowdError(f"mesh {m.name!r}: uses bone {int(m.bone_indices.max())} but "
                                 f"skeleton {sk.name!r} has {sk.bone_count} bones")
        palette = view.config.palette_materials.get(sk.name, ())
        chain = view.look_chains[body.skeleton]
        depth = None if chain is None else chain.depth
        out.append([proxy_buffers(m, palette, depth) for m in body.levels])
    return out
