"""The show's runner: :class:`ShowRunner` runs a :class:`~crowd_addon.core.authoring.show.Show`
on a crowd before each step.

It compiles the timeline cues into a schedule (spread and swept agents at their own
frames), checks every target, keeps each agent's home and hold, sends held agents back
home, switches whole streams into a cue's trigger state (the mass reaction, paper
s.3.4, s.5) and sets their release when the hold ends, and runs reactions to events on
the next frame. Its state for snapshots is :class:`~.show_state.ShowState`.

Nothing runs per agent per frame: a frame with no cue, return or reaction due costs a
dictionary lookup and one comparison per track.
"""

from __future__ import annotations

import zlib
from collections import defaultdict

import numpy as np

from ..runtime.agents import STREAM, UNIQUE
from ..base.errors import CrowdError
from ..authoring.selections import neighbour_grid, neighbours
from ..authoring.show import LOOK, Show
from .show_state import STAT_KEYS, ShowState

__all__ = ["ShowRunner"]

_NEVER = np.iinfo(np.int64).min // 4


def _mix(seed: int, salt: str, ids: np.ndarray) -> np.ndarray:
    """A well-mixed uint64 per id (splitmix64), the same in every process."""
    x = (np.asarray(ids, np.uint64) + np.uint64((int(seed) & 0xFFFFFFFF) << 32)
         + np.uint64(zlib.crc32(salt.encode())))
    with np.errstate(over="ignore"):
        x = x + np.uint64(0x9E3779B97F4A7C15)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


class ShowRunner(ShowState):
    """Runs a :class:`Show` on a crowd: ``before_step(frame)`` issues the requests due
    at ``frame`` (called by ``Crowd.step``); ``reset()`` rewinds it with the crowd.

    ``stats`` counts per cue: ``agents`` moved, ``skipped`` (held by another cue),
    ``queued`` and ``cut`` (of those sent through slots), ``switched`` (agents that
    followed their stream into the cue's trigger state) and ``streams`` (streams the
    trigger switched); ``reactions`` counts the agents each reaction reached.
    """

    def __init__(self, show: Show, crowd):
        self.show, self.crowd = show, crowd
        n = crowd.agents.count
        self._n = n
        self._cue_index = {c.name: i for i, c in enumerate(show.cues)}
        self._targets = [self._check(c) for c in show.cues]
        # per cue with a switch trigger: (S,) the streams that take it (and its release)
        ev = crowd.evaluator
        self._takes = [None if not c.action.trigger else np.array(
            [c.action.trigger in ev.triggers(k) and
             (not c.action.release or c.action.release in ev.triggers(k))
             for k in range(crowd.streams.count)], bool) for c in show.cues]
        for t in show.tracks:
            self._root(t.target, f"{t.kind} track {t.name!r}")
        for r in show.reactions:
            if r.source:
                self._root(r.source, f"reaction {r.name!r}: source")
            if r.event not in crowd.bank.tag_names:
                raise CrowdError(f"reaction {r.name!r}: no clip has event {r.event!r} "
                                 f"(events: {sorted(crowd.bank.tag_names)})")
            if not show.cue(r.cue).action.selects_agents and r.radius:
                raise CrowdError(f"reaction {r.name!r}: cue {r.cue!r} sets a "
                                 f"{show.cue(r.cue).action.kind}, which has no agents to reach")
        self._schedule = self._compile()
        self._grid, self._grid_cursor = {}, 0
        self._handles = [crowd.on_event(r.event, self._reacting(i))
                         for i, r in enumerate(show.reactions) if not r.muted]
        self.reset()

    # ------------------------------------------------------------ validation
    def _root(self, name, what):
        c = self.crowd
        if name in c.streams.names:
            return STREAM, c.streams.index(name)
        if name in c.uniques.names:
            return UNIQUE, c.uniques.index(name)
        raise CrowdError(f"{what}: unknown stream or unique {name!r} (streams: "
                         f"{list(c.streams.names)}, uniques: {list(c.uniques.names)})")

    def _check(self, cue):
        """(kind, ref, skeleton) of the cue's target, after checking it and its agents."""
        a, what = cue.action, f"cue {cue.name!r}"
        c = self.crowd
        if a.kind == LOOK:
            if a.target not in c.look_target_names:
                raise CrowdError(f"{what}: unknown look target {a.target!r} (look targets: "
                                 f"{list(c.look_target_names)})")
            kind, ref = LOOK, c.look_target_names.index(a.target)
        else:
            kind, ref = self._root(a.target, what)
        start = c.config.start_frame
        if cue.timeline and not cue.muted and cue.frame <= start:
            raise CrowdError(f"{what}: frame {cue.frame} is not after the crowd's start frame "
                             f"{start} (the first frame a cue can start at is {start + 1})")
        if a.kind == "stream" and kind != STREAM:
            raise CrowdError(f"{what}: {a.target!r} is a unique, not a stream")
        if a.kind == "unique" and kind != UNIQUE:
            raise CrowdError(f"{what}: {a.target!r} is a stream, not a unique")
        skeleton = -1 if kind == LOOK else \
            (c.streams.skeleton if kind == STREAM else c.uniques.skeleton)[ref]
        if isinstance(a.offset, int) and a.offset >= c.streams.max_offset:
            raise CrowdError(f"{what}: offset {a.offset} is outside 0..{c.streams.max_offset - 1}")
        if cue.agents is not None and cue.agents.size and \
                (cue.agents[0] < 0 or cue.agents[-1] >= self._n):
            bad = cue.agents[(cue.agents < 0) | (cue.agents >= self._n)][0]
            raise CrowdError(f"{what}: agent {int(bad)} does not exist (the crowd has "
                             f"{self._n} agents)")
        if a.selects_agents and not self._agents(cue, (kind, ref, skeleton)).size:
            raise CrowdError(f"{what}: none of its agents can " + (
                f"look at {a.target!r} (their characters have no look rig)" if kind == LOOK
                else f"play {a.target!r} (they use another skeleton)"))
        return kind, ref, skeleton

    def _agents(self, cue, target):
        """The cue's agents that can play its target (look at it: have a look rig)."""
        ids = np.arange(self._n) if cue.agents is None else cue.agents
        if target[0] == LOOK:
            return self.crowd.can_look(ids)
        return ids[self.crowd.agent_skeleton[ids] == target[2]]

    # ------------------------------------------------------------ schedule
    def _compile(self) -> dict:
        """frame -> [(cue index, agent ids or None)] for the timeline cues."""
        due = defaultdict(list)
        pos = self.crowd.agents.position
        for i, cue in enumerate(self.show.cues):
            if cue.muted or not cue.timeline:
                continue
            if not cue.action.selects_agents:
                due[cue.frame].append((i, None))
                continue
            ids = self._agents(cue, self._targets[i])
            if cue.sweep is not None:
                late = np.floor(cue.sweep.delays(pos[ids], self.crowd.fps)).astype(np.int64)
                ids = np.repeat(ids[:, None], late.shape[1], 1).reshape(-1)
                late = late.reshape(-1)
            elif cue.spread:
                late = (_mix(cue.seed, cue.name, ids) % np.uint64(cue.spread + 1)).astype(
                    np.int64)
            else:
                due[cue.frame].append((i, ids))
                continue
            order = np.argsort(late, kind="stable")
            late, ids = late[order], ids[order]
            starts = np.flatnonzero(np.r_[True, late[1:] != late[:-1]])
            for s, e in zip(starts, np.r_[starts[1:], late.size]):
                due[cue.frame + int(late[s])].append((i, np.sort(ids[s:e])))
        return dict(due)

    def reset(self):
        """Back to the start: homes from the configuration, nobody held."""
        cfg = self.crowd.config
        st = np.asarray(cfg.agent_stream, np.int64)
        self.home_kind = np.where(st >= 0, STREAM, UNIQUE).astype(np.int8)
        self.home_ref = np.where(st >= 0, st, np.asarray(cfg.agent_unique, np.int64))
        self.home_offset = np.asarray(cfg.agent_offset, np.int64).copy()
        self.held_until = np.full(self._n, _NEVER, np.int64)
        self._returns = defaultdict(list)        # frame -> [(ids, duration)]
        self._releases = defaultdict(list)       # frame -> [(cue, stream, ids)]
        self._reacted = defaultdict(list)        # reaction index -> [ids] for next frame
        self._track_last = [None] * len(self.show.tracks)
        self.stats = {c.name: dict.fromkeys(STAT_KEYS, 0) for c in self.show.cues}
        self.reactions = {r.name: 0 for r in self.show.reactions}

    # ------------------------------------------------------------------ step
    def before_step(self, frame: int):
        """Issue what is due at ``frame`` (the frame about to be stepped): tracks,
        returns home, reactions to the last frame's events, then cues."""
        self.apply_tracks(frame)
        for ids, duration in self._returns.pop(frame, ()):
            self._send_home(ids[self.held_until[ids] == frame], duration)
        for cue_i, stream, ids in self._releases.pop(frame, ()):
            self.crowd.set_trigger(int(stream), self.show.cues[cue_i].action.release)
            self.held_until[ids[self.held_until[ids] == frame]] = _NEVER
        if self._reacted:
            reacted, self._reacted = self._reacted, defaultdict(list)
            for r, groups in reacted.items():
                reaction = self.show.reactions[r]
                ids = np.unique(np.concatenate(groups))
                if reaction.radius > 0:
                    ids = neighbours(self.crowd.agents.position, ids, reaction.radius,
                                     self._neighbour_grid(reaction.radius))
                cue_i = self._cue_index[reaction.cue]
                self.reactions[reaction.name] += ids.size
                self._apply(cue_i, ids, frame, selected=False)
        for cue_i, ids in self._schedule.get(frame, ()):
            self._apply(cue_i, ids, frame)

    def apply_tracks(self, frame: int, triggers: bool = True):
        """Set the tracks' parameters to their values at ``frame`` (when changed) and
        fire the triggers that rise there (``triggers``). ``Crowd.reset`` calls it for
        the start frame, without triggers, so the history it fills already has them."""
        for k, t in enumerate(self.show.tracks):
            v = t.at(frame)
            last = self._track_last[k]
            if t.kind == "parameter":
                if v != last:
                    self.crowd.set_parameter(t.target, t.name, v)
            elif not triggers:
                continue
            elif v > 0.5 and (last is None or last <= 0.5):
                self.crowd.set_trigger(t.target, t.name)
            self._track_last[k] = v

    def _apply(self, i, ids, frame, selected=True):
        cue, c = self.show.cues[i], self.crowd
        a = cue.action
        if a.kind == "trigger":
            c.set_trigger(a.target, a.name)
            return
        if a.kind == "parameter":
            c.set_parameter(a.target, a.name, a.value)
            return
        kind, ref, skeleton = self._targets[i]
        if not selected:                     # a reaction's agents: keep the cue's own
            if cue.agents is not None:
                ids = ids[np.isin(ids, cue.agents, assume_unique=True)]
            ids = c.can_look(ids) if kind == LOOK else ids[c.agent_skeleton[ids] == skeleton]
        st = self.stats[cue.name]
        if kind == LOOK:                     # a layer on top: holds and homes stay
            if ids.size:
                c.look_at(ids, a.target, a.duration, a.hold)
                st["agents"] += int(ids.size)
            return
        if not cue.interrupt:
            free = self.held_until[ids] < frame
            st["skipped"] += int(ids.size - free.sum())
            ids = ids[free]
        if ids.size == 0:
            return
        st["agents"] += int(ids.size)
        if a.trigger:
            ids = self._switch(i, ids, frame)
            if ids.size == 0:
                return
        if a.kind == "stream":
            offset = None if a.offset == "keep" else a.offset if isinstance(a.offset, int) \
                else (_mix(cue.seed, cue.name, ids) % np.uint64(c.streams.max_offset)).astype(
                    np.int64)
            r = c.transition_to_streamed(ids, ref, a.duration, offset=offset,
                                         when_full=a.when_full)
        else:
            r = c.transition_to_unique(ids, a.target, a.duration, when_full=a.when_full)
        st["queued"] += int(r.queued.size)
        st["cut"] += int(r.cut.size)
        if a.hold:
            self.held_until[ids] = frame + a.hold
            self._returns[frame + a.hold].append((ids, a.duration))
        else:
            self.held_until[ids] = _NEVER
            self.home_kind[ids] = kind
            self.home_ref[ids] = ref
            if a.kind == "stream" and offset is not None:
                self.home_offset[ids] = offset

    def _switchable(self, i, ids, kind, ref, kind_all, ref_all) -> tuple:
        """Which of ``ids`` (playing ``kind``/``ref``) cue ``i`` switches with their
        streams, given what every agent plays (``kind_all``/``ref_all``): those on a
        stream that takes its trigger and that no agent outside ``ids`` plays (a
        stream is shared: switching it moves everyone on it). Returns (mask, streams)."""
        count = self.crowd.streams.count
        on = kind == STREAM
        on[on] = self._takes[i][ref[on]]
        mine = np.bincount(ref[on], minlength=count)
        everyone = np.bincount(ref_all[kind_all == STREAM], minlength=count)
        whole = (mine > 0) & (mine == everyone)
        on[on] = whole[ref[on]]
        return on, np.flatnonzero(whole)

    def _switch(self, i, ids, frame) -> np.ndarray:
        """Set cue ``i``'s trigger on the streams its agents ``ids`` can follow into
        the reaction (see :meth:`_switchable`); returns the agents left for the slots."""
        cue, c = self.show.cues[i], self.crowd
        a = cue.action
        kind, ref, _ = c.playing(ids)
        kind_all, ref_all, _ = c.playing(np.arange(self._n))
        on, streams = self._switchable(i, ids, kind, ref, kind_all, ref_all)
        if not streams.size:
            return ids
        for k in streams.tolist():
            c.set_trigger(k, a.trigger)
        sw, sw_ref = ids[on], ref[on]
        st = self.stats[cue.name]
        st["switched"] += int(sw.size)
        st["streams"] += int(streams.size)
        if a.hold:
            self.held_until[sw] = frame + a.hold
            for k in streams.tolist():
                self._releases[frame + a.hold].append((i, k, sw[sw_ref == k]))
        else:
            self.held_until[sw] = _NEVER
        return ids[~on]

    def _send_home(self, ids, duration):
        if ids.size == 0:
            return
        self.held_until[ids] = _NEVER
        c = self.crowd
        a = c.agents
        kind = a.kind[ids]
        home = (kind == self.home_kind[ids]) & (a.ref[ids] == self.home_ref[ids]) & \
            ((kind != STREAM) | (a.offset[ids] == self.home_offset[ids]))
        if home.any():      # never left (the cue's request still waited): no blend to
            c.slots.queue.withdraw(np.unique(ids[home]))     # where they are; wait no more
            ids = ids[~home]
        streamed = self.home_kind[ids] == STREAM
        grp = ids[streamed]                  # one request for every stream
        if grp.size:
            c.transition_to_streamed(grp, self.home_ref[grp], duration,
                                     offset=self.home_offset[grp])
        for u in np.unique(self.home_ref[ids[~streamed]]):
            grp = ids[~streamed]
            c.transition_to_unique(grp[self.home_ref[grp] == u], int(u), duration,
                                   restart=False)

    # -------------------------------------------------------------- reactions
    def _reacting(self, r):
        reaction = self.show.reactions[r]
        source = self._root(reaction.source, "") if reaction.source else None

        def on_event(_name, _frame, ids):
            ids = np.asarray(ids, np.int64)
            if source is not None:
                kind, ref, _off = self.crowd.playing(ids)
                ids = ids[(kind == source[0]) & (ref == source[1])]
            if ids.size:
                self._reacted[r].append(ids)
        return on_event

    def _neighbour_grid(self, radius):
        changes = self.crowd.agents.changes_since(self._grid_cursor)
        self._grid_cursor = changes.cursor
        if changes.moved:
            self._grid.clear()
        if radius not in self._grid:
            self._grid[radius] = neighbour_grid(self.crowd.agents.position, radius)
        return self._grid[radius]

    def close(self):
        """Stop reacting (unregister the event callbacks)."""
        for h in self._handles:
            self.crowd.events.off(h)
        self._handles = []

    def describe(self) -> list:
        """One dict per cue: ``name``, ``frame``, ``agents`` (how many it selects);
        worked out once (selections do not change), so a panel may ask every redraw."""
        if getattr(self, "_described", None) is None:
            self._described = self._describe()
        return [dict(d) for d in self._described]

    def _describe(self) -> list:
        out = []
        for i, cue in enumerate(self.show.cues):
            ids = self._agents(cue, self._targets[i]) if cue.action.selects_agents else None
            d = {"name": cue.name, "frame": cue.frame, "agents": 0 if ids is None else
                 int(ids.size), "action": cue.action.kind, "target": cue.action.target,
                 "switched": 0, "streams": 0}
            if cue.action.trigger:          # as configured: each agent on its stream
                st = np.asarray(self.crowd.config.agent_stream, np.int64)
                kind = np.where(st >= 0, STREAM, UNIQUE)
                on, streams = self._switchable(i, ids, kind[ids], st[ids], kind, st)
                d["switched"], d["streams"] = int(on.sum()), int(streams.size)
            d["slots"] = d["agents"] - d["switched"]
            out.append(d)
        return out

