"""The crowd runtime: a small facade over the paper's parts, advanced one frame per
:meth:`Crowd.step`.

Parts (each its own module): :class:`~.pools.StreamPool` (streams and the pose
history ring) and :class:`~.pools.UniquePool`; :class:`~.agents.AgentState` (what
each agent plays, where it stands, who changed); :class:`~.transitions.TransitionSlots`
(slots, queue, the request policy); :func:`~.events.deliver` and
:class:`~.events.EventDispatcher`; the skinning mode (:mod:`.skinning_modes`);
:class:`~.pose_storage.PoseStorage` (the pose texture mirror). Renderers and writers
read :attr:`Crowd.view` (:class:`~.frame_view.FrameView`).

Frame ``F`` (paper s.4.2): queued requests take free slots; every stream root is
evaluated once and written to the history; uniques are evaluated (current pose
only); transition slots blend (those whose target is already in history first,
those that need this frame's target after it: the dependency graph of s.4.4-4.5);
the skinning mode writes the rows that changed; event tags reach the agents.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..base import pose as sqt
from ..runtime.agents import STREAM, TRANSITION, UNIQUE, AgentState
from ..meshes.bodies import crowd_bodies
from ..anim.clip import ClipBank
from ..authoring.config import MAX_SUBSTEPS, CrowdConfig, validate_config
from ..authoring.config_io import config_digest
from ..base.errors import CrowdError
from ..runtime.events import EventDispatcher, deliver
from ..runtime.frame_view import FrameView
from ..anim.graph import DependencyGraph, TreeEvaluator
from ..runtime.look_at import AgentLooks, LookChain, agent_lags, apply_look, look_turns
from ..runtime.pools import StreamPool, UniquePool
from ..authoring.show import ShowRunner
from ..base.skinning import SkinningPlan
from ..runtime.skinning_modes import skinning_mode
from .snapshot import Snapshot, SnapshotCache
from .snapshot import check as check_snapshot
from .snapshot import take as take_snapshot
from ..runtime.transitions import TransitionResult, TransitionSlots

__all__ = ["Crowd", "StepReport", "MAX_SUBSTEPS", "check_substeps"]


def check_substeps(substeps) -> int:
    """``substeps`` as an int in 1..:data:`MAX_SUBSTEPS` (CrowdError otherwise)."""
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) \
            or not 1 <= substeps <= MAX_SUBSTEPS:
        raise CrowdError(f"substeps must be a whole number of samples per frame, "
                         f"1..{MAX_SUBSTEPS}, got {substeps!r}")
    return int(substeps)


@dataclass(frozen=True)
class StepReport:
    frame: int
    ms: float
    upload_bytes: int
    transitions_active: int
    transitions_started: int
    transitions_finished: int
    events: int


class Crowd:
    """A running crowd built from a :class:`CrowdConfig` (validated here).

    Parameters
    ----------
    config : the CrowdConfig.
    skinning : ``"cpu"`` (the CPU writes skinning rows) or ``"gpu"`` (the CPU keeps
        local poses, a compute shader skins; also the mode for writers that need no
        skinning), see :mod:`.skinning_modes`.
    substeps : samples per frame kept for writers, 1..:data:`MAX_SUBSTEPS` (default 1:
        whole frames only). With ``N > 1`` each frame also evaluates every stream and
        unique at ``F + k / N`` (``k = 1 .. N - 1``) from the state reached at ``F``
        (:meth:`~.graph.TreeEvaluator.poses_ahead`, which changes nothing), and keeps
        the streams' for the last M frames like the history: ``agent_poses(sub=k)``
        is an agent's pose at ``F + k / N`` (sub-frame samples for motion blur).

    Attributes
    ----------
    frame : int, the last evaluated frame.
    streams, uniques, agents, slots, events, skinning, storage : the parts.
    view : FrameView, what renderers and writers read.
    """

    def __init__(self, config: CrowdConfig, skinning: str = "cpu", substeps: int = 1):
        self.substeps = check_substeps(substeps)
        uses = validate_config(config)
        cfg = self.config = config
        self.fps = float(cfg.fps)
        skel_names = list(cfg.skeletons)
        self.skeletons = [cfg.skeletons[n] for n in skel_names]
        self.bones = max(s.bone_count for s in self.skeletons)
        defs = list(cfg.streams) + list(cfg.uniques)
        skel = np.array([skel_names.index(d.skeleton) for d in defs], np.int64)
        # clips play at their own rate and in each skeleton's bone order
        self.bank = ClipBank(list(cfg.clips.values()), self.bones, fps=self.fps,
                             uses=[(clip, cfg.skeletons[sk]) for sk, names in uses.items()
                                   for clip in names])
        self.evaluator = TreeEvaluator([(d.root, cfg.skeletons[d.skeleton]) for d in defs],
                                       self.bank, self.bones)
        self.plans = [SkinningPlan(s, self.bones) for s in self.skeletons]
        self.skinning = skinning_mode(skinning)
        m, s, u = int(cfg.max_offset), len(cfg.streams), len(cfg.uniques)
        self._stream_speed = np.array([d.speed for d in cfg.streams], np.float64)
        self._stream_phase = np.array([d.phase for d in cfg.streams], np.float64)
        self.storage = self.skinning.storage(s, m, u, int(cfg.transition_slots), self.bones,
                                             cfg.max_texture_size)
        self.streams = StreamPool([d.name for d in cfg.streams], skel[:s], m,
                                  self.skinning.history(self.storage, (m, s, self.bones,
                                                                       sqt.WIDTH)),
                                  self.bank.tag_names)
        self.uniques = UniquePool([d.name for d in cfg.uniques], skel[s:],
                                  self.skinning.unique_poses(self.storage,
                                                             (u, self.bones, sqt.WIDTH)),
                                  key_base=self.streams.key_count)
        n = self.substeps - 1
        self._sub_streams = np.zeros((m, n, s, self.bones, sqt.WIDTH), np.float32)
        self._sub_uniques = np.zeros((n, u, self.bones, sqt.WIDTH), np.float32)
        self.agents = AgentState(cfg.agent_position, cfg.agent_heading, cfg.agent_color,
                                 cfg.scales, cfg.palette)
        self.slots = TransitionSlots(int(cfg.transition_slots), self.bones, self.agents,
                                     cfg.when_full, begin=self._begin_transitions)
        self.agents.index_by(self._agent_keys)
        st = np.asarray(cfg.agent_stream, np.int64)
        self.agent_skeleton = np.where(st >= 0, skel[np.clip(st, 0, None)],
                                       skel[s + np.asarray(cfg.agent_unique, np.int64)]
                                       if u else 0).astype(np.int64)
        self._bodies = None
        self.events = EventDispatcher()
        self.view = FrameView(self)
        self.skinning.bind(self)
        self._build_graph()
        # look-at (core/runtime/look_at.py): a chain per skeleton with a look rig, the targets
        self._look_chains = [LookChain(cfg.look_rigs[name], sk) if name in cfg.look_rigs
                             else None for name, sk in zip(skel_names, self.skeletons)]
        self.look_target_names = tuple(cfg.look_targets)
        self._look_targets = tuple(cfg.look_targets.values())
        self._look_lags = agent_lags(cfg.agent_offset, cfg.look_lag, cfg.look_max_lag,
                                     cfg.seed)
        self.looks = AgentLooks(self.agents.count)
        self.show = ShowRunner(cfg.show, self) if cfg.show else None
        self.snapshots = None          # a SnapshotCache once keep_snapshots() is called
        self._quiet = 0                # > 0 inside step/reset/restore: not a user's change
        self._outside = []             # frames of changes made from outside a step
        self.reset(cfg.start_frame)

    # ---------------------------------------------------------------- dependency graph
    def _build_graph(self):
        g = DependencyGraph()
        g.add("transitions.partition", self._partition_transitions)
        g.add("transitions.ready", lambda: self._blend("ready"),
              after=["transitions.partition"])
        names = []
        for i, b in enumerate(self.evaluator.evaluate_order):
            name = f"controllers.{type(b).__qualname__.split('.')[0]}@{b.height}#{i}"
            lower = [n for n, bb in zip(names, self.evaluator.evaluate_order)
                     if bb.height < b.height]
            g.add(name, (lambda b=b: b.evaluate(self.evaluator.ctx)), after=lower)
            names.append(name)
        g.add("roots.store", self._store_roots, after=names)
        g.add("transitions.waiting", lambda: self._blend("waiting"),
              after=["transitions.partition", "roots.store"])
        g.add("transitions.finish", self._finish_transitions,
              after=["transitions.ready", "transitions.waiting"])
        g.add("skinning", self.skinning.slots_blended,
              after=["roots.store", "transitions.finish"])
        g.add("events", lambda: self._deliver_events(True),
              after=["roots.store", "transitions.finish"])
        self.graph = g

    # ---------------------------------------------------------------------- state
    def reset(self, frame: int | None = None):
        """Start over at ``frame``: history filled by evaluating the streams at frames
        ``frame - M + 1 .. frame`` (so every offset is valid at once), agents back to
        their configured references, slots and queue empty. Deterministic."""
        cfg = self.config
        f0 = cfg.start_frame if frame is None else int(frame)
        self._replay_from(f0)
        self._origin = f0
        self._quiet += 1
        try:
            self._reset(f0)
        finally:
            self._quiet -= 1

    def _reset(self, f0):
        cfg = self.config
        self.looks.reset()
        if self.show is not None:
            self.show.reset()
        self.evaluator.reset()
        for params, triggers in zip(self.evaluator.ctx.params, self.evaluator.ctx.triggers):
            params.clear()             # a reset crowd is a new crowd: no leftover parameters
            triggers.clear()
        self.evaluator.ctx.triggered.clear()
        if self.show is not None:
            self.show.apply_tracks(f0, triggers=False)
        self.slots.release(np.arange(self.slots.count))
        self.slots.queue.clear()
        self.slots.served = self.slots.cuts = 0
        st = np.asarray(cfg.agent_stream)
        self.agents.reset(np.where(st >= 0, STREAM, UNIQUE),
                          np.where(st >= 0, st, cfg.agent_unique), cfg.agent_offset)
        self.uniques.start[:] = f0 - self.streams.max_offset + 1
        self.streams.clear_events()
        self.events.fired.clear()          # counts since the last reset, like stats
        self.events.calls.clear()
        self._events_fired = 0
        self._steps, self._ms_total = 0, 0.0
        for f in range(f0 - self.streams.max_offset + 1, f0 + 1):
            self.frame = f
            self.evaluator.prepare(self._root_times(f))
            self.evaluator.evaluate()
            self._store_roots()
            self._store_substeps()
            self._deliver_events(dispatch=(f == f0))
        self.storage.take_dirty_regions()
        self.storage.mark_dirty(0, self.storage.row_count)
        self.skinning.reset()

    # ------------------------------------------------------------------ snapshots
    @property
    def config_digest(self) -> str:
        """SHA-256 of the configuration (:func:`~.config_io.config_digest`), worked out
        at the first call: what a snapshot names the crowd it belongs to by."""
        if getattr(self, "_digest", None) is None:
            self._digest = config_digest(self.config)
        return self._digest

    def snapshot(self) -> Snapshot:
        """An exact copy of the state now (:mod:`.snapshot`): :meth:`restore` it into
        this crowd or any crowd built from the same configuration and every later
        frame's poses and events equal this run's. ``snapshot().save(path)`` writes it
        to a file, :func:`~.snapshot.load_snapshot` reads it."""
        return take_snapshot(self)

    def restore(self, snapshot: Snapshot):
        """Go back (or forward) to ``snapshot``'s frame and state. A snapshot of
        another configuration or sample count, or a damaged one, raises CrowdError
        naming what differs, and changes nothing. Callbacks stay registered."""
        check_snapshot(self, snapshot)
        before = take_snapshot(self)        # a value the checks cannot see: roll back
        self._quiet += 1
        try:
            try:
                self._set_state(snapshot.state())
            except Exception as e:  # noqa: BLE001 - any fault of the snapshot's values
                self._set_state(before.state())
                raise CrowdError(f"snapshot of frame {snapshot.frame} cannot be restored: "
                                 f"{type(e).__name__}: {e}; the crowd is as it was") from e
        finally:
            self._quiet -= 1
        self._replay_from(snapshot.frame)
        self._changed()                     # its run may not be the one kept

    def _state(self) -> dict:
        """Every part's state (views), what :mod:`.snapshot` copies."""
        return {"crowd": {"frame": int(self.frame), "origin": int(self._origin),
                          "steps": self._steps,
                          "ms_total": self._ms_total, "sub_streams": self._sub_streams,
                          "sub_uniques": self._sub_uniques},
                "streams": self.streams.state(), "uniques": self.uniques.state(),
                "agents": self.agents.state(), "slots": self.slots.state(),
                "evaluator": self.evaluator.state(), "events": self.events.state(),
                "looks": self.looks.state(),
                **({"show": self.show.state()} if self.show is not None else {})}

    def _set_state(self, state: dict):
        c = state["crowd"]
        self.frame, self._origin = int(c["frame"]), int(c["origin"])
        self._steps, self._ms_total = int(c["steps"]), float(c["ms_total"])
        self._sub_streams[...] = c["sub_streams"]
        self._sub_uniques[...] = c["sub_uniques"]
        self.streams.set_state(state["streams"])
        self.uniques.set_state(state["uniques"])
        self.slots.set_state(state["slots"])
        self.agents.set_state(state["agents"])        # after the slots: it regroups by target
        self.evaluator.set_state(state["evaluator"])
        self.events.set_state(state["events"])
        self.looks.set_state(state["looks"], len(self._look_targets))
        if self.show is not None:
            self.show.set_state(state["show"])
        self._check_state()
        self._events_fired = 0
        self.skinning.restored()

    def _check_state(self):
        """Raise ValueError unless what agents, slots, the queue and the event log refer
        to exists (restored values the shape checks cannot see)."""
        a, sl, q = self.agents, self.slots, self.slots.queue
        s, u, m, n = self.streams.count, self.uniques.count, self.streams.max_offset, a.count

        def refs_ok(kind, ref, off):
            return bool(np.all(np.where(kind == STREAM, (ref >= 0) & (ref < s) & (off >= 0)
                                        & (off < m), (kind == UNIQUE) & (ref >= 0)
                                        & (ref < u))))
        tr = a.kind == TRANSITION
        slot = np.where(tr, a.ref, 0)
        if not (np.isin(a.kind, (STREAM, UNIQUE, TRANSITION)).all()
                and refs_ok(a.kind[~tr], a.ref[~tr], a.offset[~tr])
                and ((slot >= 0) & (slot < max(sl.count, 1))).all()):
            raise ValueError("an agent plays a stream, unique or slot that does not exist")
        if tr.any() and not (sl.active[slot[tr]].all()
                             and (sl.agent[slot[tr]] == np.flatnonzero(tr)).all()):
            raise ValueError("an agent's transition slot is not its own")
        act = sl.active_slots()
        if not (((sl.agent[act] >= 0) & (sl.agent[act] < n)).all()
                and refs_ok(sl.target_kind[act], sl.target_ref[act], sl.target_offset[act])
                and (sl.length[act] >= 1).all()):
            raise ValueError("a transition slot targets what does not exist")
        wait = np.flatnonzero(q._ticket >= 0)
        line = q._line[:, q._head:q._tail]
        if not (refs_ok(q._kind[wait], q._ref[wait], q._offset[wait])
                and (q._length[wait] >= 1).all() and wait.size == len(q)
                and ((line[1] >= 0) & (line[1] < n)).all()):
            raise ValueError("the transition queue holds a request that cannot be")
        log = self.streams.state()
        if not (((log["log_stream"] >= 0) & (log["log_stream"] < s)).all()
                and ((log["log_name"] >= 0) & (log["log_name"]
                                               < len(self.bank.tag_names))).all()):
            raise ValueError("the event log names a stream or tag that does not exist")

    def _agent_keys(self, agents):
        """Event/index key of what each agent plays (a transition's target)."""
        kind, ref, off = self._playing(agents)
        return np.where(kind == STREAM, self.streams.key(ref, off), self.uniques.key(ref))

    def playing(self, agents):
        """(kind, ref, offset) arrays: what each agent plays, a transition resolved to
        its target (``kind`` STREAM or UNIQUE, see :mod:`.agents`)."""
        return self._playing(self.agents.ids(agents))

    def _playing(self, agents):
        """(kind, ref, offset) each agent plays, a transition resolved to its target."""
        a = self.agents
        kind, ref, off = (a.kind[agents].astype(np.int64), a.ref[agents].copy(),
                          a.offset[agents].copy())
        tr = kind == TRANSITION
        if tr.any():
            k = ref[tr]
            kind[tr] = self.slots.target_kind[k]
            ref[tr] = self.slots.target_ref[k]
            off[tr] = self.slots.target_offset[k]
        return kind, ref, off

    # ----------------------------------------------------------------------- step
    def step(self) -> StepReport:
        """Advance one frame and return what it cost (with :meth:`keep_snapshots`, a
        frame on the snapshot grid is kept after the step; that copy is not counted)."""
        self._quiet += 1
        try:
            report = self._step()
        finally:
            self._quiet -= 1
        if self.snapshots is not None and self._origin == self.config.start_frame \
                and self.snapshots.wants(self.frame, self._origin):
            self.snapshots.add(self.snapshot(), self._origin)
        return report

    def _step(self) -> StepReport:
        t_start = time.perf_counter()
        mark = self.storage.mark()
        if self.show is not None:
            self.show.before_step(self.frame + 1)
        started = self.slots.serve_queue()
        self.frame += 1
        self._finished = 0
        self._events_fired = 0
        self.evaluator.prepare(self._root_times(self.frame))
        self.graph.run()
        self._store_substeps()
        ms = (time.perf_counter() - t_start) * 1e3
        self._steps += 1
        self._ms_total += ms
        return StepReport(self.frame, ms, self.storage.bytes_since(mark),
                          int(self.slots.active.sum()), started, self._finished,
                          self._events_fired)

    @property
    def stats(self) -> dict:
        """Since the last reset: ``steps``, ``ms_total`` (step time), ``transitions_served``
        (slots given), ``cuts`` (agents switched without a blend)."""
        return {"steps": self._steps, "ms_total": self._ms_total,
                "transitions_served": self.slots.served, "cuts": self.slots.cuts}

    def advance_to(self, frame: int):
        """Step to ``frame``. Going backwards resets and re-simulates from the start;
        with :meth:`keep_snapshots` a jump either way starts instead from the nearest
        kept snapshot before ``frame`` when that is nearer than where the crowd is, so
        it steps at most ``snapshots.every`` frames (at least one: the frame reached is
        stepped, so its events fire as on any frame change).

        ``frame`` is a whole number of magnitude at most :data:`~.bounds.MAX_FRAME`, and
        one call steps at most :data:`~.bounds.MAX_RUN_FRAMES` frames (from where the
        run starts: this frame, the snapshot it jumps from, or the start frame when it
        goes back). Both are checked before anything changes (CrowdError naming the
        bound and how to split the run)."""
        from ..base.bounds import MAX_RUN_FRAMES, check_run, whole_frame
        frame = whole_frame(frame, "advance_to")
        start = self.config.start_frame
        snap = self.jump_snapshot(frame)
        # where the run starts: the snapshot, or here, or the frame reset to (going
        # back); a replay below only drops snapshots after the one jumped from
        origin = snap.frame if snap is not None else \
            self.frame if frame >= self.frame else min(start, frame)
        check_run("advance_to", origin, frame,
                  f"advance_to({origin + MAX_RUN_FRAMES}) first, then on from there, each "
                  "call at most that many frames further")
        if frame < self.frame and self._outside:   # replayed from there: changes lost
            self._replay_from(snap.frame if snap is not None else start)
            snap = self.jump_snapshot(frame)
        if snap is not None:
            self._quiet += 1
            try:
                self._set_state(snap.state())        # one of our own: already checked
            finally:
                self._quiet -= 1
        elif frame < self.frame:
            self.reset(start if frame >= start else frame)
        while self.frame < frame:
            self.step()

    def jump_snapshot(self, frame: int):
        """The kept snapshot :meth:`advance_to` would start from to reach ``frame``
        (None when it steps on from here or resets)."""
        if self.snapshots is None or frame <= self.config.start_frame:
            return None
        snap = self.snapshots.nearest(int(frame) - 1)
        if snap is None or not (frame < self.frame or snap.frame > self.frame):
            return None
        return snap

    def keep_snapshots(self, every: int = 30, max_bytes: int = 2 << 30):
        """Keep a :class:`~.snapshot.SnapshotCache` of this run (a snapshot every
        ``every`` frames from the start frame, at most ``max_bytes`` in all), which
        :meth:`advance_to` jumps from; returns it. ``every=None`` stops keeping them.
        A change made from outside a step (a request, a parameter, a trigger, a move,
        a restore) forgets the snapshots past the current frame; going back before it
        forgets those taken after it, since a replay does not make that change again
        (so a jump shows what a re-simulation from the start shows)."""
        self.snapshots = None if every is None else SnapshotCache(every, max_bytes)
        self._outside = []
        if self.snapshots is not None and self._origin == self.config.start_frame \
                and self.snapshots.wants(self.frame, self._origin):
            self.snapshots.add(self.snapshot(), self._origin)
        return self.snapshots

    def _changed(self):
        """The run changes here (not replayed by a re-simulation): later snapshots go."""
        if self._quiet == 0 and self.snapshots is not None:
            self.snapshots.drop_after(self.frame)
            self._outside.append(self.frame)

    def _replay_from(self, frame):
        """The run is replayed from ``frame``: changes made from outside a step at or
        after it are not made again, so the snapshots taken after the first of them
        go."""
        lost = [f for f in self._outside if f >= frame]
        if lost and self.snapshots is not None:
            self.snapshots.drop_after(min(lost))
        self._outside = [f for f in self._outside if f < frame]

    def _root_times(self, frame, sub=0.0):
        """Root times at ``frame + sub``: a stream's ``phase + speed * t``
        (:class:`~.config.AnimationDef`), a unique's own clock."""
        t = float(frame) + sub
        return np.concatenate([self._stream_phase + self._stream_speed * t,
                               self.uniques.times(frame) + sub])

    def _store_roots(self):
        poses = self.evaluator.ctx.poses[self.evaluator.root_index]
        self.streams.store(self.frame, poses[:self.streams.count])
        self.uniques.poses[:] = poses[self.streams.count:]
        self.skinning.roots_stored(self.frame)

    def _store_substeps(self):
        """The streams' and uniques' poses at ``frame + k / N`` from the state reached
        now (nothing without substeps)."""
        n, s = self.substeps, self.streams.count
        for k in range(1, n):
            times = self._root_times(self.frame, k / n)
            poses = self.evaluator.poses_ahead(times)
            self._sub_streams[self.streams.slice(self.frame), k - 1] = poses[:s]
            self._sub_uniques[k - 1] = poses[s:]

    def _deliver_events(self, dispatch):
        """Deliver this frame's tags (during the history warm-up: only log them)."""
        roots, names = self.evaluator.ctx.take_events()
        self._events_fired += deliver(self.frame, roots, names, self.streams, self.uniques,
                                      self.agents.index, self.events if dispatch else None,
                                      self.bank.tag_names)

    # ---------------------------------------------------------------- transitions
    def _partition_transitions(self):
        self._tr, self._s = self.slots.partition(), {}

    def _blend(self, which):
        self._s[which] = self.skinning.blend(self._tr[which], self.frame)

    def _finish_transitions(self):
        self._finished = self.slots.finish(
            np.concatenate([self._tr["ready"], self._tr["waiting"]]),
            np.concatenate([self._s["ready"], self._s["waiting"]]))

    def _begin_transitions(self, slots, agents, kind, ref, offsets, length):
        """``agents`` enter ``slots`` now: StartP is the pose they show."""
        start = self._current_poses(agents)
        self.skinning.slot_starting(slots, agents, start)
        self.slots.start(slots, agents, kind, ref, offsets, length, start, self.frame)

    def transition_to_streamed(self, agents, stream, duration, offset=None,
                               when_full=None) -> TransitionResult:
        """Blend agents to ``stream`` (a name or index, or one stream index per agent)
        at ``offset`` (default: each agent's own offset) over ``duration`` frames (0
        switches at once)."""
        self._changed()
        agents = self.agents.ids(agents)
        length, policy = self.slots.check_request(duration, when_full)
        if np.ndim(stream) == 0:
            s = self.streams.index(stream)
        else:
            s = np.asarray(stream).reshape(-1)
            if s.shape != agents.shape or (s.size and s.dtype.kind not in "iu"):
                raise CrowdError(f"transition: per-agent streams must be {agents.size} stream "
                                 f"indices, got {s.dtype} {s.shape}")
            if s.size and (s.min() < 0 or s.max() >= self.streams.count):
                raise CrowdError(f"transition: stream index out of range 0.."
                                 f"{self.streams.count - 1}")
        off = self.agents.offset[agents].copy() if offset is None else \
            self.streams.offsets_for(offset, agents.size)
        self._check_skeleton(agents, self.streams.skeleton[s], self.streams.names, s)
        return self.slots.request(agents, STREAM, s, off, length, policy)

    def transition_to_unique(self, agents, unique, duration, restart=True,
                             when_full=None) -> TransitionResult:
        """Blend agents to unique animation ``unique`` over ``duration`` frames; with
        ``restart`` its clock restarts so it plays from its beginning next frame."""
        self._changed()
        agents = self.agents.ids(agents)
        length, policy = self.slots.check_request(duration, when_full)
        u = self.uniques.index(unique)
        self._check_skeleton(agents, self.uniques.skeleton[u], self.uniques.names, u)
        if restart and agents.size:
            self.uniques.restart(u, self.frame + 1)
        return self.slots.request(agents, UNIQUE, u, self.agents.offset[agents].copy(),
                                  length, policy)

    def _check_skeleton(self, agents, skeleton, names, ref):
        bad = np.flatnonzero(self.agent_skeleton[agents] != skeleton)
        if bad.size:
            name = names[int(np.broadcast_to(ref, agents.shape)[bad[0]])]
            raise CrowdError(f"agent {int(agents[bad[0]])}: cannot transition to "
                             f"{name!r}, it uses another skeleton")

    # ------------------------------------------------------------------ agents
    @property
    def bodies(self) -> tuple:
        """``(bodies, agent_body)`` of :func:`~.bodies.crowd_bodies`, made on first use
        (agents keep their bodies for the crowd's life)."""
        if self._bodies is None:
            self._bodies = crowd_bodies(self.config, self.agent_skeleton)
        return self._bodies

    def place_agents(self, agents, position=None, heading=None, color=None):
        """Move, turn or recolour agents (see :meth:`AgentState.place`)."""
        self._changed()
        self.agents.place(self.agents.ids(agents), position, heading, color)

    def _sub_poses(self, agents, k):
        """Local poses ``(n, B, 10)`` the agents show at ``self.frame + k / N`` (``k`` in
        1..N-1): what they play now, at that time (a transition's weight too)."""
        out = np.empty((agents.size, self.bones, sqt.WIDTH), np.float32)
        kind, ref, off = (self.agents.kind[agents], self.agents.ref[agents],
                          self.agents.offset[agents])
        slot = np.where(kind == TRANSITION, ref, 0)
        tr = kind == TRANSITION
        kind = np.where(tr, self.slots.target_kind[slot], kind)
        ref = np.where(tr, self.slots.target_ref[slot], ref)
        off = np.where(tr, self.slots.target_offset[slot], off)
        m = kind == STREAM
        out[m] = self._sub_streams[self.streams.slice(self.frame, off[m]), k - 1, ref[m]]
        m = kind == UNIQUE
        out[m] = self._sub_uniques[k - 1, ref[m]]
        if tr.any():
            s = slot[tr]
            w = np.clip((self.frame + k / self.substeps - self.slots.t0[s])
                        / self.slots.length[s], 0.0, 1.0)
            out[tr] = sqt.blend2(self.slots.start_pose[s], out[tr], w.astype(np.float32))
        return out

    def _current_poses(self, agents):
        """Local poses ``(n, B, 10)`` the agents show at ``self.frame``."""
        out = np.empty((agents.size, self.bones, sqt.WIDTH), np.float32)
        kind, ref, off = (self.agents.kind[agents], self.agents.ref[agents],
                          self.agents.offset[agents])
        m = kind == STREAM
        out[m] = self.streams.poses(self.frame, ref[m], off[m])
        m = kind == UNIQUE
        out[m] = self.uniques.poses[ref[m]]
        m = kind == TRANSITION
        if m.any():
            out[m] = self.skinning.slot_poses(ref[m])
        return out

    def agent_poses(self, agents=None, sub: int = 0) -> np.ndarray:
        """Local poses ``(n, B, 10)`` float32 of the agents now, or at ``frame + sub / N``
        (``sub`` in 0..substeps-1)."""
        agents = np.arange(self.agents.count) if agents is None else self.agents.ids(agents)
        if sub == 0:
            return self._current_poses(agents)
        return self._sub_poses(agents, self._check_sub(sub))

    def _check_sub(self, sub) -> int:
        if isinstance(sub, bool) or not isinstance(sub, (int, np.integer)) \
                or not 0 <= sub < self.substeps:
            raise CrowdError(f"sub-frame sample must be 0..{self.substeps - 1} (the crowd "
                             f"keeps {self.substeps} per frame), got {sub!r}")
        return int(sub)

    def sub_stream_poses(self, frame: int, sub: int) -> np.ndarray:
        """``(S, B, 10)`` copy of every stream head at ``frame + sub / N`` (``frame`` one
        of the last M frames, ``sub`` in 1..N-1)."""
        self.streams.head_poses(frame, self.frame)          # checks the frame
        return self._sub_streams[self.streams.slice(frame), self._check_sub(sub) - 1].copy()

    def sub_unique_poses(self, sub: int) -> np.ndarray:
        """``(U, B, 10)`` copy of every unique at ``frame + sub / N`` (``sub`` 1..N-1)."""
        return self._sub_uniques[self._check_sub(sub) - 1].copy()

    def agent_rows_index(self, agents=None) -> np.ndarray:
        """Logical pose texture row each agent reads at ``self.frame`` (the shader's rule)."""
        agents = np.arange(self.agents.count) if agents is None else self.agents.ids(agents)
        kind, ref = self.agents.kind[agents], self.agents.ref[agents]
        return np.where(kind == STREAM,
                        self.streams.row(self.frame, ref, self.agents.offset[agents]),
                        np.where(kind == UNIQUE, self.storage.unique_base + ref,
                                 self.storage.slot_base + ref))

    def agent_rows(self, agents=None) -> np.ndarray:
        """Skinning rows ``(n, B, 3, 4)`` float32 the agents are drawn with now, their
        looks applied (:meth:`look_at`; the CPU reference of the look stage)."""
        ids = np.arange(self.agents.count) if agents is None else self.agents.ids(agents)
        rows = self.skinning.rows(self.agent_rows_index(ids))
        w = self.looks.weights(self.frame, ids)
        if not (w > 0).any():
            return rows
        for sk, chain in enumerate(self._look_chains):
            pick = np.flatnonzero((w > 0) & (self.agent_skeleton[ids] == sk))
            if chain is None or not pick.size:
                continue
            a = ids[pick]
            turns = look_turns(rows[pick], chain, self.look_targets_model(a), w[pick])
            rows[pick] = apply_look(rows[pick], chain, turns).astype(rows.dtype)
        return rows

    def look_targets_model(self, agents) -> np.ndarray:
        """(n, 3) where ``agents`` (looking at something) see their target now, in
        their model space: the target's smoothed path read ``lag`` frames late,
        the agent's position, heading and scale undone."""
        a = self.agents.ids(agents)
        out = np.zeros((a.size, 3))
        for t, target in enumerate(self._look_targets):
            m = self.looks.target[a] == t
            if m.any():
                out[m] = target.at(self.frame - self._look_lags[a[m]])
        d = out - self.agents.position[a]
        h = -self.agents.heading[a].astype(np.float64)
        c, s = np.cos(h), np.sin(h)
        local = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], 1)
        return local / self.agents.scale[a, None]

    def look_at(self, agents, target, blend: float = 8.0, hold: int = 0):
        """``agents`` turn their heads toward look target ``target`` (a name of
        ``config.look_targets``) from the next frame, blending in over ``blend``
        frames, and look away again ``hold`` frames later (0: they keep looking).
        Agents whose character has no look rig are left out; CrowdError names what is
        wrong, before anything changes."""
        ids = self.can_look(agents)
        if target not in self.look_target_names:
            raise CrowdError(f"look_at: unknown look target {target!r} (targets: "
                             f"{list(self.look_target_names)})")
        blend, hold = self._look_blend(blend), int(hold)
        if hold < 0:
            raise CrowdError(f"look_at: hold must be >= 0 frames, got {hold}")
        self._changed()
        self.looks.look(ids, self.look_target_names.index(target), self.frame + 1, blend,
                        hold)

    def look_away(self, agents, blend: float = 8.0):
        """``agents`` turn back to their animation over ``blend`` frames from the next
        frame."""
        ids, blend = self.can_look(agents), self._look_blend(blend)
        self._changed()
        self.looks.look_away(ids, self.frame + 1, blend)

    def can_look(self, agents) -> np.ndarray:
        """The ids of ``agents`` whose character has a look rig."""
        ids = self.agents.ids(agents)
        rigged = np.array([c is not None for c in self._look_chains], bool)
        return ids[rigged[self.agent_skeleton[ids]]]

    @staticmethod
    def _look_blend(blend) -> float:
        try:
            b = float(blend)
        except (TypeError, ValueError):
            raise CrowdError(f"look: blend must be a number of frames, got {blend!r}") \
                from None
        if not (np.isfinite(b) and 0 <= b <= 2 ** 31 - 1):
            raise CrowdError(f"look: blend must be 0 .. 2**31 - 1 frames, got {blend!r}")
        return b

    def pose(self, stream, offset: int = 0) -> np.ndarray:
        """``PH_stream(offset)``: the local pose ``(B, 10)`` the head had ``offset`` frames ago."""
        s = self.streams.index(stream)
        self.streams.check_offsets(np.array([offset]), "pose")
        return self.streams.poses(self.frame, s, int(offset)).copy()

    def stream_rows(self, stream, offset: int = 0) -> np.ndarray:
        """Pose texture rows ``(B, 3, 4)`` of ``PH_stream(offset)``."""
        s = self.streams.index(stream)
        self.streams.check_offsets(np.array([offset]), "pose")
        return self.skinning.rows(np.array([self.streams.row(self.frame, s, int(offset))]))[0]

    # --------------------------------------------------------------- parameters
    def _root(self, target) -> int:
        if isinstance(target, str) and target in self.uniques.names:
            return self.streams.count + self.uniques.index(target)
        if isinstance(target, str) and target not in self.streams.names:
            raise CrowdError(f"unknown stream or unique {target!r}")
        return self.streams.index(target)

    def set_parameter(self, target, name: str, value: float):
        """Set a controller parameter on a stream (name or index) or unique (name)."""
        self._changed()
        self.evaluator.set_parameter(self._root(target), name, value)

    def set_trigger(self, target, name: str):
        """Set a trigger on a stream or unique; the next frame's state machines consume it."""
        self._changed()
        self.evaluator.set_trigger(self._root(target), name)

    def state_of(self, target) -> list:
        """Current state names of the state machines in a stream's or unique's tree."""
        return self.evaluator.states(self._root(target))

    def on_event(self, name, fn) -> int:
        """Register ``fn(name, frame, agent_ids)`` for event tag ``name`` (``"*"``: all);
        returns a handle (``crowd.events.off(handle)``). A name that is not a non-empty
        string or an ``fn`` that cannot be called is a CrowdError, and nothing is
        registered."""
        return self.events.on(name, fn)
