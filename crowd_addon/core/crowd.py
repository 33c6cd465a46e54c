"""The crowd runtime: StreamPool with pose history, UniquePool, agents, transitions,
events, and the pose texture, advanced one frame per :meth:`Crowd.step`.

Frame ``F`` (paper s.4.2): every stream root is evaluated once and written to
history slice ``F mod M``; uniques are evaluated (current pose only); transition
slots blend (those whose target is already in history first, those that need this
frame's target after it: the dependency graph of s.4.4-4.5); local poses become
skinning rows for exactly the rows that changed (on the CPU, or with
``gpu_skinning`` on the GPU from the local poses); event tags crossed by the stream
heads ``O`` frames ago call back for the agents at offset ``O``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from . import pose as sqt
from .agents import STREAM, TRANSITION, UNIQUE, AgentIndex, check_offsets
from .clip import ClipBank
from .config import CrowdConfig
from .errors import CrowdError
from .events import EventDispatcher
from .graph import DependencyGraph, TreeEvaluator
from .pose_storage import LOCAL_IDENTITY, PoseStorage
from .skinning import SkinningPlan
from .transitions import POLICIES, TransitionResult, TransitionSlots

__all__ = ["Crowd", "StepReport", "GpuSkinningBatch"]


@dataclass(frozen=True)
class GpuSkinningBatch:
    """Pose texture rows the GPU writes (``gpu_skinning``); all ``(n,)``.

    Row ``rows[i]`` of the pose texture becomes the skinning rows of the local pose
    ``blend(local[rows[i]], local[sources[i]], weights[i])`` (``local`` = the local-pose
    texture, ``storage``) of skeleton ``skeletons[i]``. A stream or unique row is its
    own source with weight 1; a transition slot row blends its StartP towards the
    target's row by ``S`` (paper s.4.5).

    ``rows``, ``sources`` int32 logical rows; ``weights`` float32; ``skeletons`` int32
    indices into ``Crowd.skeletons``.
    """

    rows: np.ndarray
    sources: np.ndarray
    weights: np.ndarray
    skeletons: np.ndarray

    def __len__(self) -> int:
        return int(self.rows.size)


@dataclass(frozen=True)
class StepReport:
    frame: int
    ms: float
    upload_bytes: int
    transitions_active: int
    transitions_started: int
    transitions_finished: int
    events: int


class _View:
    """What a controller may look up while it is validated."""

    def __init__(self, cfg, skeleton):
        self.cfg, self.skeleton = cfg, skeleton

    def clip(self, name):
        try:
            return self.cfg.clips[name]
        except KeyError:
            raise CrowdError(f"unknown clip {name!r} (known: {sorted(self.cfg.clips)})") \
                from None


class Crowd:
    """A running crowd built from a :class:`CrowdConfig` (validated here).

    Attributes
    ----------
    frame : int, the last evaluated frame.
    history : (M, S, B, 10) float32 local-pose ring of the streams.
    unique_poses : (U, B, 10) float32 current poses of the uniques.
    storage : PoseStorage, the texture the CPU keeps and uploads, with its dirty rows:
        the pose texture of skinning rows, or with ``gpu_skinning`` the local-pose
        texture (``history`` and ``unique_poses`` are then views of it, and slot rows
        hold each transition's StartP).
    agent_kind, agent_ref, agent_offset : (N,) agent animation references.
    events : EventDispatcher.
    gpu_skinning : bool. When true the GPU turns local poses into skinning rows and
        blends the transition slots (paper s.4.5): the CPU only evaluates the
        streams and uniques into ``storage`` (uploading 10 of 12 floats a bone
        instead of a 3x4 matrix) and :meth:`gpu_skinning_batch` says which rows the
        GPU must write. Agent poses and rows asked for on the CPU (``agent_poses``,
        ``agent_rows``, ``stream_rows``) are still exact.
    """

    def __init__(self, config: CrowdConfig, gpu_skinning: bool = False):
        cfg = config
        self.config = cfg
        self._validate(cfg)
        self.M = int(cfg.max_offset)
        self.S = len(cfg.streams)
        self.U = len(cfg.uniques)
        self.NT = int(cfg.transition_slots)
        self.fps = float(cfg.fps)
        self.when_full = cfg.when_full
        skel_names = list(cfg.skeletons)
        self.skeletons = [cfg.skeletons[n] for n in skel_names]
        self.B = max(s.bone_count for s in self.skeletons)
        defs = list(cfg.streams) + list(cfg.uniques)
        self.names = [d.name for d in defs]
        self.root_skeleton = np.array([skel_names.index(d.skeleton) for d in defs], np.int64)
        self.bank = ClipBank(list(cfg.clips.values()), self.B)
        self.evaluator = TreeEvaluator([(d.root, cfg.skeletons[d.skeleton]) for d in defs],
                                       self.bank, self.B)
        self.plans = [SkinningPlan(s, self.B) for s in self.skeletons]
        self.gpu_skinning = bool(gpu_skinning)
        self.storage = PoseStorage(self.S, self.M, self.U, self.NT, self.B,
                                   cfg.max_texture_size,
                                   fill=LOCAL_IDENTITY if self.gpu_skinning else None)
        if self.gpu_skinning:
            local = self.storage.sqt_view()
            self.history = local[:self.storage.unique_base].reshape(
                self.M, self.S, self.B, sqt.WIDTH)
            self.unique_poses = local[self.storage.unique_base:self.storage.slot_base]
            self._slot_start_rows = local[self.storage.slot_base:]
            rows = np.arange(self.storage.slot_base)
            self._row_skeleton = self.root_skeleton[
                np.where(rows < self.storage.unique_base, rows % max(self.S, 1),
                         self.S + rows - self.storage.unique_base)].astype(np.int32)
        else:
            self.history = sqt.identity_pose((self.M, self.S, self.B))
            self.unique_poses = sqt.identity_pose((self.U, self.B))
        self._skin_pending = []
        self.unique_start = np.zeros(self.U, np.int64)
        self.slots = TransitionSlots(self.NT, self.B)
        self.events = EventDispatcher()
        n = cfg.agent_count
        self.N = n
        # copies: a crowd may move its agents without touching the configuration
        self.agent_position = np.array(cfg.agent_position, np.float32)
        self.agent_heading = np.array(cfg.agent_heading, np.float32)
        self.agent_color = np.array(cfg.agent_color, np.float32)
        self._stream_skel_groups = self._groups(self.root_skeleton[:self.S])
        self._unique_skel_groups = self._groups(self.root_skeleton[self.S:])
        self._build_graph()
        self.reset(cfg.start_frame)

    # ------------------------------------------------------------------ validation
    @staticmethod
    def _validate(cfg):
        if not cfg.skeletons:
            raise CrowdError("crowd: needs at least one skeleton")
        if not cfg.streams and not cfg.uniques:
            raise CrowdError("crowd: needs at least one stream or unique animation")
        if int(cfg.max_offset) < 1:
            raise CrowdError(f"crowd: max offset M must be >= 1, got {cfg.max_offset}")
        if int(cfg.transition_slots) < 0:
            raise CrowdError(f"crowd: transition slots NT must be >= 0, got "
                             f"{cfg.transition_slots}")
        if not (np.isfinite(cfg.fps) and cfg.fps > 0):
            raise CrowdError(f"crowd: fps must be positive, got {cfg.fps}")
        if cfg.when_full not in POLICIES:
            raise CrowdError(f"crowd: when_full must be one of {POLICIES}, got "
                             f"{cfg.when_full!r}")
        for name, sk in cfg.skeletons.items():
            if sk.name != name:
                raise CrowdError(f"crowd: skeleton stored as {name!r} is named {sk.name!r}")
        for name, clip in cfg.clips.items():
            if clip.name != name:
                raise CrowdError(f"crowd: clip stored as {name!r} is named {clip.name!r}")
        seen = set()
        for pool, defs in (("stream", cfg.streams), ("unique", cfg.uniques)):
            for i, d in enumerate(defs):
                if d.name in seen:
                    raise CrowdError(f"crowd: duplicate animation name {d.name!r}")
                seen.add(d.name)
                if d.skeleton not in cfg.skeletons:
                    raise CrowdError(f"{pool} {d.name!r}: unknown skeleton {d.skeleton!r}")
                sk = cfg.skeletons[d.skeleton]
                view = _View(cfg, sk)
                stack = [d.root]
                while stack:
                    node = stack.pop()
                    try:
                        node.validate(view)
                    except CrowdError as e:
                        raise CrowdError(f"{pool} {d.name!r}: {e}") from None
                    stack.extend(node.children())
        n = cfg.agent_offset.shape[0]
        for field_name in ("agent_stream", "agent_unique"):
            if getattr(cfg, field_name).shape != (n,):
                raise CrowdError(f"crowd: {field_name} has shape "
                                 f"{getattr(cfg, field_name).shape}, expected ({n},)")
        for field_name, shape in (("agent_position", (n, 3)), ("agent_heading", (n,)),
                                  ("agent_color", (n, 3))):
            arr = np.asarray(getattr(cfg, field_name))
            if arr.shape != shape or not np.isfinite(arr).all():
                raise CrowdError(f"crowd: {field_name} must be finite {shape}, got {arr.shape}")
        check_offsets(cfg.agent_offset, int(cfg.max_offset))
        st, un = np.asarray(cfg.agent_stream), np.asarray(cfg.agent_unique)
        both = (st >= 0) == (un >= 0)
        if both.any():
            a = int(np.flatnonzero(both)[0])
            raise CrowdError(f"agent {a}: needs exactly one of a stream or a unique "
                             f"(stream {st[a]}, unique {un[a]})")
        bad = np.flatnonzero(st >= len(cfg.streams))
        if bad.size:
            raise CrowdError(f"agent {int(bad[0])}: unknown stream index {st[bad[0]]} "
                             f"({len(cfg.streams)} streams)")
        bad = np.flatnonzero(un >= len(cfg.uniques))
        if bad.size:
            raise CrowdError(f"agent {int(bad[0])}: unknown unique index {un[bad[0]]} "
                             f"({len(cfg.uniques)} uniques)")

    @staticmethod
    def _groups(skel_of):
        """(skeleton, indices, contiguous slice or None) per skeleton in ``skel_of``."""
        out = []
        for k in np.unique(skel_of):
            idx = np.flatnonzero(skel_of == k)
            contiguous = idx.size and idx[-1] - idx[0] + 1 == idx.size
            out.append((int(k), idx, slice(int(idx[0]), int(idx[-1]) + 1) if contiguous
                        else None))
        return out

    # ---------------------------------------------------------------- dependency graph
    def _build_graph(self):
        g = DependencyGraph()
        g.add("transitions.partition", self._partition_transitions)
        g.add("transitions.ready", self._transitions_ready, after=["transitions.partition"])
        names = []
        for i, b in enumerate(self.evaluator.evaluate_order):
            name = f"controllers.{type(b).__qualname__.split('.')[0]}@{b.height}#{i}"
            lower = [n for n, bb in zip(names, self.evaluator.evaluate_order)
                     if bb.height < b.height]
            g.add(name, (lambda b=b: b.evaluate(self.evaluator.ctx)), after=lower)
            names.append(name)
        g.add("roots.store", self._store_roots, after=names)
        g.add("transitions.waiting", self._transitions_waiting,
              after=["transitions.partition", "roots.store"])
        g.add("transitions.finish", self._finish_transitions,
              after=["transitions.ready", "transitions.waiting"])
        g.add("skinning", self._skin_changed_rows, after=["roots.store", "transitions.finish"])
        g.add("events", self._dispatch_events, after=["roots.store", "transitions.finish"])
        self.graph = g
        self._order = [n for wave in g.waves() for n in wave]

    # ---------------------------------------------------------------------- state
    def reset(self, frame: int | None = None):
        """Start over at ``frame``: history filled by evaluating the streams at frames
        ``frame - M + 1 .. frame`` (so every offset is valid at once), agents back to
        their configured references, slots and queue empty. Deterministic."""
        cfg = self.config
        f0 = cfg.start_frame if frame is None else int(frame)
        self.evaluator.reset()
        st = np.asarray(cfg.agent_stream)
        self.agent_kind = np.where(st >= 0, STREAM, UNIQUE).astype(np.int8)
        self.agent_ref = np.where(st >= 0, st, cfg.agent_unique).astype(np.int64)
        self.agent_offset = np.asarray(cfg.agent_offset, np.int64).copy()
        self.index = AgentIndex(self._agent_keys(np.arange(self.N)))
        self.slots = TransitionSlots(self.NT, self.B)
        self.unique_start[:] = f0 - self.M + 1
        self._log_stream = np.zeros(0, np.int64)
        self._log_name = np.zeros(0, np.int64)
        self._log_frame = np.zeros(0, np.int64)
        self._unique_hits = (np.zeros(0, np.int64), np.zeros(0, np.int64))
        self._events_fired = 0
        self.stats = {"steps": 0, "ms_total": 0.0, "transitions_served": 0, "cuts": 0}
        for f in range(f0 - self.M + 1, f0 + 1):
            self.frame = f
            self._evaluate_roots(f)
            self._store_roots()
            self._skin_changed_rows()
            self._collect_events(dispatch=(f == f0))
        self.storage.take_dirty_regions()
        self.storage.mark_dirty(0, self.storage.row_count)
        self._skin_pending = [(0, self.storage.slot_base)]

    def _playing(self, agents):
        """(kind, ref, offset) each agent plays, a transition resolved to its target."""
        kind = self.agent_kind[agents].astype(np.int64)
        ref = self.agent_ref[agents].copy()
        off = self.agent_offset[agents].copy()
        tr = kind == TRANSITION
        if tr.any():
            k = ref[tr]
            kind[tr] = self.slots.target_kind[k]
            ref[tr] = self.slots.target_ref[k]
            off[tr] = self.slots.target_offset[k]
        return kind, ref, off

    def _agent_keys(self, agents):
        """Event/index key of what each agent plays (a transition's target)."""
        kind, ref, off = self._playing(agents)
        return np.where(kind == STREAM, ref * self.M + off, self.S * self.M + ref)

    # ----------------------------------------------------------------------- step
    def step(self) -> StepReport:
        """Advance one frame and return what it cost."""
        t_start = time.perf_counter()
        mark = self.storage.mark()
        started = self._serve_queue()
        self.frame += 1
        self._finished = 0
        self._events_fired = 0
        self._evaluate_roots_prepare(self.frame)
        for name in self._order:
            self.graph.tasks[name]()
        ms = (time.perf_counter() - t_start) * 1e3
        self.stats["steps"] += 1
        self.stats["ms_total"] += ms
        upload = self.storage.bytes_since(mark)
        return StepReport(self.frame, ms, upload,
                          int(self.slots.active.sum()), started, self._finished,
                          self._events_fired)

    def advance_to(self, frame: int):
        """Step (or reset and re-simulate when going backwards) to ``frame``."""
        if frame < self.frame:
            self.reset(self.config.start_frame if frame >= self.config.start_frame else frame)
        while self.frame < frame:
            self.step()

    def _root_times(self, frame):
        t = np.empty(self.S + self.U)
        t[:self.S] = frame
        t[self.S:] = frame - self.unique_start
        return t

    def _evaluate_roots_prepare(self, frame):
        self.evaluator.prepare(self._root_times(frame))

    def _evaluate_roots(self, frame):
        self._evaluate_roots_prepare(frame)
        self.evaluator.evaluate()

    def _store_roots(self):
        poses = self.evaluator.ctx.poses[self.evaluator.root_index]
        self.history[self.frame % self.M] = poses[:self.S]
        self.unique_poses[:] = poses[self.S:]

    # ---------------------------------------------------------------- transitions
    def _partition_transitions(self):
        act = self.slots.active_slots()
        later = (self.slots.target_kind[act] != STREAM) | (self.slots.target_offset[act] == 0)
        self._tr_ready = act[~later]
        self._tr_waiting = act[later]

    def _transitions_ready(self):
        self._s_ready = self._blend_slots(self._tr_ready)

    def _transitions_waiting(self):
        self._s_waiting = self._blend_slots(self._tr_waiting)

    def _blend_slots(self, slots):
        """Blend ``slots`` on the CPU, or with GPU skinning only compute ``S`` (the
        CPU pose is then blended on demand by :meth:`_current_poses`)."""
        if self.gpu_skinning:
            return self.slots.weights(slots, self.frame)
        return self.slots.evaluate(slots, self.frame, self.history, self.M, self.unique_poses)

    def _finish_transitions(self):
        slots = np.concatenate([self._tr_ready, self._tr_waiting])
        s = np.concatenate([self._s_ready, self._s_waiting])
        done = slots[s >= 1.0]
        if done.size:
            agents = self.slots.agent[done]
            self.agent_kind[agents] = self.slots.target_kind[done]
            self.agent_ref[agents] = self.slots.target_ref[done]
            st = self.slots.target_kind[done] == STREAM
            self.agent_offset[agents[st]] = self.slots.target_offset[done[st]]
            self.slots.release(done)
            self.index.set(agents, self._agent_keys(agents))
        self._finished = int(done.size)

    def _current_poses(self, agents):
        """Local poses ``(n, B, 10)`` the agents show at ``self.frame``."""
        out = np.empty((agents.size, self.B, sqt.WIDTH), np.float32)
        kind, ref = self.agent_kind[agents], self.agent_ref[agents]
        m = kind == STREAM
        out[m] = self.history[(self.frame - self.agent_offset[agents[m]]) % self.M, ref[m]]
        m = kind == UNIQUE
        out[m] = self.unique_poses[ref[m]]
        m = kind == TRANSITION
        if m.any():
            if self.gpu_skinning:           # slots are blended on the GPU: do these here
                self.slots.evaluate(np.unique(ref[m]), self.frame, self.history, self.M,
                                    self.unique_poses)
            out[m] = self.slots.pose[ref[m]]
        return out

    def agent_rows_index(self, agents=None) -> np.ndarray:
        """Logical pose texture row each agent reads at ``self.frame`` (the shader's rule)."""
        agents = np.arange(self.N) if agents is None else self._check_agents(agents)
        kind, ref = self.agent_kind[agents], self.agent_ref[agents]
        stream_row = ((self.frame - self.agent_offset[agents]) % self.M) * self.S + ref
        return np.where(kind == STREAM, stream_row,
                        np.where(kind == UNIQUE, self.storage.unique_base + ref,
                                 self.storage.slot_base + ref))

    def agent_rows(self, agents=None) -> np.ndarray:
        """Skinning rows ``(n, B, 3, 4)`` float32 the agents are drawn with now."""
        agents = np.arange(self.N) if agents is None else self._check_agents(agents)
        index = self.agent_rows_index(agents)
        if not self.gpu_skinning:
            return self.storage.rows[index]
        # the skinning rows live on the GPU: skin each distinct row once, here
        used, inverse = np.unique(index, return_inverse=True)
        return self._skin_logical_rows(used)[inverse.reshape(-1)]

    def _skin_logical_rows(self, rows) -> np.ndarray:
        """Skinning rows ``(n, B, 3, 4)`` of logical pose texture ``rows`` (GPU skinning
        mode): the local poses of stream/unique rows, blended slots."""
        st = self.storage
        out = np.zeros((rows.size, self.B, 3, 4), np.float32)
        local = st.sqt_view()
        is_slot = rows >= st.slot_base
        poses = np.empty((rows.size, self.B, sqt.WIDTH), np.float32)
        poses[~is_slot] = local[rows[~is_slot]]
        skel = np.empty(rows.size, np.int64)
        skel[~is_slot] = self._row_skeleton[rows[~is_slot]]
        if is_slot.any():
            slots = rows[is_slot] - st.slot_base
            self.slots.evaluate(slots, self.frame, self.history, self.M, self.unique_poses)
            poses[is_slot] = self.slots.pose[slots]
            kind, ref = self.slots.target_kind[slots], self.slots.target_ref[slots]
            skel[is_slot] = self.root_skeleton[np.where(kind == STREAM, ref, self.S + ref)]
        for k in np.unique(skel):
            out[skel == k] = self.plans[k].rows(poses[skel == k])
        return out

    def gpu_skinning_batch(self) -> GpuSkinningBatch:
        """The pose texture rows the GPU must write now (``gpu_skinning``): every
        stream and unique row whose local pose changed since the last call (the new
        history slice and the uniques after a step; everything after a reset) and
        every active transition slot. Call it after uploading ``take_upload_regions``."""
        if not self.gpu_skinning:
            raise CrowdError("gpu_skinning_batch: this crowd skins on the CPU (create it "
                             "with Crowd(config, gpu_skinning=True))")
        ranges = PoseStorage._merged(self._skin_pending)
        self._skin_pending = []
        own = np.concatenate([np.arange(a, a + n, dtype=np.int64) for a, n in ranges]) \
            if ranges else np.zeros(0, np.int64)
        act = self.slots.active_slots()
        kind = self.slots.target_kind[act]
        ref = self.slots.target_ref[act]
        target = self.slots.target_rows(act, self.frame, self.S, self.M,
                                        self.storage.unique_base)
        slot_rows = self.storage.slot_base + act
        return GpuSkinningBatch(
            np.concatenate([own, slot_rows]).astype(np.int32),
            np.concatenate([own, target]).astype(np.int32),
            np.concatenate([np.ones(own.size), self.slots.weights(act, self.frame)]
                           ).astype(np.float32),
            np.concatenate([self._row_skeleton[own],
                            self.root_skeleton[np.where(kind == STREAM, ref, self.S + ref)]]
                           ).astype(np.int32))

    def stream_events(self, since_frame: int):
        """Event tags the stream heads crossed at frames ``>= since_frame`` (at most the
        last M frames are kept): ``(stream, name, frame)`` arrays, in crossing order.

        These are the crossings agents at offset ``O`` receive ``O`` frames later;
        exporters write them as the streams' event tags.
        """
        keep = self._log_frame >= int(since_frame)
        names = np.asarray(self.bank.tag_names, object)
        return (self._log_stream[keep].copy(), names[self._log_name[keep]],
                self._log_frame[keep].copy())

    def agent_poses(self, agents=None) -> np.ndarray:
        """Local poses ``(n, B, 10)`` float32 of the agents now."""
        agents = np.arange(self.N) if agents is None else self._check_agents(agents)
        return self._current_poses(agents)

    def _check_agents(self, agents) -> np.ndarray:
        """Agent ids as a flat int64 array; any shape is accepted and flattened."""
        a = np.asarray(agents).reshape(-1)
        if a.size and not np.issubdtype(a.dtype, np.integer):
            raise CrowdError(f"agent ids must be integers, got {a.dtype}")
        a = a.astype(np.int64)
        bad = np.flatnonzero((a < 0) | (a >= self.N))
        if bad.size:
            raise CrowdError(f"agent id {int(a[bad[0]])} out of range 0..{self.N - 1}")
        return a

    def _resolve(self, target, pool):
        names = self.names[:self.S] if pool == "stream" else self.names[self.S:]
        count = self.S if pool == "stream" else self.U
        if isinstance(target, str):
            if target not in names:
                raise CrowdError(f"unknown {pool} {target!r} (known: {names})")
            return names.index(target)
        if isinstance(target, (int, np.integer)) and 0 <= int(target) < count:
            return int(target)
        raise CrowdError(f"unknown {pool} index {target!r} ({count} {pool}s)")

    def transition_to_streamed(self, agents, stream, duration, offset=None,
                               when_full=None) -> TransitionResult:
        """Blend agents to ``stream`` at ``offset`` (default: each agent's own offset)
        over ``duration`` frames (0 switches at once)."""
        agents = self._check_agents(agents)
        length, policy = self._check_request(duration, when_full)
        s = self._resolve(stream, "stream")
        if offset is None:
            off = self.agent_offset[agents].copy()
        else:
            off = np.asarray(offset).reshape(-1)
            if off.size not in (1, agents.size):
                raise CrowdError(f"transition: {off.size} offsets for {agents.size} agents")
            check_offsets(off, self.M, "transition")
            off = np.broadcast_to(off, agents.shape).astype(np.int64)
        self._check_skeleton(agents, s)
        return self._request(agents, STREAM, s, off, length, policy)

    def transition_to_unique(self, agents, unique, duration, restart=True,
                             when_full=None) -> TransitionResult:
        """Blend agents to unique animation ``unique`` over ``duration`` frames; with
        ``restart`` its clock restarts so it plays from its beginning next frame."""
        agents = self._check_agents(agents)
        length, policy = self._check_request(duration, when_full)
        u = self._resolve(unique, "unique")
        self._check_skeleton(agents, self.S + u)
        if restart:
            self.unique_start[u] = self.frame + 1
        return self._request(agents, UNIQUE, u, self.agent_offset[agents].copy(), length,
                             policy)

    def _check_skeleton(self, agents, root):
        skel = self.root_skeleton[self._agent_root(agents)]
        bad = np.flatnonzero(skel != self.root_skeleton[root])
        if bad.size:
            raise CrowdError(f"agent {int(agents[bad[0]])}: cannot transition to "
                             f"{self.names[root]!r}, it uses another skeleton")

    def _agent_root(self, agents):
        kind, ref, _ = self._playing(agents)
        return np.where(kind == STREAM, ref, self.S + ref)

    def _check_request(self, duration, when_full):
        """(length in whole frames, policy) of a request, validated."""
        policy = self.when_full if when_full is None else when_full
        if policy not in POLICIES:
            raise CrowdError(f"transition: when_full must be one of {POLICIES}, got "
                             f"{policy!r}")
        try:
            d = float(duration)
        except (TypeError, ValueError):
            raise CrowdError(f"transition: duration must be a number of frames, got "
                             f"{duration!r}") from None
        if not (np.isfinite(d) and d >= 0):
            raise CrowdError(f"transition: duration must be >= 0 frames, got {duration!r}")
        return int(round(d)), policy

    def _request(self, agents, kind, ref, offsets, length, policy):
        agents, first = np.unique(agents, return_index=True)
        offsets = offsets[first]
        for a in agents.tolist():
            self.slots.queue.pop(a, None)
        if length == 0:
            self._cut(agents, kind, ref, offsets)
            empty = np.zeros(0, np.int64)
            return TransitionResult(empty, empty, empty, agents)
        # agents already blending reuse their slot
        in_slot = self.agent_kind[agents] == TRANSITION
        reuse_agents = agents[in_slot]
        reuse_slots = self.agent_ref[reuse_agents]
        rest = agents[~in_slot]
        free = self.slots.free_slots()
        take = min(free.size, rest.size)
        new_agents, new_slots = rest[:take], free[:take]
        overflow = rest[take:]
        all_agents = np.concatenate([reuse_agents, new_agents])
        all_slots = np.concatenate([reuse_slots, new_slots]).astype(np.int64)
        order = np.searchsorted(agents, all_agents)
        self._start_slots(all_slots, all_agents, kind, ref, offsets[order], length,
                          self.frame)
        queued = cut = np.zeros(0, np.int64)
        if overflow.size:
            ov_off = offsets[np.searchsorted(agents, overflow)]
            if policy == "queue":
                for a, o in zip(overflow.tolist(), ov_off.tolist()):
                    self.slots.queue[a] = (kind, ref, o, length)
                queued = overflow
            else:
                self._cut(overflow, kind, ref, ov_off)
                cut = overflow
        return TransitionResult(all_agents, all_slots, queued, cut)

    def _start_slots(self, slots, agents, kind, ref, offsets, length, frame):
        if slots.size == 0:
            return
        start = self._current_poses(agents)
        if self.gpu_skinning:
            self._slot_start_rows[slots] = start        # StartP, blended on the GPU
        else:
            # the slot shows exactly the agent's current pose until the next step
            self.storage.rows[self.storage.slot_base + slots] = self.agent_rows(agents)
        self.slots.start(slots, agents, kind, ref, offsets, length, start, frame)
        self.agent_kind[agents] = TRANSITION
        self.agent_ref[agents] = slots
        self.storage.mark_rows_dirty(self.storage.slot_base + slots)
        self.index.set(agents, self._agent_keys(agents))
        self.stats["transitions_served"] += int(slots.size)

    def _cut(self, agents, kind, ref, offsets):
        in_slot = self.agent_kind[agents] == TRANSITION
        if in_slot.any():
            self.slots.release(self.agent_ref[agents[in_slot]])
        self.agent_kind[agents] = kind
        self.agent_ref[agents] = ref
        if kind == STREAM:
            self.agent_offset[agents] = offsets
        self.index.set(agents, self._agent_keys(agents))
        self.slots.cuts += int(agents.size)
        self.stats["cuts"] += int(agents.size)

    def _serve_queue(self) -> int:
        """Give free slots to queued requests (FIFO); their blend starts at the pose
        shown now, before the frame advances."""
        q = self.slots.queue
        if not q:
            return 0
        free = self.slots.free_slots()
        n = min(free.size, len(q))
        served = 0
        for slot in free[:n].tolist():
            a, (kind, ref, off, length) = q.popitem(last=False)
            self._start_slots(np.array([slot]), np.array([a]), kind, ref, np.array([off]),
                              length, self.frame)
            served += 1
        return served

    # --------------------------------------------------------------- parameters
    def _root(self, target) -> int:
        if isinstance(target, str):
            if target not in self.names:
                raise CrowdError(f"unknown stream or unique {target!r}")
            return self.names.index(target)
        return self._resolve(target, "stream")

    def set_parameter(self, target, name: str, value: float):
        """Set a controller parameter on a stream (name or index) or unique (name)."""
        v = float(value)
        if not np.isfinite(v):
            raise CrowdError(f"parameter {name!r}: value must be finite, got {value!r}")
        self.evaluator.ctx.params[self._root(target)][str(name)] = v

    def set_trigger(self, target, name: str):
        """Set a trigger on a stream or unique; the next frame's state machines consume it."""
        self.evaluator.ctx.triggers[self._root(target)].add(str(name))

    def state_of(self, target) -> list:
        """Current state names of the state machines in a stream's or unique's tree."""
        r = self._root(target)
        out = []
        for b in self.evaluator.batches:
            if hasattr(b, "state"):
                out += [b.state(i) for i in np.flatnonzero(b.roots == r)]
        return out

    def on_event(self, name, fn) -> int:
        """Register ``fn(name, frame, agent_ids)`` for event tag ``name`` (``"*"``: all)."""
        return self.events.on(name, fn)

    # ----------------------------------------------------------------- skinning
    def _skin_changed_rows(self):
        st = self.storage
        sl = self.frame % self.M
        if self.gpu_skinning:   # history and uniques are views of the local texture
            for start, count in ((sl * self.S, self.S), (st.unique_base, self.U)):
                st.mark_dirty(start, count)
                if count:
                    self._skin_pending.append((start, count))
            return
        hist = self.history[sl]
        for k, idx, cont in self._stream_skel_groups:
            if cont is not None:
                out = st.stream_slice(sl)[cont]
                self.plans[k].rows(hist[cont], out=out)
            else:
                st.rows[sl * self.S + idx] = self.plans[k].rows(hist[idx])
        st.mark_dirty(sl * self.S, self.S)
        for k, idx, cont in self._unique_skel_groups:
            if cont is not None:
                self.plans[k].rows(self.unique_poses[cont], out=st.unique_rows()[cont])
            else:
                st.unique_rows()[idx] = self.plans[k].rows(self.unique_poses[idx])
        st.mark_dirty(st.unique_base, self.U)
        act = self.slots.active_slots()
        if act.size:
            skel = self.root_skeleton[np.where(self.slots.target_kind[act] == STREAM,
                                               self.slots.target_ref[act],
                                               self.S + self.slots.target_ref[act])]
            for k in np.unique(skel):
                s = act[skel == k]
                lo, hi = int(s[0]), int(s[-1]) + 1
                if hi - lo == s.size:
                    self.plans[k].rows(self.slots.pose[lo:hi], out=st.slot_rows()[lo:hi])
                else:
                    st.slot_rows()[s] = self.plans[k].rows(self.slots.pose[s])
            st.mark_rows_dirty(st.slot_base + act)

    # ------------------------------------------------------------------- events
    def _collect_events(self, dispatch=True):
        roots, names = self.evaluator.ctx.take_events()
        f = self.frame
        is_stream = roots < self.S
        self._log_stream = np.concatenate([self._log_stream, roots[is_stream]])
        self._log_name = np.concatenate([self._log_name, names[is_stream]])
        self._log_frame = np.concatenate([self._log_frame,
                                          np.full(int(is_stream.sum()), f, np.int64)])
        live = f - self._log_frame < self.M
        self._log_stream = self._log_stream[live]
        self._log_name = self._log_name[live]
        self._log_frame = self._log_frame[live]
        if not dispatch:
            return
        keys = np.concatenate([self._log_stream * self.M + (f - self._log_frame),
                               self.S * self.M + (roots[~is_stream] - self.S)])
        key_names = np.concatenate([self._log_name, names[~is_stream]])
        if keys.size == 0:
            return
        ids, which = self.index.lookup(keys)
        if ids.size == 0:
            return
        ev_names = key_names[which]
        for n in np.unique(ev_names):
            agents = np.unique(ids[ev_names == n])
            self._events_fired += 1
            self.events.dispatch(f, self.bank.tag_names[n], agents)

    def _dispatch_events(self):
        self._collect_events(dispatch=True)

    # ------------------------------------------------------------------- reports
    def take_upload_regions(self):
        """Texture rectangles written since the last call (PoseStorage.take_dirty_regions)."""
        return self.storage.take_dirty_regions()

    def pose(self, stream, offset: int = 0) -> np.ndarray:
        """``PH_stream(offset)``: the local pose ``(B, 10)`` the head had ``offset`` frames ago."""
        s = self._resolve(stream, "stream")
        check_offsets(np.array([offset]), self.M, "pose")
        return self.history[(self.frame - int(offset)) % self.M, s].copy()

    def stream_rows(self, stream, offset: int = 0) -> np.ndarray:
        """Pose texture rows ``(B, 3, 4)`` of ``PH_stream(offset)``."""
        s = self._resolve(stream, "stream")
        check_offsets(np.array([offset]), self.M, "pose")
        row = ((self.frame - int(offset)) % self.M) * self.S + s
        if self.gpu_skinning:
            return self._skin_logical_rows(np.array([row]))[0]
        return self.storage.rows[row].copy()
