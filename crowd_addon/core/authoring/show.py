"""The show: cues on the timeline, animated parameters and reactions to events.

A :class:`Show` is data (it is saved with the configuration and authored in the
.blend); the crowd runs it itself, before each step, through a :class:`ShowRunner`
(``Crowd.show``), so the viewport preview, a recording and every export see the same
requests in the same order, in any process.

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

Nothing runs per agent per frame: a frame with no cue, return or reaction due costs a
dictionary lookup and one comparison per track.
"""

from __future__ import annotations

import zlib
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..runtime.agents import STREAM, UNIQUE
from ..base.errors import CrowdError

__all__ = ["Action", "Sweep", "Cue", "Reaction", "Track", "Show", "ShowRunner",
           "ACTION_KINDS", "select_inside", "select_value", "select_fraction", "neighbours",
           "slot_speed"]

ACTION_KINDS = ("stream", "unique", "trigger", "parameter", "look")
LOOK = "look"                   # a look cue's target kind (targets: crowd.look_target_names)
_OPS = {"==": np.equal, "!=": np.not_equal, "<": np.less, "<=": np.less_equal,
        ">": np.greater, ">=": np.greater_equal}
_NEVER = np.iinfo(np.int64).min // 4
#: what ShowRunner.stats counts per cue
STAT_KEYS = ("agents", "skipped", "queued", "cut", "switched", "streams")


def _finite(value, what) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CrowdError(f"{what} must be a number, got {value!r}") from None
    if not np.isfinite(v):
        raise CrowdError(f"{what} must be finite, got {value!r}")
    return v


def _whole(value, what, low=None) -> int:
    v = _finite(value, what)
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
        duration = _finite(self.duration, f"{self.kind} action: duration")
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
        object.__setattr__(self, "value", _finite(self.value, f"{self.kind} action: value"))
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
        c = tuple(_finite(v, "sweep: centre") for v in np.asarray(self.centre).reshape(-1))
        if len(c) != 3:
            raise CrowdError(f"sweep: centre must be 3 numbers, got {self.centre!r}")
        object.__setattr__(self, "centre", c)
        if self.mode not in ("angle", "distance"):
            raise CrowdError(f"sweep: mode must be 'angle' or 'distance', got {self.mode!r}")
        speed = _finite(self.speed, "sweep: speed")
        if speed == 0 or (self.mode == "distance" and speed < 0):
            raise CrowdError(f"sweep: speed must be {'> 0' if self.mode == 'distance' else '!= 0'}"
                             f", got {speed:g} (a front that does not move reaches nobody)")
        object.__setattr__(self, "speed", speed)
        object.__setattr__(self, "start_angle", _finite(self.start_angle, "sweep: start_angle"))
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
    frames (reach frames are whole). The Mexican wave of a full bowl is bound by this, not by the crowd's size."""
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    slots, blend = int(slots), _finite(blend, "slot_speed: blend")
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
        r = _finite(self.radius, f"{what}: radius")
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


# ---------------------------------------------------------------------- selections
def select_value(values: np.ndarray, op: str, value: float) -> np.ndarray:
    """Indices where ``values op value`` (op one of ``== != < <= > >=``)."""
    if op not in _OPS:
        raise CrowdError(f"selection: op must be one of {sorted(_OPS)}, got {op!r}")
    return np.flatnonzero(_OPS[op](np.asarray(values), value))


def select_inside(positions: np.ndarray, world_to_local: np.ndarray, low, high) -> np.ndarray:
    """Indices of ``positions`` (n, 3) inside the box ``low .. high`` of the space that
    the 4x4 ``world_to_local`` maps to (an object's bounds)."""
    p = np.asarray(positions, np.float64)
    m = np.asarray(world_to_local, np.float64)
    local = p @ m[:3, :3].T + m[:3, 3]
    return np.flatnonzero(((local >= np.asarray(low)) & (local <= np.asarray(high))).all(1))


def select_fraction(ids: np.ndarray, fraction: float, seed: int) -> np.ndarray:
    """A random ``fraction`` (0..1) of ``ids``, sorted, the same for equal inputs."""
    f = _finite(fraction, "selection: fraction")
    if not 0 <= f <= 1:
        raise CrowdError(f"selection: fraction must be in 0..1, got {f:g}")
    ids = np.asarray(ids, np.int64)
    keep = int(round(f * ids.size))
    order = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x5E1EC7]).permutation(ids.size)
    return np.sort(ids[order[:keep]])


def neighbours(positions: np.ndarray, ids: np.ndarray, radius: float, grid=None):
    """Agents within ``radius`` of any of ``ids`` (themselves included), sorted; ``grid``
    from :func:`_grid` to reuse. Cost grows with the agents near ``ids``, not with N."""
    ids = np.asarray(ids, np.int64)
    if ids.size == 0 or radius <= 0:
        return np.unique(ids)
    order, keys, cells = grid if grid is not None else _grid(positions, radius)
    pos = np.asarray(positions, np.float64)
    near = []
    offsets = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
    for d in offsets:            # 27 neighbouring cells, each a vectorised range lookup
        want = _cell_key(cells[ids] + d)
        lo = np.searchsorted(keys, want, "left")
        hi = np.searchsorted(keys, want, "right")
        counts = hi - lo
        if counts.sum() == 0:
            continue
        src = np.repeat(ids, counts)
        cand = order[np.repeat(lo - np.cumsum(counts) + counts, counts)
                     + np.arange(counts.sum())]
        close = np.einsum("ij,ij->i", pos[cand] - pos[src], pos[cand] - pos[src]) \
            <= radius * radius
        near.append(cand[close])
    return np.unique(np.concatenate(near + [ids]))


def _cell_key(cells: np.ndarray) -> np.ndarray:
    c = cells.astype(np.int64) + (1 << 20)
    return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]


def _grid(positions, radius):
    cells = np.floor(np.asarray(positions, np.float64) / radius).astype(np.int64)
    keys = _cell_key(cells)
    order = np.argsort(keys, kind="stable")
    return order, keys[order], cells


def _mix(seed: int, salt: str, ids: np.ndarray) -> np.ndarray:
    """A well-mixed uint64 per id (splitmix64), the same in every process."""
    x = (np.asarray(ids, np.uint64) + np.uint64((int(seed) & 0xFFFFFFFF) << 32)
         + np.uint64(zlib.crc32(salt.encode())))
    with np.errstate(over="ignore"):
        x = x + np.uint64(0x9E3779B97F4A7C15)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


# -------------------------------------------------------------------------- runner
def _grouped(arrays) -> dict:
    """A list of int64 id arrays as ``{"ids": concatenated, "counts": sizes}``."""
    return {"ids": np.concatenate([np.zeros(0, np.int64), *arrays]).astype(np.int64),
            "counts": np.array([a.size for a in arrays], np.int64)}


def _ungrouped(d) -> list:
    """The arrays of :func:`_grouped`, back."""
    return np.split(d["ids"], np.cumsum(d["counts"])[:-1]) if d["counts"].size else []


class ShowRunner:
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

    def state(self) -> dict:
        """What a :mod:`.snapshot` keeps: homes, holds, the returns and reactions still
        due (in the order they will be issued), the tracks' last values and the counts."""
        returns = [(f, ids, d) for f, groups in self._returns.items() for ids, d in groups]
        reacted = [(r, ids) for r, groups in self._reacted.items() for ids in groups]
        releases = [(f, *entry) for f, groups in self._releases.items() for entry in groups]
        return {"home_kind": self.home_kind, "home_ref": self.home_ref,
                "home_offset": self.home_offset, "held_until": self.held_until,
                "returns": {"frame": np.array([f for f, _, _ in returns], np.int64),
                            "duration": np.array([d for _, _, d in returns], np.float64),
                            **_grouped([ids for _, ids, _ in returns])},
                "reacted": {"reaction": np.array([r for r, _ in reacted], np.int64),
                            **_grouped([ids for _, ids in reacted])},
                "releases": {"frame": np.array([e[0] for e in releases], np.int64),
                             "cue": np.array([e[1] for e in releases], np.int64),
                             "stream": np.array([e[2] for e in releases], np.int64),
                             **_grouped([e[3] for e in releases])},
                "track_last": list(self._track_last), "stats": self.stats,
                "reactions": self.reactions}

    def set_state(self, state: dict):
        for k in ("home_kind", "home_ref", "home_offset", "held_until"):
            getattr(self, k)[...] = state[k]
        self._returns, self._reacted = defaultdict(list), defaultdict(list)
        self._releases = defaultdict(list)
        rel = state["releases"]
        if not (rel["frame"].size == rel["cue"].size == rel["stream"].size
                == rel["counts"].size and int(rel["counts"].sum()) == rel["ids"].size
                and (rel["counts"] >= 0).all()
                and ((rel["ids"] >= 0) & (rel["ids"] < self._n)).all()
                and ((rel["stream"] >= 0) & (rel["stream"] < self.crowd.streams.count)).all()
                and all(0 <= k < len(self.show.cues) and self.show.cues[k].action.release
                        for k in rel["cue"].tolist())):
            raise ValueError("the show's pending releases name what does not exist")
        for f, k, st, ids in zip(rel["frame"].tolist(), rel["cue"].tolist(),
                                 rel["stream"].tolist(), _ungrouped(rel)):
            self._releases[f].append((k, st, ids))
        r = state["returns"]
        for f, d, ids in zip(r["frame"].tolist(), r["duration"].tolist(), _ungrouped(r)):
            self._returns[f].append((ids, d))
        r = state["reacted"]
        for k, ids in zip(r["reaction"].tolist(), _ungrouped(r)):
            self._reacted[k].append(ids)
        last = [None if v is None else float(v) for v in state["track_last"]]
        if len(last) != len(self.show.tracks):
            raise ValueError("the show's track values do not fit its tracks")
        self._track_last = last
        self.stats = {str(c): {**dict.fromkeys(STAT_KEYS, 0),
                               **{str(k): int(v) for k, v in d.items()}}
                      for c, d in state["stats"].items()}
        self.reactions = {str(k): int(v) for k, v in state["reactions"].items()}
        c = self.crowd
        ids = [r["ids"] for r in (state["returns"], state["reacted"])]
        if not (np.isin(self.home_kind, (STREAM, UNIQUE)).all()
                and all(((i >= 0) & (i < self._n)).all() for i in ids)
                and all(int(r["counts"].sum()) == r["ids"].size and (r["counts"] >= 0).all()
                        for r in (state["returns"], state["reacted"]))
                and state["returns"]["frame"].size == state["returns"]["duration"].size
                == state["returns"]["counts"].size
                and state["reacted"]["reaction"].size == state["reacted"]["counts"].size
                and ((state["reacted"]["reaction"] >= 0)
                     & (state["reacted"]["reaction"] < len(self.show.reactions))).all()
                and np.where(self.home_kind == STREAM,
                             (self.home_ref >= 0) & (self.home_ref < c.streams.count)
                             & (self.home_offset >= 0)
                             & (self.home_offset < c.streams.max_offset),
                             (self.home_ref >= 0) & (self.home_ref < c.uniques.count)).all()):
            raise ValueError("the show's homes, returns or reactions name what does not "
                             "exist")
        self._grid_cursor = 0               # the neighbour grids are rebuilt when needed

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
            self._grid[radius] = _grid(self.crowd.agents.position, radius)
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

