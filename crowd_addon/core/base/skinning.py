"""Local -> model -> skinning matrices, and the CPU reference skinning (paper Eq. 1).

``SkinningPlan.rows`` is the runtime path: local SQT poses ``(n, B, 10)`` to pose
texture rows ``(n, B_max, 3, 4)`` (the top three rows of ``model @ inverse_bind``
per bone, float32). It works in a component-major layout ``(3, 4, B, n)`` with
bones sorted by depth so each hierarchy level is one contiguous slice and one
``einsum``.

``model_matrices``/``skinning_matrices`` are the float64 reference and
``skin_vertices`` is the CPU reference skinning the GPU backends are tested
against.
"""

from __future__ import annotations

import numpy as np

from . import pose as sqt
from .skeleton import Skeleton, local_to_model

__all__ = ["SkinningPlan", "model_matrices", "skinning_matrices", "skin_vertices"]


class SkinningPlan:
    """Precomputed hierarchy order of one skeleton for the fast float32 path."""

    CHUNK = 256

    def __init__(self, skeleton: Skeleton, row_bones: int | None = None):
        b = skeleton.bone_count
        self.skeleton = skeleton
        self.bones = b
        self.row_bones = row_bones or b
        depth = np.zeros(b, np.int64)
        for i, p in enumerate(skeleton.parents):
            if p >= 0:
                depth[i] = depth[p] + 1
        perm = np.argsort(depth, kind="stable")
        inv = np.empty(b, np.int64)
        inv[perm] = np.arange(b)
        self.perm = perm
        self.unperm = inv
        sorted_depth = depth[perm]
        par = skeleton.parents[perm]
        self.sorted_parent = np.where(par >= 0, inv[np.maximum(par, 0)], -1)
        self.levels = []
        for d in range(1, int(depth.max()) + 1):
            a = int(np.searchsorted(sorted_depth, d, "left"))
            e = int(np.searchsorted(sorted_depth, d, "right"))
            self.levels.append((a, e, self.sorted_parent[a:e]))
        self.n_roots = int(np.searchsorted(sorted_depth, 0, "right"))
        ib = skeleton.inverse_bind[perm][:, :3, :].astype(np.float32)   # (B, 3, 4)
        self.inv_bind = np.ascontiguousarray(ib.transpose(1, 2, 0))      # (3, 4, B)
        self._ws = {}

    def _workspace(self, n):
        """Contiguous scratch arrays for ``n`` poses padded up to a multiple of 64,
        reused across frames (fresh multi-megabyte temporaries each frame cost more in
        page faults than the arithmetic, and einsum is several times slower on
        non-contiguous views). The padding columns hold finite leftovers."""
        cap = max(64, -(-n // 64) * 64)
        ws = self._ws.pop(cap, None)
        if ws is None:
            b = self.bones
            z = lambda *shape: np.zeros(shape, np.float32)  # noqa: E731
            ws = {
                "xt": z(b * sqt.WIDTH, cap), "x": z(b, sqt.WIDTH, cap), "t": z(10, b, cap),
                "m": z(3, 4, b, cap), "skin": z(3, 4, b, cap), "bone_major": z(b, 3, 4, cap),
                "levels": [(z(3, 4, e - a, cap), z(3, 4, e - a, cap)) for a, e, _ in self.levels],
                "inv_bind": np.ascontiguousarray(
                    np.broadcast_to(self.inv_bind[..., None], self.inv_bind.shape + (cap,))),
            }
        self._ws[cap] = ws                  # most recently used last
        while len(self._ws) > 4:
            self._ws.pop(next(iter(self._ws)))
        return ws, cap

    def rows(self, local: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Pose texture rows of local poses.

        Parameters
        ----------
        local : (n, >=B, 10) float32 local SQT (extra bones are ignored).
        out : optional (n, row_bones, 3, 4) float32 to write into (may be a view of
            the pose storage); bones beyond the skeleton are left untouched.

        Returns
        -------
        (n, row_bones, 3, 4) float32: ``(model @ inverse_bind)[:3, :]`` per bone.
        """
        n = local.shape[0]
        if out is None:
            out = np.zeros((n, self.row_bones, 3, 4), np.float32)
            out[:, :, 0, 0] = out[:, :, 1, 1] = out[:, :, 2, 2] = 1
        if n == 0:
            return out
        if n > self.CHUNK:
            # cache-sized chunks: at ~256 poses the scratch arrays stay in L2; one
            # call on 800 poses is ~1.7x slower per pose than four calls on 200
            for a in range(0, n, self.CHUNK):
                self.rows(local[a:a + self.CHUNK], out=out[a:a + self.CHUNK])
            return out
        b = self.bones
        ws, cap = self._workspace(n)
        # (n, B, 10) -> (B, 10, n): one 2-D transpose, then a row gather into depth order
        np.copyto(ws["xt"][:, :n], local[:, :b].reshape(n, b * sqt.WIDTH).T)
        x = np.take(ws["xt"].reshape(b, sqt.WIDTH, cap), self.perm, axis=0, out=ws["x"],
                    mode="clip")
        s0, s1, s2 = x[:, 0], x[:, 1], x[:, 2]
        w, qx, qy, qz = x[:, 3], x[:, 4], x[:, 5], x[:, 6]
        xx, yy, zz, xy, xz, yz, wx, wy, wz, tmp = ws["t"]
        mul = np.multiply
        mul(qx, qx, out=xx), mul(qy, qy, out=yy), mul(qz, qz, out=zz)
        mul(qx, qy, out=xy), mul(qx, qz, out=xz), mul(qy, qz, out=yz)
        mul(w, qx, out=wx), mul(w, qy, out=wy), mul(w, qz, out=wz)
        m = ws["m"]

        def diag(dst, p, q, scale):          # (1 - 2 (p + q)) * scale
            np.add(p, q, out=dst)
            dst *= -2
            dst += 1
            dst *= scale

        def off(dst, p, q, sign, scale):     # 2 (p +- q) * scale
            (np.add if sign > 0 else np.subtract)(p, q, out=dst)
            mul(scale, 2, out=tmp)
            dst *= tmp

        diag(m[0, 0], yy, zz, s0)
        off(m[0, 1], xy, wz, -1, s1)
        off(m[0, 2], xz, wy, +1, s2)
        off(m[1, 0], xy, wz, +1, s0)
        diag(m[1, 1], xx, zz, s1)
        off(m[1, 2], yz, wx, -1, s2)
        off(m[2, 0], xz, wy, -1, s0)
        off(m[2, 1], yz, wx, +1, s1)
        diag(m[2, 2], xx, yy, s2)
        np.copyto(m[:, 3], x[:, 7:10].transpose(1, 0, 2))
        for (a, e, par), (loc, pm) in zip(self.levels, ws["levels"]):
            np.copyto(loc, m[:, :, a:e])
            np.take(m, par, axis=2, out=pm, mode="clip")
            np.einsum("rkbn,kcbn->rcbn", pm[:, :3], loc[:3], out=m[:, :, a:e])
            m[:, 3, a:e] += pm[:, 3]
        skin = ws["skin"]
        np.einsum("rkbn,kcbn->rcbn", m[:, :3], ws["inv_bind"][:3], out=skin)
        skin[:, 3] += m[:, 3]
        bone_major = np.take(skin.transpose(2, 0, 1, 3), self.unperm, axis=0,
                             out=ws["bone_major"], mode="clip")             # (B, 3, 4, n) bone order
        out[:, :b] = bone_major.reshape(b * 12, cap)[:, :n].T.reshape(n, b, 3, 4)
        return out


def model_matrices(local: np.ndarray, skeleton: Skeleton, bones=None) -> np.ndarray:
    """Reference model matrices ``(n, B, 4, 4)`` of local SQT ``(n, B, 10)``; with
    ``bones`` (indices, each bone's parent among them: :func:`with_ancestors`), only
    theirs, ``(n, len(bones), 4, 4)``, in that order (a look reads a third of a fan's
    bones)."""
    if bones is None:
        return local_to_model(sqt.pose_to_matrices(local[:, :skeleton.bone_count]), skeleton)
    bones = np.asarray(bones, np.int64)
    mats = sqt.pose_to_matrices(local[:, bones])
    at = {int(b): i for i, b in enumerate(bones.tolist())}
    for i, b in enumerate(bones.tolist()):
        p = int(skeleton.parents[b])
        if p >= 0:
            mats[:, i] = mats[:, at[p]] @ mats[:, i]
    return mats


def with_ancestors(bones, skeleton: Skeleton) -> np.ndarray:
    """``bones`` and every bone above them, ascending (parents before children)."""
    out = set()
    for b in np.asarray(bones, np.int64).tolist():
        while b >= 0 and b not in out:
            out.add(b)
            b = int(skeleton.parents[b])
    return np.array(sorted(out), np.int64)


def skinning_matrices(local: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """Reference skinning matrices ``(n, B, 4, 4)`` float64: ``model @ inverse_bind``."""
    return model_matrices(local, skeleton) @ skeleton.inverse_bind


def skin_vertices(vertices: np.ndarray, bone_indices: np.ndarray, weights: np.ndarray,
                  rows: np.ndarray) -> np.ndarray:
    """CPU reference skinning (paper Eq. 1): ``v' = sum_i w_i (M_i M_ref_i^-1) v``.

    Parameters
    ----------
    vertices : (V, 3) rest positions.
    bone_indices : (V, K) int bone index per influence, any K (a ``ProxyMesh`` has 4
        or 8).
    weights : (V, K) weights per influence (normalised here to sum 1; unused
        influences have weight 0).
    rows : (n, B, 3, 4) skinning rows per agent (pose texture rows) or (n, B, 4, 4).

    Returns
    -------
    (n, V, 3) float64 skinned positions.
    """
    v = np.asarray(vertices, np.float64)
    w = np.asarray(weights, np.float64)
    w = w / np.where(w.sum(1, keepdims=True) > 0, w.sum(1, keepdims=True), 1)
    m = np.asarray(rows, np.float64)[:, :, :3, :]               # (n, B, 3, 4)
    g = m[:, np.asarray(bone_indices, np.int64)]                 # (n, V, K, 3, 4)
    blended = np.einsum("vi,nvirc->nvrc", w, g)                  # (n, V, 3, 4)
    return np.einsum("nvrc,vc->nvr", blended[..., :3], v) + blended[..., 3]
