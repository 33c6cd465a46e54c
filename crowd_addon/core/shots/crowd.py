"""The crowd runtime: a small facade over the paper's parts, advanced one frame per
:meth:`Crowd.step`.

Parts (each its own module): :class:`~.pools.StreamPool` (streams and the pose
history ring) and :class:`~.pools.UniquePool`; :class:`~.agents.AgentState` (what
each agent plays, where it stands, who changed); :class:`~.transitions.TransitionSlots`
(slots, queue, the request policy); :func:`~.events.deliver` and
:class:`~.events.EventDispatcher`; the skinning mode (:mod:`.skinning_modes`);
:class:`~.pose_storage.PoseStorage` (the pose texture mirror). Renderers and writers
read :attr:`Crowd.view` (:class:`~.frame_view.FrameView`). The frame's tasks are in
:mod:`.frame`, the look stage in :mod:`.looks`, the poses agents show in
:mod:`.agent_poses`, the state a snapshot keeps in :mod:`.crowd_state` and moving
through frames (``advance_to``, snapshots kept) in :mod:`.scrub`.
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from ..runtime.agent_poses import SubSamples, current_poses
from ..runtime.agents import STREAM, TRANSITION, UNIQUE, AgentState
from ..meshes.bodies import crowd_bodies
from ..anim.clip import ClipBank
from ..authoring.config import MAX_SUBSTEPS, CrowdConfig, validate_config
from ..authoring.config_io import config_digest
from ..base.errors import CrowdError
from ..runtime.events import EventDispatcher
from ..runtime.frame_view import FrameView
from ..anim.graph import TreeEvaluator
from ..runtime.looks import LookStage, turn_rows
from ..runtime.pools import StreamPool, UniquePool
from .show_runner import ShowRunner
from ..base.skinning import SkinningPlan
from ..runtime.skinning_modes import skinning_mode
from . import crowd_state
from .snapshot import Snapshot
from .frame import Frame, StepReport
from .scrub import Scrub
from ..runtime.transitions import TransitionResult, TransitionSlots

__all__ = ["Crowd", "MAX_SUBSTEPS", "check_substeps"]


def check_substeps(substeps) -> int:
    """``substeps`` as an int in 1..:data:`MAX_SUBSTEPS` (CrowdError otherwise)."""
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) \
            or not 1 <= substeps <= MAX_SUBSTEPS:
        raise CrowdError(f"substeps must be a whole number of samples per frame, "
                         f"1..{MAX_SUBSTEPS}, got {substeps!r}")
    return int(substeps)


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
        self.subs = SubSamples(self.substeps, m, s, u, self.bones)
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
        self.frame_tasks = Frame(self, [d.speed for d in cfg.streams],
                                 [d.phase for d in cfg.streams])
        # streams at another speed than 1 move on a sub-frame grid (.anim.sub_keys)
        self.bank.resample(self.evaluator.clip_entries(self.frame_tasks.gridded))
        self.graph = self.frame_tasks.graph
        self.look = LookStage(cfg, skel_names, self.skeletons)       # look-at (.looks)
        self.looks, self.look_target_names = self.look.looks, self.look.target_names
        self.show = ShowRunner(cfg.show, self) if cfg.show else None
        self.scrub = Scrub(self)       # snapshots kept, changes from outside a step
        self.reset(cfg.start_frame)

    # ---------------------------------------------------------------------- state
    def reset(self, frame: int | None = None):
        """Start over at ``frame``: history filled by evaluating the streams at frames
        ``frame - M + 1 .. frame`` (so every offset is valid at once), agents back to
        their configured references, slots and queue empty. Deterministic."""
        cfg = self.config
        f0 = cfg.start_frame if frame is None else int(frame)
        self.scrub.replay_from(f0)
        self._origin = f0
        with self.scrub.inside():
            self._reset(f0)

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
        self.frame_tasks.warm_up(f0)
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
        return crowd_state.take(self)

    def restore(self, snapshot: Snapshot):
        """Go back (or forward) to ``snapshot``'s frame and state. A snapshot of
        another configuration or sample count, or a damaged one, raises CrowdError
        naming what differs, and changes nothing. Callbacks stay registered."""
        crowd_state.restore(self, snapshot)
        self.scrub.replay_from(snapshot.frame)
        self._changed()                     # its run may not be the one kept

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
        with self.scrub.inside():
            report = self.frame_tasks.step()
        self.scrub.stepped()
        return report

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
        self.scrub.advance_to(frame)

    def jump_snapshot(self, frame: int):
        """The kept snapshot :meth:`advance_to` would start from to reach ``frame``
        (None when it steps on from here or resets)."""
        return self.scrub.jump_snapshot(frame)

    def keep_snapshots(self, every: int = 30, max_bytes: int = 2 << 30):
        """Keep a :class:`~.snapshot_store.SnapshotCache` of this run (a snapshot every
        ``every`` frames from the start frame, at most ``max_bytes`` in all), which
        :meth:`advance_to` jumps from; returns it. ``every=None`` stops keeping them.
        A change made from outside a step (a request, a parameter, a trigger, a move,
        a restore) forgets the snapshots past the current frame; going back before it
        forgets those taken after it, since a replay does not make that change again
        (so a jump shows what a re-simulation from the start shows)."""
        return self.scrub.keep(every, max_bytes)

    @property
    def snapshots(self):
        """The :class:`~.snapshot_store.SnapshotCache` kept (None: none kept)."""
        return self.scrub.snapshots

    def _changed(self):
        """The run changes here (not replayed by a re-simulation)."""
        self.scrub.changed()

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

    def _current_poses(self, agents):
        """Local poses ``(n, B, 10)`` the agents show at ``self.frame``."""
        return current_poses(agents, self.frame, self.agents, self.streams, self.uniques,
                             self.skinning)

    def agent_poses(self, agents=None, sub: int = 0) -> np.ndarray:
        """Local poses ``(n, B, 10)`` float32 of the agents now, or at ``frame + sub / N``
        (``sub`` in 0..substeps-1)."""
        agents = np.arange(self.agents.count) if agents is None else self.agents.ids(agents)
        if sub == 0:
            return self._current_poses(agents)
        return self.subs.agent_poses(agents, self.subs.check(sub), self.frame, self.agents,
                                     self.slots, self.streams)

    def sub_stream_poses(self, frame: int, sub: int) -> np.ndarray:
        """``(S, B, 10)`` copy of every stream head at ``frame + sub / N`` (``frame`` one
        of the last M frames, ``sub`` in 1..N-1)."""
        self.streams.head_poses(frame, self.frame)          # checks the frame
        return self.subs.streams[self.streams.slice(frame), self.subs.check(sub) - 1].copy()

    def sub_unique_poses(self, sub: int) -> np.ndarray:
        """``(U, B, 10)`` copy of every unique at ``frame + sub / N`` (``sub`` 1..N-1)."""
        return self.subs.uniques[self.subs.check(sub) - 1].copy()

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
        return turn_rows(rows, self.agent_skeleton[ids], self.looks.weights(self.frame, ids),
                         self.look.chains, lambda pick: self.look_targets_model(ids[pick]))

    def look_targets_model(self, agents) -> np.ndarray:
        """(n, 3) where ``agents`` (looking at something) see their target now, in
        their model space: the target's smoothed path read ``lag`` frames late,
        the agent's position, heading and scale undone."""
        return self.look.targets_model(self.agents.ids(agents), self.frame, self.agents)

    def look_at(self, agents, target, blend: float = 8.0, hold: int = 0):
        """``agents`` turn their heads toward look target ``target`` (a name of
        ``config.look_targets``) from the next frame, blending in over ``blend``
        frames, and look away again ``hold`` frames later (0: they keep looking).
        Agents whose character has no look rig are left out; CrowdError names what is
        wrong, before anything changes."""
        ids = self.can_look(agents)
        t, blend, hold = self.look.check_look(target, blend, hold)
        self._changed()
        self.looks.look(ids, t, self.frame + 1, blend, hold)

    def look_away(self, agents, blend: float = 8.0):
        """``agents`` turn back to their animation over ``blend`` frames from the next
        frame."""
        ids, blend = self.can_look(agents), self.look.check_blend(blend)
        self._changed()
        self.looks.look_away(ids, self.frame + 1, blend)

    def can_look(self, agents) -> np.ndarray:
        """The ids of ``agents`` whose character has a look rig."""
        return self.look.rigged(self.agents.ids(agents), self.agent_skeleton)

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
