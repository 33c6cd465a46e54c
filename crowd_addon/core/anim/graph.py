"""Evaluation of controller trees in batches, and the frame's dependency graph.

:class:`TreeEvaluator` flattens the trees of all stream and unique roots into one
node array, groups nodes by (kind, group key, depth, height) and evaluates each
group with one :class:`~.controllers.Batch`: top-down ``prepare`` (times, weights,
state machines), then bottom-up ``evaluate`` (poses).

:class:`DependencyGraph` orders the frame's tasks (paper s.4.4-4.5): controller
batches have no dependency on other trees; a transition blend depends on its
target only when the target pose is not yet in history (offset 0, or a unique).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ..base import pose as sqt
from .controllers import Batch
from ..base.errors import CrowdError
from ..base.state import copy_state

__all__ = ["TreeEvaluator", "FrameContext", "DependencyGraph"]


class FrameContext:
    """Per-node frame arrays shared by all batches.

    Attributes
    ----------
    poses : (N, B, 10) float32, each node's latest pose (kept between frames).
    time : (N,) float64, node time in frames.
    shift : (N,) time subtracted from the parent's time (set by parents' prepare).
    local_weight : (N,) weight of a node in its parent's output.
    weight : (N,) effective weight in the root's output (product along the path).
    params, triggers : per root dict / set, from the simulation; ``triggered`` the roots
        whose trigger set is not empty (so a frame clears those only).
    """

    #: the per-node arrays a frame leaves behind (kept by snapshots)
    ARRAYS = ("poses", "time", "shift", "local_weight", "weight")

    def __init__(self, n_nodes, bones, n_roots):
        self.poses = sqt.identity_pose((n_nodes, bones))
        self.time = np.zeros(n_nodes)
        self.shift = np.zeros(n_nodes)
        self.local_weight = np.ones(n_nodes)
        self.weight = np.ones(n_nodes)
        self.params = [dict() for _ in range(n_roots)]
        self.triggers = [set() for _ in range(n_roots)]
        self.triggered = set()
        self._emit_roots = []
        self._emit_names = []

    def emit(self, roots: np.ndarray, names: np.ndarray) -> None:
        """Record event tags crossed this frame: (root index, tag name id) pairs."""
        self._emit_roots.append(np.asarray(roots, np.int64))
        self._emit_names.append(np.asarray(names, np.int64))

    def take_events(self):
        if not self._emit_roots:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        r = np.concatenate(self._emit_roots)
        n = np.concatenate(self._emit_names)
        self._emit_roots.clear()
        self._emit_names.clear()
        return r, n


class TreeEvaluator:
    """Evaluates many controller trees at once.

    Parameters
    ----------
    roots : sequence of (controller, skeleton) pairs.
    bank : ClipBank holding every clip the trees play.
    bones : pose row width in bones (B_max).
    """

    def __init__(self, roots, bank, bones):
        self.bank = bank
        self.bones = bones
        nodes, parent, depth, root_of, children, skels = [], [], [], [], [], []

        def visit(ctrl, par, d, r, sk):
            i = len(nodes)
            nodes.append(ctrl)
            parent.append(par)
            depth.append(d)
            root_of.append(r)
            skels.append(sk)
            children.append([])
            for c in ctrl.children():
                children[i].append(visit(c, i, d + 1, r, sk))
            return i

        root_index = [visit(c, -1, 0, r, sk) for r, (c, sk) in enumerate(roots)]
        n = len(nodes)
        height = np.zeros(n, np.int64)
        for i in reversed(range(n)):
            if children[i]:
                height[i] = 1 + max(height[c] for c in children[i])
        groups = defaultdict(list)
        for i, ctrl in enumerate(nodes):
            key_fn = getattr(type(ctrl), "group_key", None)
            key = (type(ctrl), key_fn(ctrl) if key_fn else None, depth[i], int(height[i]))
            groups[key].append(i)
        # renumber the nodes group by group, so each batch writes one contiguous range
        # of the frame arrays (a slice, not a scatter)
        old = [i for idx in groups.values() for i in idx]
        new = np.empty(n, np.int64)
        new[old] = np.arange(n)
        nodes = [nodes[i] for i in old]
        parent = [int(new[parent[i]]) if parent[i] >= 0 else -1 for i in old]
        depth = [depth[i] for i in old]
        root_of = [root_of[i] for i in old]
        skels = [skels[i] for i in old]
        children = [[int(new[c]) for c in children[i]] for i in old]
        height = height[old]
        groups = {key: [int(new[i]) for i in idx] for key, idx in groups.items()}
        self.root_index = new[np.asarray(root_index, np.int64)]
        self.nodes = nodes
        self.parent = np.array(parent, np.int64)
        self.depth = np.array(depth, np.int64)
        self.height = height
        self.batches = []
        for (cls, _, d, h), idx in groups.items():
            batch = cls.Batch([nodes[i] for i in idx], idx, [root_of[i] for i in idx],
                              [children[i] for i in idx], bank, bones,
                              [skels[i] for i in idx])
            batch.depth, batch.height = d, h
            self.batches.append(batch)
        self.prepare_order = sorted((b for b in self.batches
                                     if type(b).prepare is not Batch.prepare),
                                    key=lambda b: b.depth)
        self.evaluate_order = sorted(self.batches, key=lambda b: b.height)
        self.levels = []
        for d in range(1, int(self.depth.max()) + 1 if n else 1):
            idx = np.flatnonzero(self.depth == d)
            self.levels.append((d, idx, self.parent[idx]))
        self.ctx = FrameContext(n, bones, len(roots))
        taken = [set() for _ in roots]
        for ctrl, r in zip(nodes, root_of):
            taken[r].update(tr.trigger for tr in getattr(ctrl, "transitions", ())
                            if tr.trigger is not None)
        self._root_triggers = tuple(frozenset(t) for t in taken)

    def clip_entries(self, roots) -> list:
        """The clip bank entries the clip players of the trees ``roots`` (root indices)
        play, sorted."""
        from .controllers import ClipPlayer
        roots = {int(r) for r in roots}
        return sorted({int(e) for b in self.batches if isinstance(b, ClipPlayer.Batch)
                       for e, r in zip(b.clip_ids, b.roots) if int(r) in roots})

    def batches_for_roots(self, roots) -> list:
        """The batches whose nodes belong to any of the given roots."""
        roots = set(int(r) for r in roots)
        return [b for b in self.batches if roots.intersection(b.roots.tolist())]

    def reset(self):
        for b in self.batches:
            b.reset()

    def prepare(self, root_times: np.ndarray, root_weights: np.ndarray | None = None):
        """Top-down pass: node times, weights and state machines for this frame."""
        ctx = self.ctx
        ctx.time[self.root_index] = root_times
        ctx.weight[self.root_index] = 1.0 if root_weights is None else root_weights
        by_depth = defaultdict(list)
        for b in self.prepare_order:
            by_depth[b.depth].append(b)
        for b in by_depth.get(0, ()):
            b.prepare(ctx)
        for d, idx, par in self.levels:
            ctx.time[idx] = ctx.time[par] - ctx.shift[idx]
            ctx.weight[idx] = ctx.weight[par] * ctx.local_weight[idx]
            for b in by_depth.get(d, ()):
                b.prepare(ctx)
        for r in ctx.triggered:
            ctx.triggers[r].clear()
        ctx.triggered.clear()

    def evaluate(self, batches=None) -> None:
        """Bottom-up pass over the given batches (default all), children first."""
        for b in (self.evaluate_order if batches is None else batches):
            b.evaluate(self.ctx)

    def root_poses(self) -> np.ndarray:
        """(R, B, 10) float32 poses of the roots (a copy)."""
        return self.ctx.poses[self.root_index]

    def poses_ahead(self, root_times: np.ndarray) -> np.ndarray:
        """(R, B, 10) float32 root poses at ``root_times`` (e.g. between this frame and
        the next, for sub-frame samples) as the trees would show them from their
        present state, which is left exactly as it was (:meth:`state`: state machine
        states and fades, clip players' last times, the frame arrays, the triggers
        still to be consumed) with the events not yet taken. Tags crossed on the way
        are not reported."""
        saved = copy_state(self.state())
        emitted = len(self.ctx._emit_roots)
        try:
            self.prepare(root_times)
            self.evaluate()
            return self.root_poses()
        finally:
            self.set_state(saved)
            del self.ctx._emit_roots[emitted:], self.ctx._emit_names[emitted:]

    def state(self) -> dict:
        """Everything the trees carry from frame to frame (views; :mod:`.snapshot`
        copies): each batch's :data:`~.controllers.Batch.STATE` arrays (state machines'
        states and fades, clip players' last times), the frame arrays, parameters and
        triggers."""
        ctx = self.ctx
        return {"batches": {str(i): {k: getattr(b, k) for k in b.STATE}
                            for i, b in enumerate(self.batches) if b.STATE},
                "frame": {k: getattr(ctx, k) for k in FrameContext.ARRAYS},
                "params": [dict(p) for p in ctx.params],
                "triggers": [sorted(t) for t in ctx.triggers]}

    def set_state(self, state: dict):
        """Back to a :meth:`state` (the arrays are copied in)."""
        ctx = self.ctx
        for i, b in enumerate(self.batches):
            for k in b.STATE:
                getattr(b, k)[...] = state["batches"][str(i)][k]
            b.check_state()
        for k in FrameContext.ARRAYS:
            getattr(ctx, k)[...] = state["frame"][k]
        for params, v in zip(ctx.params, state["params"]):
            v = {str(n): float(x) for n, x in v.items()}
            if not all(np.isfinite(x) for x in v.values()):
                raise ValueError("a parameter is not finite")
            params.clear()
            params.update(v)
        for triggers, v in zip(ctx.triggers, state["triggers"]):
            triggers.clear()
            triggers.update(str(n) for n in v)
        ctx.triggered = {r for r, t in enumerate(ctx.triggers) if t}

    def set_parameter(self, root: int, name: str, value: float):
        """Set controller parameter ``name`` of tree ``root`` (finite values only)."""
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise CrowdError(f"parameter {name!r}: value must be a number, got "
                             f"{value!r}") from None
        if not np.isfinite(v):
            raise CrowdError(f"parameter {name!r}: value must be finite, got {value!r}")
        self.ctx.params[root][str(name)] = v

    def set_trigger(self, root: int, name: str):
        """Set trigger ``name`` on tree ``root``; the next prepare consumes it."""
        self.ctx.triggers[root].add(str(name))
        self.ctx.triggered.add(root)

    def triggers(self, root: int) -> frozenset:
        """The trigger names a state machine in tree ``root`` has a transition on (the
        triggers that can change what the tree plays)."""
        return self._root_triggers[root]

    def states(self, root: int) -> list:
        """Current state names of the state machines in tree ``root``."""
        out = []
        for b in self.batches:
            if hasattr(b, "state"):
                out += [b.state(i) for i in np.flatnonzero(b.roots == root)]
        return out


class DependencyGraph:
    """Tasks with dependencies, run in topological waves.

    A task is a name and a callable. ``waves()`` lists tasks whose dependencies are
    all in earlier waves; tasks in one wave are independent (a threaded executor
    could run them together; the crowd runs them in order on one core). The order is
    worked out once, when first needed after the last ``add``.
    """

    def __init__(self):
        self.tasks = {}
        self.deps = {}
        self._order = None

    def add(self, name, fn, after=()):
        unknown = set(after) - set(self.tasks)
        if unknown:
            raise ValueError(f"task {name!r} comes after unknown tasks {sorted(unknown)}")
        self.tasks[name] = fn
        self.deps[name] = set(after)
        self._order = None

    def waves(self) -> list:
        remaining = dict(self.deps)
        done, out = set(), []
        while remaining:
            ready = [t for t, d in remaining.items() if d <= done]
            out.append(ready)       # never empty: a task only follows tasks added before it
            done.update(ready)
            for t in ready:
                del remaining[t]
        return out

    def run(self) -> None:
        """Run every task once, wave by wave."""
        if self._order is None:
            self._order = [n for wave in self.waves() for n in wave]
        for name in self._order:
            self.tasks[name]()
