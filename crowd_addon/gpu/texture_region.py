"""Rectangles of textures to write, and rows laid out in column blocks.

A block-laid texture (``gpu_shaders/block_layout.glsl``) holds logical rows of
``row_texels`` texels; row ``r`` starts at texel ``((r // H) * row_texels, r % H)``
with ``H`` the texture height. Core's pose textures use it
(:class:`crowd_addon.core.runtime.pose_storage.PoseStorage`) and so does the agent texture.
"""

from __future__ import annotations

import numpy as np

from ..core.runtime.pose_storage import TextureRegion

__all__ = ["block_regions", "block_image", "stage_rows"]


def block_regions(rows: np.ndarray, changed: np.ndarray, block_rows: int,
                  max_regions: int | None = 16) -> list:
    """Regions of a block-laid texture covering the logical rows ``changed``.

    ``rows`` is the ``(R, row_texels, 4)`` row array. Runs of consecutive rows, split
    at block boundaries, one region each; past ``max_regions`` runs (None: never),
    one region per block from its first to its last changed row (fewer, larger
    writes).
    """
    changed = np.unique(np.asarray(changed, np.int64))
    if changed.size == 0:
        return []
    block = changed // block_rows
    new_block = np.r_[True, block[1:] != block[:-1]]
    starts = np.flatnonzero(new_block | np.r_[True, np.diff(changed) != 1])
    if max_regions is not None and starts.size > max_regions:
        starts = np.flatnonzero(new_block)
    ends = np.r_[starts[1:], changed.size] - 1
    texels = rows.shape[1]
    out = []
    for s, e in zip(starts.tolist(), ends.tolist()):
        r0, r1 = int(changed[s]), int(changed[e]) + 1
        b = r0 // block_rows
        out.append(TextureRegion(b * texels, r0 - b * block_rows, texels, r1 - r0,
                                 rows[r0:r1], (r0, r1)))
    return out


def block_image(rows: np.ndarray, block_rows: int, blocks: int) -> np.ndarray:
    """The whole ``(block_rows, blocks * row_texels, 4)`` texture of ``rows``."""
    n, texels = rows.shape[:2]
    img = np.zeros((block_rows, blocks * texels) + rows.shape[2:], rows.dtype)
    for b in range(blocks):
        part = rows[b * block_rows:(b + 1) * block_rows]
        img[:part.shape[0], b * texels:(b + 1) * texels] = part
    return img


def stage_rows(regions) -> tuple:
    """``(staging (n, row_texels, 4) float32, rows (n,) int32)``: the rows of ``regions``
    (block-laid, whole rows, e.g. ``FrameView.take_upload_regions()``) stacked for the
    row upload shader (``gpu_shaders/row_upload_comp.glsl``)."""
    regions = list(regions)
    if not regions:
        return np.zeros((0, 0, 4), np.float32), np.zeros(0, np.int32)
    staging = np.concatenate([r.data for r in regions]).astype(np.float32, copy=False)
    rows = np.concatenate([np.arange(*r.rows) for r in regions]).astype(np.int32)
    return np.ascontiguousarray(staging), rows
