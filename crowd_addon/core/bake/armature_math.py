"""Armature data as plain arrays -> skeletons, local transforms and skin influences.

The Blender side (``crowd_addon.blender.armature``) reads bone names, parent names
and ``bone.matrix_local`` (armature space, row-major float64) with ``foreach_get``;
everything computed from them is here. Conventions: the local transform of bone
``i`` is ``inv(model[parent]) @ model[i]`` (roots keep their model matrix); the bind
pose is the rest pose and ``inverse_bind = inv(bone.matrix_local)``, so skinning
matrices are ``pose matrix @ inv(bone.matrix_local)`` as in Blender's Armature
modifier.
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from ..base import quaternion as quat
from ..base.errors import CrowdError
from ..base.skeleton import Skeleton, affine_inverse

__all__ = ["relative_to_parent", "rest_skeleton", "check_hierarchy", "sqt_from_matrices",
           "vertex_influences"]


def relative_to_parent(model: np.ndarray, parents: np.ndarray,
                       inverse: np.ndarray | None = None) -> np.ndarray:
    """Local matrices ``inv(model[parent]) @ model`` (roots keep their model matrix).

    model : (..., B, 4, 4) float64 model matrices; parents : (B,) int64 parent index,
        -1 for roots.
    inverse : optional (B, 4, 4) inverses of ``model`` (2-D ``model`` only), when the
        caller has them already (the same numbers: each matrix is inverted on its own).
    Returns (..., B, 4, 4) float64.
    """
    out = model.copy()
    has = parents >= 0
    inv = np.linalg.inv(model[..., parents[has], :, :]) if inverse is None \
        else inverse[parents[has]]
    out[..., has, :, :] = inv @ model[..., has, :, :]
    return out


def rest_skeleton(name: str, bone_names, parent_names, matrix_local: np.ndarray):
    """The :class:`Skeleton` of an armature's bones and its rest pose.

    Parameters
    ----------
    name : the skeleton's name.
    bone_names : B bone names in the armature's order; parent_names : B parent names
        (None for roots).
    matrix_local : (B, 4, 4) float64 rest matrices in armature space, same order.

    Returns
    -------
    ``(skeleton, rest, rotation)``: the skeleton (bones ordered parents first, bind
    pose the rest pose relative to the parent, ``inverse_bind = inv(matrix_local)``),
    the rest pose relative to the parent ``(B, 4, 4)`` float64 and its rotations
    ``(B, 4)`` float64, both in the armature's order.
    """
    index = {n: i for i, n in enumerate(bone_names)}
    parents = np.array([-1 if p is None else index[p] for p in parent_names], np.int64)
    inverse = affine_inverse(matrix_local)
    rel = relative_to_parent(matrix_local, parents, inverse)
    rot = quat.from_matrix(rel[:, :3, :3])
    bind = sqt.identity_pose(len(bone_names)).astype(np.float64)
    bind[:, sqt.ROT] = rot
    bind[:, sqt.TRANS] = rel[:, :3, 3]
    skeleton = Skeleton.from_parent_names(name, bone_names, parent_names, bind,
                                          inverse_bind=inverse)
    return skeleton, rel, rot


def check_hierarchy(skeleton: Skeleton, armature: str, bone_names, parent_names) -> None:
    """Raise a :class:`CrowdError` unless ``skeleton`` has exactly the bones
    ``bone_names`` with parents ``parent_names`` (None for roots) of the armature
    named ``armature``."""
    parent_of = dict(zip(bone_names, parent_names))
    if set(bone_names) != set(skeleton.bone_names):
        extra = sorted(set(skeleton.bone_names) - set(bone_names))
        missing = sorted(set(bone_names) - set(skeleton.bone_names))
        raise CrowdError(f"skeleton {skeleton.name!r} does not match armature "
                         f"{armature!r}: bones only in the skeleton {extra}, "
                         f"only in the armature {missing}")
    for i, n in enumerate(skeleton.bone_names):
        p = skeleton.parents[i]
        if (skeleton.bone_names[p] if p >= 0 else None) != parent_of[n]:
            raise CrowdError(f"skeleton {skeleton.name!r}: bone {n!r} has a different parent "
                             f"than in armature {armature!r} ({parent_of[n]!r})")


def sqt_from_matrices(local: np.ndarray, bone_names, what: str,
                      frame_labels=None) -> np.ndarray:
    """SQT ``(..., B, 10)`` float64 of local affine matrices ``(..., B, 4, 4)``.

    A matrix must be rotation x axis scale (no shear, non-zero scale); a negative
    determinant flips the x scale. Anything else raises a :class:`CrowdError` naming
    ``what``, the bone and the frame (``frame_labels[i]`` for leading index ``i``).
    """
    m3 = local[..., :3, :3]
    s = np.linalg.norm(m3, axis=-2)                                   # column norms
    flip = np.linalg.det(m3) < 0
    s[..., 0] = np.where(flip, -s[..., 0], s[..., 0])
    tiny = (np.abs(s) < 1e-9).any(-1)
    r = m3 / np.where(np.abs(s) < 1e-9, 1, s)[..., None, :]
    err = np.abs(np.swapaxes(r, -1, -2) @ r - np.eye(3)).max((-1, -2))
    bad = tiny | (err > 1e-4)
    if bad.any():
        at = np.argwhere(bad)[0]
        frame = "" if len(at) < 2 else \
            f" at frame {frame_labels[at[0]] if frame_labels is not None else at[0]}"
        kind = "zero scale" if tiny[tuple(at)] else "shear (non-uniform scale inherited " \
                                                    "through a rotated child)"
        raise CrowdError(f"{what}: bone {bone_names[at[-1]]!r}{frame} has {kind}; a crowd "
                         "bone stores scale, rotation and translation only")
    out = np.empty(local.shape[:-2] + (sqt.WIDTH,))
    out[..., sqt.SCALE] = s
    out[..., sqt.ROT] = quat.from_matrix(r)
    out[..., sqt.TRANS] = local[..., :3, 3]
    return out


def vertex_influences(counts: np.ndarray, groups: np.ndarray, weights: np.ndarray,
                      bone_of_group: np.ndarray):
    """Per-vertex bone influences from vertex-group memberships.

    Parameters
    ----------
    counts : (V,) int64 memberships per vertex; groups, weights : (sum(counts),) the
        group index (int64) and weight (float) of each membership, vertex by vertex.
    bone_of_group : (G + 1,) int64 skeleton bone of each vertex group, -1 for groups
        that deform no bone (the last entry, -1, catches out-of-range groups).

    Returns
    -------
    ``(indices, weights)``: (V, K) int64 bones and (V, K) float64 weights, K the most
    memberships of a vertex (at least 1); memberships of no bone weigh 0.
    """
    counts = np.asarray(counts, np.int64)
    groups = np.asarray(groups, np.int64)
    v = counts.shape[0]
    bone = bone_of_group[np.where((groups >= 0) & (groups < len(bone_of_group) - 1),
                                  groups, -1)]
    w = np.where(bone >= 0, np.asarray(weights, np.float64), 0.0)
    k = max(int(counts.max()) if v else 0, 1)
    row = np.repeat(np.arange(v), counts)
    col = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    idx = np.zeros((v, k), np.int64)
    wt = np.zeros((v, k))
    idx[row, col] = np.maximum(bone, 0)
    wt[row, col] = w
    return idx, wt
