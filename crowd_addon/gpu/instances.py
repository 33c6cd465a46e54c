"""Per-agent instance data: the texture the skinning shader reads by agent id.

A row of three RGBA32F texels per agent (``gpu_shaders/agents.glsl``):
``(x, y, z, heading)``, ``(kind * 65536 + offset, ref, scale, rgb24)`` and the agent's
four palette colours as rgb24 (-1: none), the rows in column
blocks of the texture's height like the pose texture (``block_layout.glsl``), so
one row-upload path serves both. Built vectorised from a crowd's ``FrameView``;
each frame :meth:`InstanceData.update` asks the crowd which agents changed since its
last call (the agents' change log, ``FrameView.agent_changes``) and repacks only
those: a frame where no agent changed costs nothing per agent.
"""

from __future__ import annotations

import numpy as np

from ..core.runtime.pose_storage import block_layout
from .programs import AGENT_TEXELS
from .texture_region import block_image, block_regions

__all__ = ["InstanceData", "pack_colors", "pack_kind_offset", "OFFSET_LIMIT"]


def pack_colors(colors: np.ndarray) -> np.ndarray:
    """``(N, 3)`` colours in 0..1 -> ``(N,)`` float32 ``r * 65536 + g * 256 + b`` of
    8-bit channels (exact in float32)."""
    c = np.rint(np.clip(np.asarray(colors, np.float64), 0, 1) * 255).astype(np.int64)
    return (c[:, 0] * 65536 + c[:, 1] * 256 + c[:, 2]).astype(np.float32)


#: offsets packed beside the kind stay below this (M is at most it, core.config)
OFFSET_LIMIT = 65536


def pack_kind_offset(kind, offset) -> np.ndarray:
    """``kind * 65536 + offset`` as float32 (exact: below 2**24)."""
    return (np.asarray(kind, np.int64) * OFFSET_LIMIT + np.asarray(offset, np.int64)) \
        .astype(np.float32)


class InstanceData:
    """The agent texture of a crowd and its per-frame changes.

    Parameters
    ----------
    view : the crowd's :class:`~crowd_addon.core.runtime.frame_view.FrameView`; the records
        are packed from it at once.
    max_texture_size : the GPU's largest texture side in texels.

    Attributes
    ----------
    records : (N, 2, 4) float32 agent rows.
    block_rows, blocks : texture height and column blocks; ``width = 2 * blocks``.
    moved : bool, whether the last :meth:`update` saw a position or heading change
        (draw lists sorted by camera distance must then be rebuilt).
    """

    def __init__(self, view, max_texture_size: int = 16384):
        n = view.agent_count
        self.count = n
        self.block_rows, self.blocks, self.width = block_layout(n, AGENT_TEXELS, max_texture_size,
                                                                "agent texture")
        self.height = self.block_rows
        self.records = np.zeros((n, AGENT_TEXELS, 4), np.float32)
        self._cursor = 0
        self.moved = True
        self.update(view)

    def texture_image(self) -> np.ndarray:
        """The whole ``(height, width, 4)`` float32 texture."""
        return block_image(self.records, self.block_rows, self.blocks)

    def update(self, view, max_regions: int | None = 1024) -> list:
        """Repack the agents the crowd changed since the last call
        (``view.agent_changes``; every agent on the first call or after a reset) and
        return their texture regions: one per run of consecutive changed agents, or
        past ``max_regions`` runs one per column block (None: no limit)."""
        changes = view.agent_changes(self._cursor)
        self._cursor = changes.cursor
        self.moved = changes.moved
        changed = np.arange(self.count) if changes.agents is None else changes.agents
        if changed.size == 0:
            return []
        a, rec = view.agents, self.records
        rec[changed, 0, :3] = a.position[changed]
        rec[changed, 0, 3] = a.heading[changed]
        rec[changed, 1, 0] = pack_kind_offset(a.kind[changed], a.offset[changed])
        rec[changed, 1, 1] = a.ref[changed]
        rec[changed, 1, 2] = a.scale[changed]
        rec[changed, 1, 3] = pack_colors(a.color[changed])
        pal = a.palette[changed]                              # (k, 4, 3), -1: none
        rec[changed, 2] = np.where((pal >= 0).all(2),
                                   pack_colors(pal.reshape(-1, 3)).reshape(-1, 4), -1.0)
        return block_regions(rec, changed, self.block_rows, max_regions)
