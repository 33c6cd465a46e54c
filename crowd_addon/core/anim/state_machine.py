"""The state machine controller kind (paper s.3.4): :class:`StateMachine`, states (each a
controller) with :class:`StateTransition` edges fired by triggers and parameters, and its
batch evaluator (:mod:`.controllers`' protocol): cross-fades, interrupted ones from a
snapshot of the pose shown.
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from ..base.errors import CrowdError
from .controllers import Batch, Controller

__all__ = ["StateMachine", "StateTransition"]


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
