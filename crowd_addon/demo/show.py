"""The stadium show: the simulation side of the demo, driving a core :class:`Crowd`.

It is what a game's crowd system would do with the paper's machinery, scripted on
a timeline (frames at the crowd's fps):

- a **goal** for the home side: every home agent blends from its idle stream to the
  cheer stream through transition slots (requests beyond the free slots wait in the
  queue), cheers for a while, then blends back to its own idle stream and offset;
- a **Mexican wave** travelling around the bowl: each frame the agents whose seat
  angle the wave front has just passed get a timed transition to the wave stream,
  and ``wave_hold`` frames later one back (the paper's use case for its 800 slots);
- a **hit by the ball**: a few agents each switch to their own unique animation
  (the UniquePool: one animation per agent, restarted) and return to idle when it ends;
- **claps** counted per frame through the ``clap`` event callback, one call per
  frame with all clapping agents.

:meth:`StadiumShow.before_step` is called before each ``crowd.step()``; it only
issues requests, so the same show drives the headless demo, the viewport preview
and the USD export (as its ``on_frame`` hook).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from ..core.crowd import Crowd
from ..core.errors import CrowdError

__all__ = ["ShowPlan", "StadiumShow"]


@dataclass
class ShowPlan:
    """When things happen (frames after the show starts) and how long they take."""

    goal_frame: int = 45
    cheer_frames: int = 90
    wave_start: int = 20
    wave_lap_frames: int = 240          # one lap of the bowl
    wave_laps: float = 1.0
    wave_hold: int = 16                 # frames an agent stays up
    wave_start_angle: float = 0.0       # radians around the bowl where the wave starts
    blend_frames: int = 6               # transition length L
    hit_frame: int = 70
    seed: int = 11


@dataclass
class ShowStats:
    requested: int = 0
    started_at_once: int = 0
    queued: int = 0
    cut: int = 0
    claps: dict = field(default_factory=lambda: defaultdict(int))   # frame -> agents
    clap_calls: int = 0
    waves: int = 0
    cheering: int = 0
    hits: int = 0


class StadiumShow:
    """Scripted reactions for a stadium crowd.

    Parameters
    ----------
    crowd : Crowd whose agents are the seats.
    seat_angle : (N,) radians of each seat around the bowl's centre (for the wave).
    home : (N,) bool, True for the home section (they cheer at the goal).
    cheer, wave : stream names; hits : unique names, one per agent hit by the ball
        (empty to skip the hit); hit_frames : how long the hit plays.
    away_reaction : stream the away side blends to at the goal (None: they stay).
    actors : (N,) bool, the agents the show may move (default all); others (e.g. a
        second character type) keep playing their stream.
    plan : ShowPlan.
    start_frame : crowd frame the show's timeline starts at (default: the crowd's).
    """

    def __init__(self, crowd: Crowd, seat_angle, home, cheer="cheer", wave="wave",
                 hits=(), hit_frames=45, plan: ShowPlan | None = None,
                 start_frame=None, clap_event="clap", away_reaction=None, actors=None):
        self.crowd = crowd
        self.plan = plan or ShowPlan()
        n = crowd.agents.count
        self.angle = np.mod(np.asarray(seat_angle, np.float64).reshape(-1), 2 * np.pi)
        self.home = np.asarray(home, bool).reshape(-1)
        if self.angle.shape != (n,) or self.home.shape != (n,):
            raise CrowdError(f"show: seat_angle and home need one value per agent ({n}), got "
                             f"{self.angle.shape} and {self.home.shape}")
        self.cheer = crowd.streams.index(cheer)
        self.wave = crowd.streams.index(wave)
        self.away = None if away_reaction is None else crowd.streams.index(away_reaction)
        self.actors = np.ones(n, bool) if actors is None else np.asarray(actors, bool).reshape(-1)
        if self.actors.shape != (n,):
            raise CrowdError(f"show: actors needs one value per agent ({n}), got "
                             f"{self.actors.shape}")
        self.hits = np.array([crowd.uniques.index(h) for h in hits], np.int64)
        self.hit_frames = int(hit_frames)
        self.idle_stream = np.asarray(crowd.config.agent_stream, np.int64).copy()
        if (self.idle_stream < 0).any():
            raise CrowdError("show: every seat must start on a stream (idle), agent "
                             f"{int(np.argmax(self.idle_stream < 0))} starts on a unique")
        self.idle_offset = np.asarray(crowd.config.agent_offset, np.int64).copy()
        self.t0 = crowd.frame if start_frame is None else int(start_frame)
        self.stats = ShowStats()
        self._returns = defaultdict(list)          # frame -> agent id arrays to send back
        self._busy = ~self.actors                  # in a scripted reaction (or no actor)
        rng = np.random.default_rng(self.plan.seed)
        pool = np.flatnonzero(self.actors)
        self._hit_ids = rng.choice(pool, size=min(self.hits.size, pool.size), replace=False)
        crowd.on_event(clap_event, self._on_clap)

    # ----------------------------------------------------------------- callbacks
    def _on_clap(self, name, frame, ids):
        self.stats.claps[int(frame)] += int(ids.size)
        self.stats.clap_calls += 1

    # ------------------------------------------------------------------ timeline
    def before_step(self, crowd: Crowd | None = None, frame: int | None = None):
        """Issue this frame's requests (the frame about to be stepped)."""
        c = self.crowd
        f = c.frame + 1 if frame is None else int(frame)
        t = f - self.t0 - 1                  # 0 on the first frame stepped
        p = self.plan
        for ids in self._returns.pop(f, []):
            self._send_home(ids)
        if t == p.goal_frame:
            ids = np.flatnonzero(self.home & ~self._busy)
            self._request(ids, "stream", self.cheer, offset=0)
            self.stats.cheering += ids.size
            self._later(f + p.cheer_frames, ids)
            if self.away is not None:
                ids = np.flatnonzero(~self.home & ~self._busy)
                self._request(ids, "stream", self.away, offset=0)
                self._later(f + p.cheer_frames, ids)
        if p.wave_lap_frames > 0 and p.wave_start <= t < p.wave_start + p.wave_laps * \
                p.wave_lap_frames:
            a0 = (t - p.wave_start) / p.wave_lap_frames * 2 * np.pi
            a1 = (t + 1 - p.wave_start) / p.wave_lap_frames * 2 * np.pi
            swept = np.mod(self.angle - p.wave_start_angle - a0, 2 * np.pi) < (a1 - a0)
            ids = np.flatnonzero(swept & ~self._busy)
            self._request(ids, "stream", self.wave, offset=0)
            self.stats.waves += ids.size
            self._later(f + p.wave_hold, ids)
        if t == p.hit_frame and self._hit_ids.size:
            # the ball waits for nobody: a hit interrupts whatever the fan was doing
            self._cancel_returns(self._hit_ids)
            for a, u in zip(self._hit_ids, self.hits):
                self._request(np.array([a]), "unique", int(u))
            self.stats.hits += self._hit_ids.size
            self._later(f + self.hit_frames, self._hit_ids)

    __call__ = before_step

    def _cancel_returns(self, ids):
        """Forget the scheduled returns of ``ids`` (they get a new reaction)."""
        for frame, groups in self._returns.items():
            self._returns[frame] = [g[~np.isin(g, ids)] for g in groups]

    def _later(self, frame, ids):
        if ids.size:
            self._busy[ids] = True
            self._returns[int(frame)].append(ids)

    def _send_home(self, ids):
        self._busy[ids] = False
        for s in np.unique(self.idle_stream[ids]):
            grp = ids[self.idle_stream[ids] == s]
            self._request(grp, "stream", int(s), offset=self.idle_offset[grp])

    def _request(self, ids, kind, target, offset=None):
        if ids.size == 0:
            return
        c = self.crowd
        if kind == "stream":
            r = c.transition_to_streamed(ids, target, self.plan.blend_frames, offset=offset)
        else:
            r = c.transition_to_unique(ids, target, self.plan.blend_frames)
        self.stats.requested += ids.size
        self.stats.started_at_once += r.started.size
        self.stats.queued += r.queued.size
        self.stats.cut += r.cut.size

    def summary(self) -> dict:
        s, c = self.stats, self.crowd
        return {"transitions_requested": s.requested, "started_at_once": s.started_at_once,
                "queued": s.queued, "cut": s.cut,
                "transitions_served": int(c.stats["transitions_served"]),
                "cheering": s.cheering, "wave_agents": s.waves, "hits": s.hits,
                "clap_agent_events": int(sum(s.claps.values())), "clap_calls": s.clap_calls,
                "events_fired": int(sum(c.events.fired.values()))}
