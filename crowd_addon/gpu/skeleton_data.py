"""Small textures of the GPU transition shader (``gpu_shaders/transition_comp.glsl``)."""

from __future__ import annotations

import numpy as np

__all__ = ["skeleton_image", "END_OF_SKELETON"]

#: Parent value marking bones past a skeleton's last bone.
END_OF_SKELETON = -2.0


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
