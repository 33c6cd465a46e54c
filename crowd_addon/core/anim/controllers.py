"""Controller trees (paper s.3.4): nodes evaluated at time t into a local pose.

Authoring objects (:class:`ClipPlayer` here, :class:`~.blends.Blend2`,
:class:`~.blends.BlendMask`, :class:`~.blends.Layer`, :class:`~.blends.BlendSpace2D` in
:mod:`.blends`, :class:`~.state_machine.StateMachine` in :mod:`.state_machine`) describe a
tree. This module holds their base and batch protocol and the leaf kind. The
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

from ..base.errors import CrowdError

__all__ = ["Controller", "Batch", "ClipPlayer"]


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
