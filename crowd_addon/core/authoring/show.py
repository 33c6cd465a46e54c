"""The show's data: cues on the timeline, animated parameters and reactions to events.

A :class:`Show` is data (it is saved with the configuration and authored in the
.blend); the crowd runs it itself, before each step, through a
:class:`~crowd_addon.core.shots.show_runner.ShowRunner` (``Crowd.show``), so the viewport
preview, a recording and every export see the same requests in the same order, in any
process. The selections that pick a cue's agents are in :mod:`.selections`.

- A :class:`Cue` applies an :class:`Action` to its agents at a frame. The agents may
  start together, be spread at random over ``spread`` frames, or be reached one after
  the other by a :class:`Sweep` (a front turning around a centre, or moving away from
  it, at a given speed: the Mexican wave). Actions: a transition to a stream (blend
  length, target offset keep / random / given, queue or cut), a unique animation, a
  trigger, a parameter. With ``hold`` the agents go back after that many frames to
  the animation they were on before the cue (their *home*: their configured stream,
  or the last stream a cue without ``hold`` sent them to). A cue leaves agents held
  by another cue alone unless it ``interrupt``\\ s them.
- A :class:`Reaction` runs a cue's action when event tag ``event`` fires for agents
  playing ``source``, on those agents or on every agent within ``radius`` metres of
  them, at the next frame.
- A :class:`Track` is an animated parameter (the value per frame) or trigger (fires
  on each frame its value rises above 0.5), sampled from the .blend's F-curves and
  drivers.

:func:`slot_speed` is the fastest a :class:`Sweep` may go for the crowd's slots.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.bounds import finite
from ..base.errors import CrowdError

__all__ = ["Action", "Sweep", "Cue", "Reaction", "Track", "Show", "ACTION_KINDS", "slot_speed"]

ACTION_KINDS = ("stream", "unique", "trigger", "parameter", "look")
LOOK = "look"                   # a look cue's target kind (targets: crowd.look_target_names)


def _whole(value, what, low=None) -> int:
    v = finite(value, what)
    if v != int(v) or abs(v) > 2**31 - 1:
        raise CrowdError(f"{what} must be a whole number of frames, got {value!r}")
    if low is not None and v < low:
        raise CrowdError(f"{what} must be >= {low}, got {value!r}")
    return int(v)


# ---------------------------------------------------------------------------- data
@dataclass(frozen=True)
class Action:
    """What a cue does.

    kind : ``"stream"`` (blend to stream ``target``), ``"unique"`` (blend to unique
        ``target``, restarted), ``"trigger"`` (set trigger ``name`` on stream or unique
        ``target``), ``"parameter"`` (set parameter ``name`` of ``target`` to ``value``)
        or ``"look"`` (turn the agents' heads toward look target ``target``, blending
        in over ``duration`` frames, and away again after ``hold`` frames; it moves
        no agent, so holds and homes are left alone: :mod:`.look_at`).
    duration : blend length in frames (0 cuts).
    offset : stream actions: ``"keep"`` (each agent's own offset), ``"random"`` (a
        random offset per agent, seeded) or an offset ``0 .. M-1``.
    when_full : ``None`` (the crowd's setting), ``"queue"`` or ``"cut"``.
    hold : stream and unique actions: frames after which the agents go back home
        (0: they stay, and the target becomes their home).
    trigger : stream and unique actions: the mass reaction (paper s.3.4, s.5). Agents
        on a stream whose state machine has a transition on this trigger, and whose
        every agent the cue selects, stay on it: the cue sets the trigger on those
        streams, so each agent follows its stream into the reaction state at its own
        offset (no slot, no per-agent work); only the other agents blend to
        ``target`` through transition slots.
    release : with ``trigger`` and ``hold``: the trigger set on the switched streams
        when the hold ends (the state machine's way back).
    """

    kind: str
    target: str
    duration: float = 8.0
    offset: object = "keep"
    when_full: str | None = None
    hold: int = 0
    name: str = ""
    value: float = 0.0
    trigger: str = ""
    release: str = ""

    def __post_init__(self):
        if self.kind not in ACTION_KINDS:
            raise CrowdError(f"action: kind must be one of {ACTION_KINDS}, got {self.kind!r}")
        if not str(self.target).strip():
            raise CrowdError(f"{self.kind} action: no target animation named")
        duration = finite(self.duration, f"{self.kind} action: duration")
        if duration < 0:
            raise CrowdError(f"{self.kind} action: duration must be >= 0, got {duration:g}")
        object.__setattr__(self, "duration", duration)
        object.__setattr__(self, "hold", _whole(self.hold, f"{self.kind} action: hold", 0))
        if self.when_full not in (None, "queue", "cut"):
            raise CrowdError(f"{self.kind} action: when_full must be 'queue', 'cut' or None, "
                             f"got {self.when_full!r}")
        if self.offset not in ("keep", "random"):
            object.__setattr__(self, "offset", _whole(self.offset, "stream action: offset", 0))
        if self.kind in ("trigger", "parameter") and not str(self.name).strip():
            raise CrowdError(f"{self.kind} action: no {self.kind} name")
        object.__setattr__(self, "value", finite(self.value, f"{self.kind} action: value"))
        for key in ("trigger", "release"):
            v = getattr(self, key)
            if not isinstance(v, str):
                raise CrowdError(f"{self.kind} action: {key} must be a trigger name (text), "
                                 f"got {v!r}")
            object.__setattr__(self, key, v.strip())
        if (self.trigger or self.release) and not self.moves_agents:
            raise CrowdError(f"{self.kind} action: a switch trigger or release belongs to "
                             "stream and unique actions (a trigger action sets its own)")
        if self.release and not self.trigger:
            raise CrowdError(f"{self.kind} action: release {self.release!r} without a "
                             "trigger (nothing was switched to release)")
        if self.release and not self.hold:
            raise CrowdError(f"{self.kind} action: release {self.release!r} needs a hold "
                             "(it is set when the hold ends)")
        if self.trigger and self.hold and not self.release:
            raise CrowdError(f"{self.kind} action: trigger {self.trigger!r} with a hold of "
                             f"{self.hold} needs a release trigger (what brings the "
                             "switched streams back when the hold ends)")

    @property
    def moves_agents(self) -> bool:
        return self.kind in ("stream", "unique")

    @property
    def selects_agents(self) -> bool:
        """Whether the action applies to agents (a selection), not to an animation."""
        return self.moves_agents or self.kind == LOOK


@dataclass(frozen=True)
class Sweep:
    """A front that reaches agents in order.

    mode ``"angle"``: the front turns about +Z around ``centre`` from ``start_angle``
    (radians from +X, counter-clockwise) at ``speed`` radians per second (negative:
    clockwise), ``laps`` times. ``"distance"``: it moves away from ``centre`` at
    ``speed`` metres per second.
    """

    centre: tuple = (0.0, 0.0, 0.0)
    mode: str = "angle"
    speed: float = 1.0
    start_angle: float = 0.0
    laps: int = 1

    def __post_init__(self):
        c = tuple(finite(v, "sweep: centre") for v in np.asarray(self.centre).reshape(-1))
        if len(c) != 3:
            raise CrowdError(f"sweep: centre must be 3 numbers, got {self.centre!r}")
        object.__setattr__(self, "centre", c)
        if self.mode not in ("angle", "distance"):
            raise CrowdError(f"sweep: mode must be 'angle' or 'distance', got {self.mode!r}")
        speed = finite(self.speed, "sweep: speed")
        if speed == 0 or (self.mode == "distance" and speed < 0):
            raise CrowdError(f"sweep: speed must be {'> 0' if self.mode == 'distance' else '!= 0'}"
                             f", got {speed:g} (a front that does not move reaches nobody)")
        object.__setattr__(self, "speed", speed)
        object.__setattr__(self, "start_angle", finite(self.start_angle, "sweep: start_angle"))
        object.__setattr__(self, "laps", _whole(self.laps, "sweep: laps", 1))

    def delays(self, positions: np.ndarray, fps: float) -> np.ndarray:
        """(n, laps) frames after the cue at which the front reaches each position."""
        d = np.asarray(positions, np.float64) - np.asarray(self.centre)
        if self.mode == "distance":
            return (np.hypot(np.hypot(d[:, 0], d[:, 1]), d[:, 2]) / self.speed * fps)[:, None]
        angle = np.arctan2(d[:, 1], d[:, 0]) - self.start_angle
        turn = np.mod(angle if self.speed > 0 else -angle, 2 * np.pi)
        lap = 2 * np.pi / abs(self.speed) * fps
        return turn[:, None] / abs(self.speed) * fps + lap * np.arange(self.laps)


def slot_speed(sweep: Sweep, positions, fps: float, slots: int, blend: float) -> float:
    """The fastest speed (``sweep``'s units, its sign kept) at which ``sweep`` over
    ``positions`` never needs more than ``slots`` transition slots, when each agent it
    reaches blends in over ``blend`` frames and later home over ``blend`` frames (a cue
    with a hold): at most ``slots / 2`` agents may be reached within any ``blend + 1``
    frames (reach frames are whole). The Mexican wave of a full bowl is bound by this,
    not by the crowd's size."""
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    slots, blend = int(slots), finite(blend, "slot_speed: blend")
    if slots < 2 or blend <= 0 or not pos.size:
        raise CrowdError(f"slot_speed: needs agents, at least 2 slots and a blend > 0 "
                         f"(got {pos.shape[0]} agents, {slots} slots, blend {blend:g})")
    d = pos - np.asarray(sweep.centre)
    if sweep.mode == "distance":
        where = np.sort(np.hypot(np.hypot(d[:, 0], d[:, 1]), d[:, 2]))
        period = None
    else:                                   # turns round the centre, wrapped once
        turn = np.sort(np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi))
        where, period = np.r_[turn, turn + 2 * np.pi], 2 * np.pi
    n, allowed = pos.shape[0], slots // 2

    def fits(speed):                        # most agents within blend frames <= allowed
        width = speed * (blend + 1) / fps          # reach frames are whole
        if period is not None and width >= period:
            return n <= allowed
        heads = where[:n]
        return int((np.searchsorted(where, heads + width, "right") - np.arange(n)).max()) \
            <= allowed

    if fits(abs(sweep.speed)):
        return sweep.speed
    lo, hi = 0.0, abs(sweep.speed)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    if lo <= 0:
        raise CrowdError(f"slot_speed: {allowed * 2} slots cannot serve {n} agents at "
                         "the same place (more agents share one spot than slots)")
    return float(np.copysign(lo, sweep.speed))


@dataclass(frozen=True, eq=False)
class Cue:
    """An action applied to agents from a frame.

    agents : (n,) agent ids, or None for every agent (agents of another skeleton than
        the target's are left out). Not used by trigger and parameter actions.
    spread : the agents start at random frames in ``frame .. frame + spread``.
    sweep : a :class:`Sweep` that orders them instead (not with ``spread``).
    interrupt : also move agents another cue holds (their pending return is dropped).
    timeline : False for a cue that only runs through reactions.
    """

    name: str
    frame: int
    action: Action
    agents: np.ndarray | None = None
    spread: int = 0
    sweep: Sweep | None = None
    seed: int = 0
    interrupt: bool = False
    muted: bool = False
    timeline: bool = True

    def __post_init__(self):
        if not str(self.name).strip():
            raise CrowdError("cue: the name must not be empty")
        what = f"cue {self.name!r}"
        if not isinstance(self.action, Action):
            raise CrowdError(f"{what}: action must be an Action, got {type(self.action).__name__}")
        object.__setattr__(self, "frame", _whole(self.frame, f"{what}: frame"))
        object.__setattr__(self, "spread", _whole(self.spread, f"{what}: spread", 0))
        object.__setattr__(self, "seed", _whole(self.seed, f"{what}: seed"))
        if self.sweep is not None and not isinstance(self.sweep, Sweep):
            raise CrowdError(f"{what}: sweep must be a Sweep")
        if self.sweep is not None and self.spread:
            raise CrowdError(f"{what}: choose a spread or a sweep, not both")
        if self.action.trigger and (self.sweep is not None or self.spread):
            raise CrowdError(f"{what}: trigger {self.action.trigger!r} switches whole "
                             "streams at once; it cannot be spread or swept (the agents' "
                             "offsets already spread the switch over up to M frames)")
        if self.agents is not None:
            ids = np.asarray(self.agents)
            if ids.ndim != 1 or (ids.size and ids.dtype.kind not in "iu"):
                raise CrowdError(f"{what}: agents must be a 1-D array of agent ids")
            if ids.size == 0 and self.action.selects_agents:
                raise CrowdError(f"{what}: the selection is empty (no agent to move)")
            ids = np.unique(ids.astype(np.int64))
            ids.flags.writeable = False
            object.__setattr__(self, "agents", ids)


@dataclass(frozen=True)
class Reaction:
    """When event ``event`` fires for agents playing ``source`` (a stream or unique
    name; "" any), run cue ``cue``'s action on them (``radius`` 0) or on every agent
    within ``radius`` metres of them, at the next frame. A cue with a selection only
    reacts with its selected agents."""

    name: str
    event: str
    cue: str
    source: str = ""
    radius: float = 0.0
    muted: bool = False

    def __post_init__(self):
        if not str(self.name).strip():
            raise CrowdError("reaction: the name must not be empty")
        what = f"reaction {self.name!r}"
        if not str(self.event).strip():
            raise CrowdError(f"{what}: no event named")
        if not str(self.cue).strip():
            raise CrowdError(f"{what}: no cue named")
        r = finite(self.radius, f"{what}: radius")
        if r < 0:
            raise CrowdError(f"{what}: radius must be >= 0, got {r:g}")
        object.__setattr__(self, "radius", r)


@dataclass(frozen=True, eq=False)
class Track:
    """Values of a parameter (``kind="parameter"``) or trigger (``"trigger"``) of stream
    or unique ``target`` at frames ``first, first + 1, ...`` (held beyond both ends)."""

    target: str
    name: str
    first: int
    values: np.ndarray
    kind: str = "parameter"

    def __post_init__(self):
        what = f"{self.kind} track {self.target!r}/{self.name!r}"
        if self.kind not in ("parameter", "trigger"):
            raise CrowdError(f"track: kind must be 'parameter' or 'trigger', got {self.kind!r}")
        if not str(self.target).strip() or not str(self.name).strip():
            raise CrowdError(f"{what}: needs a target animation and a name")
        object.__setattr__(self, "first", _whole(self.first, f"{what}: first"))
        v = np.asarray(self.values, np.float64)
        if v.ndim != 1 or v.size == 0:
            raise CrowdError(f"{what}: values must be a non-empty 1-D array, got {v.shape}")
        if not np.isfinite(v).all():
            bad = int(np.argmax(~np.isfinite(v)))
            raise CrowdError(f"{what}: value at frame {self.first + bad} is not finite")
        v = v.copy()
        v.flags.writeable = False
        object.__setattr__(self, "values", v)

    def at(self, frame: int) -> float:
        return float(self.values[min(max(frame - self.first, 0), self.values.size - 1)])


@dataclass(frozen=True, eq=False)
class Show:
    """Cues, reactions and tracks; names of cues and reactions are unique."""

    cues: tuple = ()
    reactions: tuple = ()
    tracks: tuple = ()

    def __post_init__(self):
        for attr, kind in (("cues", Cue), ("reactions", Reaction), ("tracks", Track)):
            items = tuple(getattr(self, attr))
            for item in items:
                if not isinstance(item, kind):
                    raise CrowdError(f"show: {attr} must hold {kind.__name__} values, got "
                                     f"{type(item).__name__}")
            object.__setattr__(self, attr, items)
        for attr in ("cues", "reactions"):
            seen = set()
            for item in getattr(self, attr):
                if item.name in seen:
                    raise CrowdError(f"show: two {attr} are named {item.name!r}")
                seen.add(item.name)
        cues = {c.name for c in self.cues}
        for r in self.reactions:
            if r.cue not in cues:
                raise CrowdError(f"reaction {r.name!r}: unknown cue {r.cue!r} "
                                 f"(known: {sorted(cues)})")

    def cue(self, name) -> Cue:
        for c in self.cues:
            if c.name == name:
                return c
        raise CrowdError(f"unknown cue {name!r}")

    def outside(self, first: int, last: int) -> list:
        """Names of timeline cues (not muted) that start outside frames
        ``first .. last``."""
        return [c.name for c in self.cues if c.timeline and not c.muted
                and not first <= c.frame <= last]

    def __bool__(self):
        return bool(self.cues or self.reactions or self.tracks)
