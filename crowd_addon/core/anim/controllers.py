"""Controller trees (paper s.3.4): nodes evaluated at time t into a local pose.

Authoring objects (:class:`ClipPlayer`, :class:`Blend2`, :class:`BlendMask`,
:class:`Layer`, :class:`BlendSpace2D`, :class:`StateMachine`) describe a tree. The
evaluator in :mod:`.graph` groups the nodes of *all* trees by (kind, depth,
height) and calls one :class:`Batch` per group, so a frame costs a few numpy calls
per kind, not one per controller.

A new kind plugs in by subclassing :class:`Controller` and its :class:`Batch`:
``children`` says what it reads, ``Batch.prepare`` (top-down, optional) sets each
child's time shift and weight, ``Batch.evaluate`` (bottom-up) writes the poses of
its nodes into ``ctx.poses``. The scheduler knows nothing else about kinds.

Weights and parameters: a weight is a number or the name of a parameter that the
simulation sets per stream (``Crowd.set_parameter``); triggers
(``Crowd.set_trigger``) drive state machines.

Time: node times, a clip player's ``start``, a layer's reference frame and transition
durations are crowd frames; a clip player converts to clip frames with the clip's
``rate = clip.fps / crowd fps`` (``ClipBank.rate``), so every clip plays at its own
rate. Clips are played in the bone order of the tree's skeleton (``ClipBank.entry``).
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from ..base.errors import CrowdError

__all__ = [
    "Controller", "Batch", "ClipPlayer", "Blend2", "BlendMask", "Layer", "BlendSpace2D",
    "StateMachine", "StateTransition", "blend_space_weights",
]


class Controller:
    """Base of all controller kinds (a node of a tree)."""

    def children(self) -> tuple:
        return ()

    class Batch:  # replaced by each kind
        pass

    def validate(self, crowd_view) -> None:
        """Check references (clips, bones) against the crowd; raise CrowdError.

        ``crowd_view`` has ``skeleton`` (the tree's), ``fps`` (the crowd's) and
        ``clip(name)``, which raises unless the clip exists and has the skeleton's
        bones."""


class Batch:
    """The nodes of one kind at one depth and height, evaluated together.

    Attributes set by the evaluator: ``nodes`` (the controllers), ``index`` ((n,)
    node indices into the frame arrays), ``roots`` ((n,) root index of each node),
    ``child_index`` (list per node of child node indices), ``bank`` (ClipBank),
    ``bones`` (B_max).
    """

    def __init__(self, nodes, index, roots, child_index, bank, bones, skeletons):
        self.nodes = nodes
        self.index = np.asarray(index, np.int64)
        # where the batch writes its poses: a slice when its nodes are contiguous
        # (the evaluator numbers them so), else the index array
        contiguous = self.index.size and (np.diff(self.index) == 1).all()
        self.out = slice(int(self.index[0]), int(self.index[-1]) + 1) if contiguous \
            else self.index
        self.roots = np.asarray(roots, np.int64)
        self.child_index = child_index
        self.bank = bank
        self.bones = bones
        self.skeletons = skeletons  # per node
        self.setup()

    def setup(self):
        pass

    def prepare(self, ctx) -> None:
        """Top-down: set ``ctx.shift`` and ``ctx.local_weight`` of children."""

    def evaluate(self, ctx) -> None:
        raise NotImplementedError

    #: the attributes a frame leaves for the next (what snapshots and look-aheads keep;
    #: everything else is set up once or recomputed by every prepare)
    STATE = ()

    def check_state(self) -> None:
        """Raise ValueError when restored :data:`STATE` arrays cannot be this batch's."""

    def reset(self) -> None:
        """Forget per-frame state (time restarted)."""

    # helpers -----------------------------------------------------------------
    def param_values(self, ctx, specs, default=0.0) -> np.ndarray:
        """Resolve a number-or-parameter-name per node into a float array (numbers
        are gathered once; only named parameters are looked up each frame)."""
        tables = self.__dict__.setdefault("_param_tables", {})
        table = tables.get(id(specs))
        if table is None or table[0] is not specs:
            const = np.array([0.0 if isinstance(v, str) else v for v in specs], np.float64)
            named = [(i, v, int(r)) for i, (v, r) in enumerate(zip(specs, self.roots))
                     if isinstance(v, str)]
            table = tables[id(specs)] = (specs, const, named)
        _, const, named = table
        out = const.copy()
        for i, name, root in named:
            out[i] = ctx.params[root].get(name, default)
        return out


def _weight_spec(value, what):
    if isinstance(value, str):
        if not value:
            raise CrowdError(f"{what}: empty parameter name")
        return value
    v = float(value)
    if not np.isfinite(v):
        raise CrowdError(f"{what}: weight must be finite, got {value!r}")
    return v


# --------------------------------------------------------------------------- clip
class ClipPlayer(Controller):
    """Plays a clip: at node time ``t`` (crowd frames) the clip is ``start + speed * t``
    crowd frames in, i.e. at clip frame ``rate * (start + speed * t)`` with ``rate =
    clip.fps / crowd fps``: speed 1 plays the clip at its own rate, whatever its fps."""

    def __init__(self, clip: str, speed: float = 1.0, start: float = 0.0):
        self.clip = str(clip)
        self.speed = float(speed)
        self.start = float(start)
        if not (np.isfinite(self.speed) and np.isfinite(self.start)):
            raise CrowdError(f"clip player {clip!r}: speed and start must be finite")

    def validate(self, view):
        view.clip(self.clip)            # exists, with the skeleton's bones

    class Batch(Batch):
        STATE = ("prev",)            # node times of the last frame, for tag crossings

        def setup(self):
            self.clip_ids = np.array([self.bank.entry(n.clip, sk)
                                      for n, sk in zip(self.nodes, self.skeletons)], np.int64)
            rate = self.bank.rate[self.clip_ids]
            # in clip frames: t_clip = start + speed * t (exactly the given values at rate 1)
            self.speed = rate * np.array([n.speed for n in self.nodes])
            self.start = rate * np.array([n.start for n in self.nodes])
            # only nodes whose clip has event tags follow their last time
            bank = self.bank
            self.tagged = np.flatnonzero(bank.tag_start[self.clip_ids + 1]
                                         > bank.tag_start[self.clip_ids])
            self.prev = np.full(self.tagged.size, np.nan)

        def reset(self):
            self.prev[:] = np.nan

        def evaluate(self, ctx):
            t = self.start + self.speed * ctx.time[self.index]        # clip frames
            if isinstance(self.out, slice):
                self.bank.sample(self.clip_ids, t, out=ctx.poses[self.out])
            else:
                ctx.poses[self.out] = self.bank.sample(self.clip_ids, t)
            if not self.tagged.size:
                return
            t = t[self.tagged]
            active = ctx.weight[self.index[self.tagged]] > 0
            # A node that was not playing, or whose time went back, starts fresh:
            # tags exactly at its current time fire.
            prev = np.where(np.isnan(self.prev) | (self.prev > t), t - 1e-6, self.prev)
            self.prev = np.where(active, t, np.nan)
            if active.any():
                sel = self.tagged[active]
                which, tag = self.bank.crossings(self.clip_ids[sel], prev[active], t[active])
                if which.size:
                    ctx.emit(self.roots[sel[which]], self.bank.tag_name[tag])


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


# ------------------------------------------------------------------ state machine
class StateTransition:
    """A state machine edge.

    Parameters
    ----------
    source : state name, or ``"*"`` for any state.
    target : state name.
    duration : cross-fade length in frames (0 cuts).
    trigger : fire when this trigger is set on the stream (consumed).
    condition : ``(parameter, op, value)`` with op in ``< <= > >= == !=``; fires while
        true. A transition may have a trigger, a condition, or both (both must hold).
    """

    OPS = {"<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal,
           "==": np.equal, "!=": np.not_equal}

    def __init__(self, source, target, duration=8.0, trigger=None, condition=None):
        self.source, self.target = str(source), str(target)
        self.duration = float(duration)
        if not (np.isfinite(self.duration) and self.duration >= 0):
            raise CrowdError(f"state transition {source}->{target}: duration must be >= 0")
        if trigger is None and condition is None:
            raise CrowdError(f"state transition {source}->{target}: needs a trigger or a "
                             "condition")
        if condition is not None:
            if len(condition) != 3 or condition[1] not in self.OPS:
                raise CrowdError(f"state transition {source}->{target}: condition must be "
                                 f"(parameter, op, value) with op in {list(self.OPS)}")
        self.trigger = None if trigger is None else str(trigger)
        self.condition = None if condition is None else (str(condition[0]), condition[1],
                                                         float(condition[2]))

    def holds(self, params, triggers) -> bool:
        if self.trigger is not None and self.trigger not in triggers:
            return False
        if self.condition is not None:
            name, op, value = self.condition
            if name not in params or not self.OPS[op](params[name], value):
                return False
        return True


class StateMachine(Controller):
    """States (each a controller) and transitions fired by triggers and parameters.

    Entering a state restarts its subtree's time at 0. A transition cross-fades from
    the live pose of the state being left to the entered state over ``duration``
    frames; a transition that interrupts a cross-fade fades from a snapshot of the
    pose shown at that moment, so nothing pops. Triggers are consumed by the frame
    that sees them, fired or not.
    """

    def __init__(self, states: dict, transitions=(), initial: str | None = None):
        if not states:
            raise CrowdError("state machine: needs at least one state")
        self.state_names = tuple(str(s) for s in states)
        self.states = tuple(states.values())
        self.transitions = tuple(transitions)
        self.initial = self.state_names[0] if initial is None else str(initial)
        known = set(self.state_names)
        if self.initial not in known:
            raise CrowdError(f"state machine: unknown initial state {self.initial!r}")
        for tr in self.transitions:
            if tr.source != "*" and tr.source not in known:
                raise CrowdError(f"state machine: transition from unknown state "
                                 f"{tr.source!r}")
            if tr.target not in known:
                raise CrowdError(f"state machine: transition to unknown state {tr.target!r}")

    def children(self):
        return self.states

    class Batch(Batch):
        STATE = ("current", "source", "fading", "fade_t", "fade_len", "entered",
                 "src_entered", "snapshot", "has_snapshot")

        def check_state(self):
            n = np.array([len(nd.state_names) for nd in self.nodes])
            if ((self.current < 0) | (self.current >= n)).any() or \
                    ((self.source < -1) | (self.source >= n)).any():
                raise ValueError("a state machine's state is not one of its states")
            if not (self.fade_len > 0).all():
                raise ValueError("a state machine's fade length is not positive")

        def setup(self):
            n = len(self.nodes)
            self.current = np.array([nd.state_names.index(nd.initial) for nd in self.nodes])
            self.source = np.full(n, -1)          # state faded from (-1: snapshot)
            self.fading = np.zeros(n, bool)
            self.fade_t = np.zeros(n)
            self.fade_len = np.ones(n)
            self.entered = np.full(n, np.nan)     # node time at which current was entered
            self.src_entered = np.zeros(n)
            self.snapshot = sqt.identity_pose((n, self.bones))
            self.has_snapshot = np.zeros(n, bool)
            self.initial = self.current.copy()
            width = max(len(c) for c in self.child_index)
            self.kids = np.array([c + c[:1] * (width - len(c)) for c in self.child_index],
                                 np.int64)                   # (n, most states), padded
            self.all_kids = np.concatenate([np.asarray(c, np.int64) for c in self.child_index])
            self.rows = np.arange(n)

        def reset(self):
            self.setup()

        def state(self, i) -> str:
            return self.nodes[i].state_names[self.current[i]]

        def prepare(self, ctx):
            t = ctx.time[self.index]
            # first frame, or an enclosing state re-entered: start over
            restart = np.isnan(self.entered) | (t < self.entered)
            if restart.any():
                self.current[restart] = self.initial[restart]
                self.fading[restart] = False
                self.entered[restart] = t[restart]
            # every transition needs a trigger or a parameter: only nodes whose stream
            # has one set this frame can fire
            for i, (node, root) in enumerate(zip(self.nodes, self.roots)):
                params, triggers = ctx.params[root], ctx.triggers[root]
                if not (params or triggers):
                    continue
                cur = node.state_names[self.current[i]]
                for tr in node.transitions:
                    if tr.target == cur or tr.source not in ("*", cur):
                        continue
                    if tr.holds(params, triggers):
                        self._enter(i, node.state_names.index(tr.target), tr.duration, t[i],
                                    ctx)
                        break
            f = self.fading
            self.fade_t[f] = t[f] - self.entered[f]
            self.fading &= ~(f & (self.fade_t >= self.fade_len))
            current = self.kids[self.rows, self.current]
            ctx.local_weight[self.all_kids] = 0.0
            ctx.shift[current] = self.entered
            w = np.where(self.fading, np.minimum(self.fade_t / self.fade_len, 1.0), 1.0)
            ctx.local_weight[current] = w
            m = np.flatnonzero(self.fading & (self.source >= 0))
            if m.size:
                source = self.kids[m, self.source[m]]
                ctx.shift[source] = self.src_entered[m]
                ctx.local_weight[source] = 1.0 - w[m]

        def _enter(self, i, state, duration, now, ctx):
            if self.fading[i]:
                # interrupting a cross-fade: fade from the pose shown last frame
                self.snapshot[i] = ctx.poses[self.index[i]]
                self.source[i] = -1
            else:
                self.source[i] = self.current[i]
                self.src_entered[i] = self.entered[i]
            self.current[i] = state
            self.entered[i] = now
            self.fading[i] = duration > 0
            self.fade_len[i] = max(duration, 1e-9)
            self.fade_t[i] = 0.0

        def evaluate(self, ctx):
            out = ctx.poses[self.kids[self.rows, self.current]]
            fading = np.flatnonzero(self.fading)
            if fading.size:
                src_idx = self.kids[fading, np.maximum(self.source[fading], 0)]
                src = np.where((self.source[fading] >= 0)[:, None, None],
                               ctx.poses[src_idx], self.snapshot[fading])
                w = (self.fade_t[fading] / self.fade_len[fading]).astype(np.float32)
                out[fading] = sqt.blend2(src, out[fading], w)
            ctx.poses[self.out] = out
