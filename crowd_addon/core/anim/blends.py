"""The blending controller kinds (paper s.3.4, Eq. 2-3): :class:`Blend2` (two-way),
:class:`BlendMask` (per-bone masked sum), :class:`Layer` (override or additive layer on a
base) and :class:`BlendSpace2D` (children at 2-D points weighted by a parameter point,
:func:`blend_space_weights`), each with its batch evaluator (:mod:`.controllers`' protocol).
A weight is a number or the name of a parameter set per stream.
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from ..base.errors import CrowdError
from .controllers import Batch, Controller

__all__ = ["Blend2", "BlendMask", "Layer", "BlendSpace2D", "blend_space_weights"]


def _weight_spec(value, what):
    if isinstance(value, str):
        if not value:
            raise CrowdError(f"{what}: empty parameter name")
        return value
    v = float(value)
    if not np.isfinite(v):
        raise CrowdError(f"{what}: weight must be finite, got {value!r}")
    return v


# -------------------------------------------------------------------------- blend2
class Blend2(Controller):
    """Two-way blend (paper Eq. 2): ``a + (b - a) * weight``; weight 0..1 or a parameter."""

    def __init__(self, a: Controller, b: Controller, weight=0.5):
        self.a, self.b = a, b
        self.weight = _weight_spec(weight, "blend2")

    def children(self):
        return (self.a, self.b)

    class Batch(Batch):
        def setup(self):
            self.ia = np.array([c[0] for c in self.child_index], np.int64)
            self.ib = np.array([c[1] for c in self.child_index], np.int64)
            self.specs = [n.weight for n in self.nodes]

        def prepare(self, ctx):
            w = np.clip(self.param_values(ctx, self.specs), 0.0, 1.0)
            self.w = w
            ctx.local_weight[self.ia] = 1 - w
            ctx.local_weight[self.ib] = w

        def evaluate(self, ctx):
            ctx.poses[self.out] = sqt.blend2(ctx.poses[self.ia], ctx.poses[self.ib],
                                               self.w.astype(np.float32))


# ---------------------------------------------------------------------- blend mask
class BlendMask(Controller):
    """Per-bone masked sum of children (paper Eq. 3): ``sum_k mask_k * P_k``.

    Parameters
    ----------
    children : sequence of controllers.
    masks : (k, B) per-bone weights (or dicts bone name -> weight, other bones 0);
        for every bone the weights must sum to a positive value and are normalised.
    """

    def __init__(self, children, masks):
        self._children = tuple(children)
        self.masks = masks
        if len(self._children) < 1:
            raise CrowdError("blend mask: needs at least one child")
        if len(masks) != len(self._children):
            raise CrowdError(f"blend mask: {len(masks)} masks for {len(self._children)} "
                             "children")

    def children(self):
        return self._children

    def validate(self, view):
        m = self.resolved_masks(view.skeleton)
        total = m.sum(axis=0)
        if (total <= 0).any():
            b = int(np.flatnonzero(total <= 0)[0])
            raise CrowdError(f"blend mask: bone {view.skeleton.bone_names[b]!r} has no "
                             "weight in any mask")

    def resolved_masks(self, skeleton) -> np.ndarray:
        out = np.zeros((len(self.masks), skeleton.bone_count))
        for k, m in enumerate(self.masks):
            out[k] = _bone_weights(m, skeleton, "blend mask")
        return out

    class Batch(Batch):
        def setup(self):
            k = len(self.nodes[0].children())
            if any(len(n.children()) != k for n in self.nodes):
                raise AssertionError("evaluator groups blend masks by child count")
            w = np.zeros((len(self.nodes), k, self.bones), np.float32)
            for i, (n, sk) in enumerate(zip(self.nodes, self.skeletons)):
                m = n.resolved_masks(sk)
                w[i, :, :m.shape[1]] = m
                w[i, 0, m.shape[1]:] = 1
            w /= w.sum(axis=1, keepdims=True)
            self.w = w
            self.ci = np.array(self.child_index, np.int64)  # (n, k)

        def prepare(self, ctx):
            ctx.local_weight[self.ci] = self.w.max(axis=2)

        def evaluate(self, ctx):
            ctx.poses[self.out] = sqt.blend_weighted(ctx.poses[self.ci], self.w)

    @staticmethod
    def group_key(node):
        return len(node.children())


# ---------------------------------------------------------------------------- layer
class Layer(Controller):
    """A layer on top of a base: override (masked replace) or additive.

    Parameters
    ----------
    base, layer : controllers.
    mode : ``"override"`` blends toward the layer pose per bone; ``"additive"`` adds
        the layer's difference to ``reference`` on top of the base (e.g. a wave on a
        walk).
    bone_weights : None (all bones 1), (B,) array, or dict bone name -> weight
        (other bones 0), e.g. ``{"upperarm.R": 1, "forearm.R": 1, "hand.R": 1}``.
    weight : overall weight, number or parameter name.
    reference : for additive layers, ``(clip name, frame)`` whose pose is the
        zero of the delta, ``frame`` in crowd frames from the clip's start (clip frame
        ``frame * clip.fps / crowd fps``); default the skeleton's bind pose.
    """

    MODES = ("override", "additive")

    def __init__(self, base, layer, mode="override", bone_weights=None, weight=1.0,
                 reference=None):
        if mode not in self.MODES:
            raise CrowdError(f"layer: mode must be one of {self.MODES}, got {mode!r}")
        self.base, self.layer = base, layer
        self.mode = mode
        self.bone_weights = bone_weights
        self.weight = _weight_spec(weight, "layer")
        self.reference = reference

    def children(self):
        return (self.base, self.layer)

    def validate(self, view):
        _bone_weights(self.bone_weights, view.skeleton, "layer")
        if self.reference is not None:
            clip_name, frame = self.reference
            clip = view.clip(clip_name)
            length = clip.frames_at(view.fps)
            if not 0 <= float(frame) <= length * (1 + 1e-12):
                raise CrowdError(f"layer: reference frame {frame} outside clip "
                                 f"{clip_name!r} (0..{length:g} frames at {view.fps:g} fps)")

    @staticmethod
    def group_key(node):
        return node.mode

    class Batch(Batch):
        def setup(self):
            n = len(self.nodes)
            self.ib = np.array([c[0] for c in self.child_index], np.int64)
            self.il = np.array([c[1] for c in self.child_index], np.int64)
            self.bw = np.zeros((n, self.bones), np.float32)
            self.ref = sqt.identity_pose((n, self.bones))
            for i, (node, sk) in enumerate(zip(self.nodes, self.skeletons)):
                self.bw[i, :sk.bone_count] = _bone_weights(node.bone_weights, sk, "layer")
                if node.reference is None:
                    self.ref[i, :sk.bone_count] = sk.bind_pose
                else:
                    c = self.bank.entry(node.reference[0], sk)
                    at = self.bank.rate[c] * float(node.reference[1])      # clip frames
                    self.ref[i] = self.bank.sample([c], [at])[0]
            self.specs = [node.weight for node in self.nodes]
            self.additive = self.nodes[0].mode == "additive"
            # bones no node of the batch layers stay the base pose, computed on none
            used = np.flatnonzero(self.bw.max(axis=0) > 0)
            self.bones_used = slice(None) if used.size == self.bones else used
            self.ref_used = self.ref[:, self.bones_used]

        def prepare(self, ctx):
            w = np.clip(self.param_values(ctx, self.specs), 0.0, 1.0)
            self.w = (self.bw * w[:, None].astype(np.float32))
            ctx.local_weight[self.ib] = 1.0
            ctx.local_weight[self.il] = self.w.max(axis=1)

        def evaluate(self, ctx):
            if isinstance(self.out, slice):        # the base straight into the output
                out = ctx.poses[self.out]
                np.take(ctx.poses, self.ib, axis=0, out=out, mode="clip")   # (unbuffered)
            else:
                out = ctx.poses[self.ib]
            b = self.bones_used
            base = out[:, b]
            lay = ctx.poses[self.il[:, None], b] if isinstance(b, np.ndarray) \
                else ctx.poses[self.il]
            w = self.w[:, b]
            if self.additive:
                delta = sqt.additive_delta(lay, self.ref_used)
                out[:, b] = sqt.apply_additive(base, delta, w)
            else:
                out[:, b] = sqt.blend2(base, lay, w)
            if not isinstance(self.out, slice):
                ctx.poses[self.out] = out


def _bone_weights(spec, skeleton, what) -> np.ndarray:
    b = skeleton.bone_count
    if spec is None:
        return np.ones(b)
    if isinstance(spec, dict):
        out = np.zeros(b)
        for name, w in spec.items():
            if name not in skeleton.bone_names:
                raise CrowdError(f"{what}: skeleton {skeleton.name!r} has no bone {name!r}")
            out[skeleton.bone_names.index(name)] = float(w)
    else:
        out = np.asarray(spec, np.float64).reshape(-1)
        if out.shape != (b,):
            raise CrowdError(f"{what}: {out.shape[0]} bone weights for skeleton "
                             f"{skeleton.name!r} with {b} bones")
    if not np.isfinite(out).all() or (out < 0).any() or (out > 1).any():
        raise CrowdError(f"{what}: bone weights must be finite and in 0..1")
    return out


# -------------------------------------------------------------------- blend space
def blend_space_weights(points: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Gradient-band interpolation weights of 2-D sample ``points`` at parameters ``p``.

    Parameters
    ----------
    points : (n, k, 2) sample positions (distinct per node).
    p : (n, 2) parameter points.

    Returns
    -------
    (n, k) weights >= 0 summing to 1; exactly one-hot at a sample point. The nearest
    sample always has an unnormalised weight >= 1/2, so the sum never vanishes.
    """
    d = points[:, None, :, :] - points[:, :, None, :]          # (n, i, j, 2) p_j - p_i
    len2 = np.sum(d * d, axis=-1)                                # (n, i, j)
    rel = p[:, None, :] - points                                 # (n, i, 2)
    proj = np.einsum("nic,nijc->nij", rel, d)
    k = points.shape[1]
    eye = np.eye(k, dtype=bool)[None]
    h = 1.0 - proj / np.where(eye, 1.0, len2)
    h = np.where(eye, np.inf, h)
    h = np.clip(h.min(axis=2), 0.0, None) if k > 1 else np.ones(p.shape[:1] + (1,))
    return h / h.sum(axis=1, keepdims=True)


class BlendSpace2D(Controller):
    """2-D blend space: children placed at points, weighted by a parameter point.

    Parameters
    ----------
    children : sequence of controllers (k >= 1).
    points : (k, 2) distinct sample positions.
    x, y : parameter names (or numbers) giving the point to evaluate.
    """

    def __init__(self, children, points, x="x", y="y"):
        self._children = tuple(children)
        pts = np.asarray(points, np.float64)
        if pts.shape != (len(self._children), 2) or not np.isfinite(pts).all():
            raise CrowdError(f"blend space: points must be finite ({len(self._children)}, 2), "
                             f"got {pts.shape}")
        for i in range(len(pts)):
            for j in range(i):
                if np.allclose(pts[i], pts[j]):
                    raise CrowdError(f"blend space: samples {j} and {i} share point "
                                     f"{tuple(pts[i])}")
        self.points = pts
        self.x = _weight_spec(x, "blend space x")
        self.y = _weight_spec(y, "blend space y")

    def children(self):
        return self._children

    @staticmethod
    def group_key(node):
        return len(node.children())

    class Batch(Batch):
        def setup(self):
            self.pts = np.stack([n.points for n in self.nodes])
            self.ci = np.array(self.child_index, np.int64)
            self.xs = [n.x for n in self.nodes]
            self.ys = [n.y for n in self.nodes]

        def prepare(self, ctx):
            p = np.stack([self.param_values(ctx, self.xs), self.param_values(ctx, self.ys)], 1)
            if getattr(self, "_p", None) is None or not np.array_equal(p, self._p):
                self._p, self.w = p, blend_space_weights(self.pts, p)   # point moved
            ctx.local_weight[self.ci] = self.w

        def evaluate(self, ctx):
            ctx.poses[self.out] = sqt.blend_weighted(ctx.poses[self.ci],
                                                       self.w.astype(np.float32))
