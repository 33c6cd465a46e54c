"""The variety planner: the stream count, M and offsets that repeat least within a
memory budget (``crowd plan``, the panel's *Plan Variety*).

The paper's memory model (:mod:`.budget`) says how many (stream, offset) keys a GPU
budget holds; it does not say which split a viewer sees as least repetitive. This
planner measures it: for each candidate it places the crowd's agents as a bake would
and computes the repetition metric (:mod:`.repetition`) through the camera.

What a candidate may change, per authored stream (a *template*, with the timing
variation its author gave it, :mod:`.variety`):

- ``M``, the history length, for every stream (at most the shortest clip a template
  plays, as the paper requires);
- ``copies``: phase-shifted copies of every speed stream of every template (capped
  per template at ``clip frames // M``, beyond which copies would show poses other
  copies show);
- the offset distribution: *Uniform* (every offset equally likely) or *Spread*
  (neighbours on one stream kept out of step, :func:`.variety.spread_offsets`).

What it keeps: every agent's template and speed (the author's choices), positions,
bodies and colours, the uniques and the transition slots. Memory is the pose texture
(:func:`.budget.plan` with S and M given: ``(M x S + uniques + slots)`` rows of
``bones x 48`` bytes); candidates over the budget, or with more than ``max_streams`` streams
(the per-frame CPU cost), are reported and not chosen. Among the others the lowest
metric wins; within ``TIE`` (2 %) of it, the fewest streams, then the least memory.

The screen-space neighbours are found once; each candidate only re-draws streams and
offsets and compares its pairs (a few milliseconds at 65,000 agents).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..runtime.agents import STREAM, UNIQUE
from ..meshes.bodies import body_keys
from .budget import plan as budget_plan
from ..base.errors import CrowdError
from ..variety.repetition import (RepetitionSettings, colors_shown, nearest_neighbours,
                                  pairs_alike, screen_points, stream_periods)
from ..variety.timing import spread_offsets

__all__ = ["Template", "PlanInput", "Candidate", "VarietyPlan", "plan_input", "plan_variety",
           "M_CHOICES", "COPY_CHOICES", "OFFSET_MODES", "MAX_STREAMS", "TIE"]

#: history lengths tried (besides the current one), frames
M_CHOICES = (15, 20, 30, 40, 60, 90, 120, 180, 240, 300)
#: copies per speed stream tried
COPY_CHOICES = (1, 2, 3, 4, 6, 8)
#: offset distributions tried
OFFSET_MODES = ("UNIFORM", "SPREAD")
#: streams a plan may use by default: the paper's 256 (its per-frame CPU cost)
MAX_STREAMS = 256
#: metrics within this share of the lowest are a tie (then fewer streams, then less
#: memory, win)
TIE = 0.02


@dataclass(frozen=True)
class Template:
    """An authored stream: ``name``, its speed streams (``speeds``), its
    ``clip_frames``, the shortest clip its tree plays, and its ``period`` (``inf``: it
    does not repeat, :func:`.repetition.stream_periods`), in crowd frames at speed 1."""

    name: str
    speeds: tuple
    clip_frames: float
    period: float = float("inf")


@dataclass(frozen=True)
class PlanInput:
    """The agents a plan places, as arrays over all ``n`` agents.

    positions (n, 3), colors (n, 3 + 12) float (:func:`.repetition.colors_shown`);
    look (n,) int body (:func:`~.bodies.body_keys`); template (n,) int (an
    index into ``templates``, -1 for agents on a unique); speed (n,) int the agent's
    speed stream within its template; unique (n,) int (-1 for streamed agents).
    ``max_offset``, ``copies`` (per template), ``offsets`` (n,), ``streams`` (n,) and
    the streams' ``periods`` (S,) are the configuration as it is (the *default*);
    ``bones``: the pose row's bones; ``uniques``, ``slots``: the fixed rows; ``seed``
    the draws'."""

    positions: np.ndarray
    colors: np.ndarray
    look: np.ndarray
    template: np.ndarray
    speed: np.ndarray
    unique: np.ndarray
    templates: tuple
    max_offset: int
    copies: tuple
    offsets: np.ndarray
    streams: np.ndarray
    bones: int
    uniques: int
    slots: int
    seed: int = 0
    periods: np.ndarray = None

    @property
    def count(self) -> int:
        return int(self.template.size)


@dataclass(frozen=True)
class Candidate:
    """One choice: ``max_offset`` M, ``copies`` asked (``template_copies`` per template
    after the clip cap), ``offset_mode``, the ``streams`` and ``bytes`` it needs,
    whether it ``fits`` (budget and stream cap) and its ``repetition``."""

    max_offset: int
    copies: int
    offset_mode: str
    template_copies: tuple
    streams: int
    bytes: int
    fits: bool
    repetition: float | None


@dataclass(frozen=True)
class VarietyPlan:
    """The planner's answer: ``default`` (the configuration as it is, measured on its
    own agents), ``planned`` (the chosen candidate), every ``candidates`` tried, the
    ``budget_bytes`` and ``max_streams`` it kept to, the metric's ``settings`` and the
    ``templates``' names (the order of ``Candidate.template_copies``)."""

    default: Candidate
    planned: Candidate
    candidates: tuple
    budget_bytes: float
    max_streams: int
    agents: int
    visible: int
    settings: RepetitionSettings = field(default_factory=RepetitionSettings)
    notes: tuple = ()
    templates: tuple = ()          # the templates' names, in ``template_copies`` order

    def as_dict(self) -> dict:
        return {"repetition_default": self.default.repetition,
                "repetition_planned": self.planned.repetition,
                "default": asdict(self.default), "planned": asdict(self.planned),
                "budget_bytes": self.budget_bytes, "max_streams": self.max_streams,
                "agents": self.agents, "visible": self.visible, "k": self.settings.k,
                "offset_tolerance": self.settings.offset_tolerance,
                "appearance": self.settings.appearance,
                "templates": list(self.templates),
                "candidates": [asdict(c) for c in self.candidates],
                "notes": list(self.notes)}


def _tree_clips(root):
    stack, out = [root], []
    while stack:
        node = stack.pop()
        if hasattr(node, "clip") and isinstance(getattr(node, "clip"), str):
            out.append((node.clip, abs(float(getattr(node, "speed", 1.0))) or 1.0))
        stack.extend(node.children())
    return out


def plan_input(cfg, offsets=None, seed=None) -> PlanInput:
    """The :class:`PlanInput` of a configuration: its streams grouped by template
    (``AnimationDef.template_name``), its agents with their template, speed stream,
    body and colour; ``offsets`` overrides the agents' offsets (default theirs)."""
    from ..authoring.config import validate_config
    validate_config(cfg)
    skeletons = list(cfg.skeletons)
    periods = stream_periods(cfg)
    names, speeds, clip_frames, copies, period = [], {}, {}, {}, {}
    of_stream = np.zeros((len(cfg.streams), 2), np.int64)      # template, speed index
    for i, d in enumerate(cfg.streams):
        t = d.template_name
        if t not in speeds:
            names.append(t)
            speeds[t], copies[t] = [], {}
            lengths = [cfg.clips[c].frames_at(cfg.fps) / s for c, s in _tree_clips(d.root)]
            clip_frames[t] = min(lengths) if lengths else float("inf")
            period[t] = float(periods[i] * d.speed)
        v = round(float(d.speed), 9)
        if v not in speeds[t]:
            speeds[t].append(v)
        copies[t][v] = copies[t].get(v, 0) + 1
        of_stream[i] = names.index(t), speeds[t].index(v)
    st = np.asarray(cfg.agent_stream, np.int64)
    streamed = st >= 0
    template = np.where(streamed, of_stream[np.maximum(st, 0), 0], -1)
    speed = np.where(streamed, of_stream[np.maximum(st, 0), 1], 0)
    stream_skel = np.array([skeletons.index(d.skeleton) for d in cfg.streams] + [0], np.int64)
    unique_skel = np.array([skeletons.index(d.skeleton) for d in cfg.uniques] + [0], np.int64)
    un = np.asarray(cfg.agent_unique, np.int64)
    look = body_keys(cfg, np.where(streamed, stream_skel[st], unique_skel[un]))[1]
    bones = max(sk.bone_count for sk in cfg.skeletons.values())
    return PlanInput(
        positions=np.asarray(cfg.agent_position, np.float64),
        colors=colors_shown(cfg.agent_color, cfg.palette), look=look, template=template,
        speed=speed, unique=np.where(streamed, -1, un),
        templates=tuple(Template(t, tuple(speeds[t]), clip_frames[t], period[t])
                        for t in names),
        max_offset=int(cfg.max_offset),
        copies=tuple(max(copies[t].values()) for t in names),
        offsets=np.asarray(cfg.agent_offset if offsets is None else offsets, np.int64),
        streams=st, bones=int(bones), uniques=len(cfg.uniques),
        slots=int(cfg.transition_slots), seed=int(cfg.seed if seed is None else seed),
        periods=periods)


def _template_copies(inp, m, copies):
    return tuple(int(min(copies, max(1, np.floor(t.clip_frames / m))))
                 for t in inp.templates)


def _streams_of(inp, template_copies):
    """(first stream per template, per-template speed count) of a layout."""
    per = np.array([len(t.speeds) * c for t, c in zip(inp.templates, template_copies)],
                   np.int64)
    return np.concatenate([[0], np.cumsum(per)[:-1]]), int(per.sum())


def _periods(inp, template_copies) -> np.ndarray:
    """(S,) periods of a layout's streams (template, speed, copy order)."""
    return np.array([t.period / v for t, c in zip(inp.templates, template_copies)
                     for v in t.speeds for _ in range(c)], np.float64)


def _memory(inp, m, streams) -> int:
    """Pose-texture bytes of ``streams`` streams of M = ``m`` frames, by the memory
    model's GPU layout (:func:`.budget.plan` with S and M given)."""
    return budget_plan(max(inp.count, inp.uniques), 1e300, inp.bones, [m],
                       max_offset=m, streams=max(streams, 1), unique_agents=inp.uniques,
                       transition_slots=inp.slots).bytes_used


def _assign(inp, m, template_copies, mode, seed):
    """(stream (n,), offset (n,)) of streamed agents for one candidate; -1 on uniques."""
    rng = np.random.default_rng(seed)
    first, _ = _streams_of(inp, template_copies)
    tc = np.array(template_copies + (1,), np.int64)
    t = inp.template
    on = t >= 0
    c = tc[t]
    copy = np.floor(rng.random(inp.count) * c).astype(np.int64)
    stream = np.where(on, first[np.maximum(t, 0)] + inp.speed * c + copy, -1)
    if mode == "SPREAD":
        off = spread_offsets(inp.positions, stream, m, seed + 1).astype(np.int64)
    elif mode == "UNIFORM":
        off = rng.integers(0, m, inp.count)
    else:
        raise CrowdError(f"plan: unknown offset mode {mode!r} (choose from {OFFSET_MODES})")
    return stream, off


class _Pairs:
    """The screen-space neighbour pairs of the agents, found once."""

    def __init__(self, inp, view_projection, settings):
        xy, vis = screen_points(inp.positions, view_projection, settings.width,
                                settings.height)
        idx = np.flatnonzero(vis)
        nb = nearest_neighbours(xy[idx], settings.k)
        ok = nb >= 0
        self.i = idx[np.repeat(np.arange(idx.size), ok.sum(1))]
        self.j = idx[nb[ok]]
        self.visible = int(idx.size)
        self.inp, self.settings = inp, settings

    def metric(self, stream, offset, periods) -> float | None:
        if not self.i.size:
            return None
        inp = self.inp
        kind = np.where(stream >= 0, STREAM, UNIQUE).astype(np.int8)
        ref = np.where(stream >= 0, stream, inp.unique)
        alike = pairs_alike(self.i, self.j, kind, ref, offset, inp.look, inp.colors,
                            self.settings, periods)
        return float(alike.mean())


def plan_variety(inp: PlanInput, view_projection, budget_bytes: float,
                 settings: RepetitionSettings = RepetitionSettings(),
                 max_streams: int = MAX_STREAMS, m_choices=M_CHOICES,
                 copy_choices=COPY_CHOICES, offset_modes=OFFSET_MODES,
                 progress=None) -> VarietyPlan:
    """Try every (M, copies, offset mode) of the choices and return the
    :class:`VarietyPlan` (module docstring). ``progress(done, total)`` after each."""
    budget = float(budget_bytes)
    if not (np.isfinite(budget) and budget > 0):
        raise CrowdError(f"plan: the budget must be a positive number of bytes, got "
                         f"{budget_bytes!r}")
    if isinstance(max_streams, bool) or int(max_streams) < 1:
        raise CrowdError(f"plan: max streams must be >= 1, got {max_streams!r}")
    if not inp.templates or not (inp.template >= 0).any():
        raise CrowdError("plan: no agent plays a stream; there is nothing to plan")
    pairs = _Pairs(inp, view_projection, settings)
    shortest = min(t.clip_frames for t in inp.templates)
    ms = sorted({int(m) for m in (*m_choices, inp.max_offset) if 1 <= int(m) <= shortest})
    notes = []
    if not ms:
        raise CrowdError(f"plan: the shortest clip is {shortest:g} frames; no M fits")
    if max(m_choices) > shortest:
        notes.append(f"M at most the shortest clip, {shortest:g} frames")
    _, now_streams = _streams_of(inp, inp.copies)
    default = Candidate(inp.max_offset, max(inp.copies), "AS IS", tuple(inp.copies),
                        now_streams, _memory(inp, inp.max_offset, now_streams),
                        _memory(inp, inp.max_offset, now_streams) <= budget
                        and now_streams <= max_streams,
                        pairs.metric(inp.streams, inp.offsets, inp.periods))
    grid = [(m, c, mode) for m in ms for c in copy_choices for mode in offset_modes]
    seen, out = set(), []
    for n, (m, c, mode) in enumerate(grid):
        tc = _template_copies(inp, m, c)
        if (m, tc, mode) in seen:          # the clip cap made it the same as another
            continue
        seen.add((m, tc, mode))
        _, streams = _streams_of(inp, tc)
        size = _memory(inp, m, streams)
        fits = size <= budget and streams <= max_streams
        value = None
        if fits:
            value = pairs.metric(*_assign(inp, m, tc, mode, inp.seed + 17 * n),
                                 _periods(inp, tc))
        out.append(Candidate(m, c, mode, tc, streams, size, fits, value))
        if progress is not None:
            progress(n + 1, len(grid))
    ok = [c for c in out if c.fits and c.repetition is not None]
    if not ok:
        raise CrowdError(f"plan: no candidate fits {budget:,.0f} B and {max_streams} "
                         f"streams (the smallest needs {min(c.bytes for c in out):,} B)")
    best = min(c.repetition for c in ok)
    planned = min((c for c in ok if c.repetition <= best * (1 + TIE)),
                  key=lambda c: (c.streams, c.bytes, c.repetition))
    return VarietyPlan(default, planned, tuple(out), budget, int(max_streams), inp.count,
                       pairs.visible, settings, tuple(notes),
                       tuple(t.name for t in inp.templates))
