"""Proxy meshes as vertex arrays for the skinning program's inputs.

A core :class:`~crowd_addon.core.mesh.ProxyMesh` becomes one
:class:`ProxyBuffers` per LOD: named attribute arrays matching the ``vertex_in``
names of :data:`~.programs.CROWD_DRAW` (``pos``, ``nor`` float32 ``(V, 3)``,
``bone_idx`` uint16 ``(V, 4)``, ``bone_w`` float32 ``(V, 4)``, the form Blender's
``GPUVertBuf.attr_fill`` takes), an interleaved copy for moderngl, and uint32
triangle indices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import CrowdError

__all__ = ["ProxyBuffers", "proxy_buffers", "crowd_proxies", "copies_per_instance",
           "INTERLEAVED_FORMAT"]

#: (attribute, moderngl format, bytes) of :meth:`ProxyBuffers.interleaved`, in order.
INTERLEAVED_FORMAT = (("pos", "3f", 12), ("nor", "3f", 12), ("bone_idx", "4u2", 8),
                      ("bone_w", "4f", 16))
_DTYPE = np.dtype([("pos", "<f4", 3), ("nor", "<f4", 3), ("bone_idx", "<u2", 4),
                   ("bone_w", "<f4", 4)])


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
    def influences(self) -> int:
        """Most bones any vertex uses (1..4): the skinning shader's ``INFLUENCES``."""
        return max(1, int((self.attributes["bone_w"] > 0).sum(1).max()))

    def batched(self, copies: int) -> "ProxyBuffers":
        """``copies`` back-to-back copies of this mesh in one set of arrays (copy ``k``'s
        vertices at ``k * V``), for drawing several agents per instance."""
        attrs = {k: np.ascontiguousarray(np.tile(v, (copies, 1)))
                 for k, v in self.attributes.items()}
        offsets = (np.arange(copies, dtype=np.int64) * self.vertex_count)[:, None]
        indices = (self.indices[None].astype(np.int64) + offsets).astype(np.uint32).reshape(-1)
        return ProxyBuffers(self.name, attrs, indices)

    def interleaved(self) -> np.ndarray:
        """(V,) structured array in :data:`INTERLEAVED_FORMAT` order (48 bytes a vertex)."""
        out = np.empty(self.vertex_count, _DTYPE)
        for name in _DTYPE.names:
            out[name] = self.attributes[name]
        return out


def proxy_buffers(mesh) -> ProxyBuffers:
    """Vertex arrays of a :class:`~crowd_addon.core.mesh.ProxyMesh` (already validated:
    top-4 influences summing to 1)."""
    attrs = {"pos": np.ascontiguousarray(mesh.positions, np.float32),
             "nor": np.ascontiguousarray(mesh.normals, np.float32),
             "bone_idx": np.ascontiguousarray(mesh.bone_indices, np.uint16),
             "bone_w": np.ascontiguousarray(mesh.bone_weights, np.float32)}
    return ProxyBuffers(mesh.name, attrs, np.ascontiguousarray(mesh.triangles, np.uint32)
                        .reshape(-1))


def crowd_proxies(view) -> list:
    """Per skeleton of ``view.skeletons`` (a crowd's ``FrameView``), its LOD list of
    :class:`ProxyBuffers` (empty for a skeleton no agent uses). A skeleton that agents
    use but that has no proxy mesh (``CrowdConfig.add_mesh``) is an error naming it."""
    used = np.unique(view.agent_skeleton)
    out = []
    for k, sk in enumerate(view.skeletons):
        levels = view.config.meshes.get(sk.name, [])
        if k in used and not levels:
            raise CrowdError(f"skeleton {sk.name!r}: its agents need a proxy mesh to be "
                             "drawn (CrowdConfig.add_mesh)")
        for m in levels:
            if int(m.bone_indices.max()) >= sk.bone_count:
                raise CrowdError(f"mesh {m.name!r}: uses bone {int(m.bone_indices.max())} but "
                                 f"skeleton {sk.name!r} has {sk.bone_count} bones")
        out.append([proxy_buffers(m) for m in levels] if k in used else [])
    return out
