"""Per-agent instance data: the texture the skinning shader reads by agent id.

A row of two RGBA32F texels per agent (``gpu_shaders/agents.glsl``):
``(x, y, z, heading)`` and ``(kind, ref, offset, rgb24)``, the rows in column
blocks of the texture's height like the pose texture (``block_layout.glsl``), so
one row-upload path serves both. Built vectorised from a core ``Crowd``; each
frame :meth:`InstanceData.update` compares the crowd's agent arrays with what was
last packed and returns only the rows of agents whose reference, placement or
colour changed.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import CrowdError
from .programs import AGENT_TEXELS
from .texture_region import block_image, block_regions

__all__ = ["InstanceData", "pack_colors"]


def pack_colors(colors: np.ndarray) -> np.ndarray:
    """``(N, 3)`` colours in 0..1 -> ``(N,)`` float32 ``r * 65536 + g * 256 + b`` of
    8-bit channels (exact in float32)."""
    c = np.rint(np.clip(np.asarray(colors, np.float64), 0, 1) * 255).astype(np.int64)
    return (c[:, 0] * 65536 + c[:, 1] * 256 + c[:, 2]).astype(np.float32)


class InstanceData:
    """The agent texture of a crowd and its per-frame changes.

    Attributes
    ----------
    records : (N, 2, 4) float32 agent rows.
    block_rows, blocks : texture height and column blocks; ``width = 2 * blocks``.
    moved : bool, whether the last :meth:`update` saw positions or headings change
        (draw lists sorted by camera distance must then be rebuilt).
    """

    def __init__(self, crowd, max_texture_size: int = 16384):
        n = crowd.N
        self.count = n
        self.block_rows = max(1, min(n, int(max_texture_size)))
        self.blocks = max(1, -(-n // self.block_rows))
        self.width, self.height = self.blocks * AGENT_TEXELS, self.block_rows
        if self.width > max_texture_size:
            raise CrowdError(f"agent texture cannot fit: {n} agents need {self.width} x "
                             f"{self.height} texels, max texture size is {max_texture_size}")
        self.records = np.zeros((n, AGENT_TEXELS, 4), np.float32)
        self._last = None
        self.moved = True
        self.update(crowd)

    def texture_image(self) -> np.ndarray:
        """The whole ``(height, width, 4)`` float32 texture."""
        return block_image(self.records, self.block_rows, self.blocks)

    @staticmethod
    def _state(crowd):
        return (crowd.agent_kind, crowd.agent_ref, crowd.agent_offset, crowd.agent_position,
                crowd.agent_heading, crowd.agent_color)

    def update(self, crowd) -> list:
        """Repack the agents that changed since the last call; their texture regions
        (every agent on the first call)."""
        state = self._state(crowd)
        if self._last is None:
            changed = np.arange(self.count)
        else:
            diff = [(new != old) for new, old in zip(state, self._last)]
            diff = [d if d.ndim == 1 else d.any(1) for d in diff]
            self.moved = bool(diff[3].any() or diff[4].any())
            changed = np.flatnonzero(np.logical_or.reduce(diff))
        if changed.size == 0:
            return []
        kind, ref, offset, position, heading, color = (np.asarray(a) for a in state)
        rec = self.records
        rec[changed, 0, :3] = position[changed]
        rec[changed, 0, 3] = heading[changed]
        rec[changed, 1, 0] = kind[changed]
        rec[changed, 1, 1] = ref[changed]
        rec[changed, 1, 2] = offset[changed]
        rec[changed, 1, 3] = pack_colors(color[changed])
        self._last = tuple(np.array(a, copy=True) for a in state)
        # a write per run of changed agents: a few hundred small writes cost less than
        # re-sending whole blocks (1.8x the minimum bytes at the paper's transitions)
        return block_regions(rec, changed, self.block_rows, max_regions=1024)
