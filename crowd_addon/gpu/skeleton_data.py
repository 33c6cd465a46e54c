"""Small textures of the GPU skinning-rows shader (``gpu_shaders/skin_rows_comp.glsl``)."""

from __future__ import annotations

import numpy as np

__all__ = ["skeleton_image", "batch_image", "fill_batch", "END_OF_SKELETON", "BATCH_WIDTH"]

#: Parent value marking bones past a skeleton's last bone.
END_OF_SKELETON = -2.0
#: Entries per texel row of the batch texture.
BATCH_WIDTH = 1024


def skeleton_image(skeletons, bones: int) -> np.ndarray:
    """``(K, 4 * bones, 4)`` float32: per skeleton row, per bone the top three rows of
    its inverse bind matrix and ``(parent, 0, 0, 0)`` (``END_OF_SKELETON`` past its
    last bone). Uploaded once."""
    img = np.zeros((len(skeletons), bones, 4, 4), np.float32)
    img[:, :, 3, 0] = END_OF_SKELETON
    for k, sk in enumerate(skeletons):
        b = sk.bone_count
        img[k, :b, :3] = sk.inverse_bind[:, :3, :]
        img[k, :b, 3, 0] = sk.parents
    return img.reshape(len(skeletons), bones * 4, 4)


def batch_image(rows: int) -> np.ndarray:
    """``(H, W, 4)`` float32 staging image for up to ``rows`` batch entries (one RGBA
    texel each, row-major: ``linear_texel`` in gpu_shaders/block_layout.glsl)."""
    width = max(1, min(rows, BATCH_WIDTH))
    return np.zeros((-(-max(rows, 1) // width), width, 4), np.float32)


def fill_batch(image: np.ndarray, batch) -> tuple:
    """Write a ``FrameView.take_skinning_batch()`` into ``image`` as (row, source, S,
    skeleton) texels; returns (entries, texel rows used). Row indices stay exact in
    float32 (a pose texture has far fewer than 2**24 rows)."""
    n = len(batch)
    if n > image.shape[0] * image.shape[1]:
        raise ValueError(f"skinning batch of {n} entries exceeds the batch texture "
                         f"({image.shape[0] * image.shape[1]})")
    flat = image.reshape(-1, 4)
    flat[:n, 0] = batch.rows
    flat[:n, 1] = batch.sources
    flat[:n, 2] = batch.weights
    flat[:n, 3] = batch.skeletons
    return n, -(-n // image.shape[1])
