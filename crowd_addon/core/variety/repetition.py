"""How much a crowd repeats itself on screen: the repetition metric.

The paper judges diversity by eye; this measures it. Seen from a camera, every visible
agent is paired with its ``k`` nearest visible agents in screen space (pixels). A pair
*looks alike* when, at that frame, both agents

- play the same stream with offsets at most ``offset_tolerance`` frames apart (on a
  stream that loops with a period of ``P`` frames, offsets ``P`` apart show the same
  pose: the distance is taken around the loop, :func:`stream_periods`), or the same
  unique (which shows one pose to all its agents);
- use the same body (``look``: the character's mesh, or its variant);
- have colours within ``color_tolerance`` of each other (largest RGB channel
  difference, 0..1): the agent's colour and its palette colours (:func:`colors_shown`).

Agents blending in a transition slot show a pose of their own and look like nobody.
The metric is the share of such neighbour pairs that look alike (pairs are ordered:
``(i, j)`` with ``j`` among ``i``'s neighbours), averaged over the frames measured:
0 when no neighbours are in step, 1 when every agent looks like all its neighbours (one
stream at one offset). Occlusion is ignored: "visible" is inside the camera's frustum.

Nothing here costs per frame of a running crowd: the metric is measured on demand (the
panel, ``crowd preview``, ``crowd demo``, ``crowd export``, ``crowd plan``). Neighbours
are found exactly with a multi-level grid, numpy only (:func:`nearest_neighbours`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..runtime.agents import STREAM, TRANSITION, UNIQUE
from ..meshes.bodies import body_keys
from ..base.errors import CrowdError

__all__ = ["OFFSET_TOLERANCE", "RepetitionSettings", "Repetition", "nearest_neighbours", "screen_points",
           "screen_neighbours", "pairs_alike", "frame_repetition", "crowd_repetition", "recording_repetition",
           "recording_repetition_steps", "measure_frames", "describe", "combine",
           "stream_periods", "colors_shown"]

#: offsets at most this many frames apart look alike (the default tolerance)
OFFSET_TOLERANCE = 2
#: points at or below which neighbours are found by brute force
_BRUTE = 2048
#: distances computed at once by the brute-force comparison
_BLOCK_CELLS = 1 << 22


@dataclass(frozen=True)
class RepetitionSettings:
    """What counts as a neighbour and as alike. ``k`` neighbours per agent; offsets at
    most ``offset_tolerance`` frames apart (2 frames: 1/15 s at 30 fps, too close for a
    viewer to tell apart); colours within ``color_tolerance`` per RGB channel;
    ``width`` x ``height`` pixels of the screen the camera's image fills; ``frames``
    measured over a shot, spread evenly (the first and the last among them);
    ``appearance`` False compares motion alone (bodies and colours are not compared:
    the part of the likeness the planner's choices change)."""

    k: int = 6
    offset_tolerance: int = OFFSET_TOLERANCE
    color_tolerance: float = 0.05
    width: int = 1280
    height: int = 720
    frames: int = 8
    appearance: bool = True

    def __post_init__(self):
        for name in ("k", "width", "height", "frames"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or int(v) < 1:
                raise CrowdError(f"repetition: {name} must be an integer >= 1, got {v!r}")
            object.__setattr__(self, name, int(v))
        tol = self.offset_tolerance
        if isinstance(tol, bool) or int(tol) != tol or int(tol) < 0:
            raise CrowdError(f"repetition: offset_tolerance must be an integer >= 0 (frames), "
                             f"got {tol!r}")
        object.__setattr__(self, "offset_tolerance", int(tol))
        c = float(self.color_tolerance)
        if not (np.isfinite(c) and 0 <= c <= 1):
            raise CrowdError(f"repetition: color_tolerance must be in 0..1, got "
                             f"{self.color_tolerance!r}")
        object.__setattr__(self, "color_tolerance", c)
        if not isinstance(self.appearance, (bool, np.bool_)):
            raise CrowdError(f"repetition: appearance must be True or False, got "
                             f"{self.appearance!r}")


@dataclass(frozen=True)
class Repetition:
    """The metric over the frames measured: ``value`` is the mean of ``per_frame``
    (frames without a visible neighbour pair are left out; ``None`` when no frame had
    one). ``visible`` and ``pairs`` are per frame too."""

    value: float | None
    frames: tuple
    per_frame: tuple
    visible: tuple
    pairs: tuple
    settings: RepetitionSettings = field(default_factory=RepetitionSettings)

    def as_dict(self) -> dict:
        s = self.settings
        return {"value": None if self.value is None else round(self.value, 6),
                "frames": list(self.frames),
                "per_frame": [None if v is None else round(v, 6) for v in self.per_frame],
                "visible": list(self.visible), "pairs": list(self.pairs),
                "k": s.k, "offset_tolerance": s.offset_tolerance,
                "color_tolerance": s.color_tolerance, "screen": [s.width, s.height]}

    def line(self) -> str:
        """One line for a terminal or a panel (:func:`describe`)."""
        return describe(self.as_dict())


def describe(measured: dict) -> str:
    """One line for :meth:`Repetition.as_dict`'s dict (what exports report)."""
    value, n = measured["value"], len(measured["frames"])
    if value is None:
        return "repetition: no visible neighbours"
    vis = int(round(np.mean(measured["visible"]))) if measured["visible"] else 0
    return (f"repetition {value:.3f} ({value * 100:.1f} % of neighbour pairs alike; "
            f"k={measured['k']}, {vis:,} agents visible, {n} frame{'s' if n != 1 else ''})")


# ------------------------------------------------------------------ neighbours

def nearest_neighbours(points, k: int) -> np.ndarray:
    """The ``k`` nearest other points of each of ``points`` ((n, 2), any units):
    (n, k) int64 indices ordered by (distance, index), ``-1`` where there are fewer
    than ``k`` other points. Exact: a grid at several cell sizes, finest first, settles
    each point whose ``k``-th candidate is nearer than the cell size (nothing outside
    the 3 x 3 cells around it can be nearer); the rest are compared with every point."""
    xy = np.asarray(points, np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise CrowdError(f"repetition: points must be (n, 2), got {xy.shape}")
    if not np.isfinite(xy).all():
        raise CrowdError("repetition: points must be finite")
    n, k = xy.shape[0], int(k)
    if k < 1:
        raise CrowdError(f"repetition: k must be >= 1, got {k}")
    out = np.full((n, k), -1, np.int64)
    kk = min(k, n - 1)
    if kk < 1:
        return out
    todo = np.arange(n)
    if n > _BRUTE:
        todo = _grid_pass(xy, kk, out)
    block = max(1, _BLOCK_CELLS // n)
    for a in range(0, todo.size, block):
        q = todo[a:a + block]
        out[q, :kk] = _brute(xy, q, kk)
    return out


def _d2(xy, q, j):
    d = xy[q] - xy[j]
    return d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]


def _brute(xy, q, kk):
    """(len(q), kk) nearest of ``q`` among all points, by (distance, index)."""
    d2 = _d2(xy, q[:, None], np.arange(xy.shape[0])[None, :])
    d2[np.arange(q.size), q] = np.inf
    kth = np.partition(d2, kk - 1, axis=1)[:, kk - 1:kk]
    rows, cols = np.nonzero(d2 <= kth)           # the kk nearest and any ties at the kth
    order = np.lexsort((cols, d2[rows, cols], rows))
    rows, cols = rows[order], cols[order]
    start = np.searchsorted(rows, np.arange(q.size))
    return cols[start[:, None] + np.arange(kk)]


def _grid_pass(xy, kk, out) -> np.ndarray:
    """Fill ``out`` for the points the grids settle; returns the others.

    Each point has its own cell size ``base * 2**e``: it starts at the size where a
    uniform spread would put about ``kk`` points in a cell and moves finer while its
    3 x 3 cells hold more than ``cap`` candidates (a dense cluster), coarser while they
    hold too few or do not settle it. The finest pending size is worked first, one
    grid of all points per size visited."""
    n = xy.shape[0]
    lo = xy.min(0)
    extent = float(max(np.ptp(xy[:, 0]), np.ptp(xy[:, 1]), 1e-12))
    cap = max(64, 16 * kk)                   # candidates a point may gather at one level
    base = extent * np.sqrt(kk / n)
    level = np.zeros(n, np.int64)
    uncapped = np.zeros(n, bool)             # found too sparse one size finer
    todo, left = np.arange(n), []
    while todo.size:
        lev = int(level[todo].min())
        now = level[todo] == lev
        at, todo = todo[now], todo[~now]
        h = base * 2.0 ** lev
        if h > 4 * extent or lev < -48:      # no size settles these: compare with all
            left.append(at)
            continue
        dense, sparse, total = _grid_level(xy, lo, h, kk, cap, uncapped, at, out)
        level[dense] -= np.maximum(1, np.floor(0.5 * np.log2(total / (2 * kk)))).astype(
            np.int64)
        level[sparse] += 1
        uncapped[sparse] = True
        todo = np.concatenate([todo, dense, sparse])
    return np.concatenate(left) if left else np.zeros(0, np.int64)


def _grid_level(xy, lo, h, kk, cap, uncapped, todo, out):
    """Work the points ``todo`` on a grid of cell size ``h``: fill ``out`` for those it
    settles; returns ``(dense, sparse, dense_totals)`` of the others."""
    cell = np.floor((xy - lo) / h).astype(np.int64) + 1
    ny = int(cell[:, 1].max()) + 2
    cid = cell[:, 0] * ny + cell[:, 1]
    order = np.argsort(cid, kind="stable")
    cells, starts, counts = np.unique(cid[order], return_index=True, return_counts=True)
    near = (cid[todo][:, None] + (np.array([-1, 0, 1])[:, None] * ny
                                  + np.array([-1, 0, 1])[None, :]).reshape(1, 9))
    at = np.clip(np.searchsorted(cells, near), 0, cells.size - 1)
    cnt = np.where(cells[at] == near, counts[at], 0)
    total = cnt.sum(1)
    dense = (total > cap) & ~uncapped[todo]
    ok = (total > kk) & ~dense
    settled = np.zeros(todo.size, bool)
    if ok.any():
        q, at, cnt = todo[ok], at[ok], cnt[ok]
        # every (query, candidate) pair of the 3 x 3 cells, query-major
        flat = cnt.reshape(-1)
        owner = np.repeat(np.repeat(np.arange(q.size), 9), flat)
        first = np.repeat(starts[at].reshape(-1), flat)
        step = np.arange(flat.sum()) - np.repeat(np.cumsum(flat) - flat, flat)
        cand = order[first + step]
        qi = q[owner]
        d2 = _d2(xy, qi, cand)
        d2[cand == qi] = np.inf
        picked, kth = _smallest_all(owner, cand, d2, cnt.sum(1), kk)
        done = kth < h * h * (1 - 1e-9)
        out[q[done], :kk] = picked[done]
        settled[np.flatnonzero(ok)[done]] = True
    sparse = ~dense & ~settled
    return todo[dense], todo[sparse], total[dense]


def _smallest_all(owner, cand, d2, totals, kk):
    """:func:`_smallest` over queries of any widths, in blocks of similar widths that
    keep the padded arrays near ``_BLOCK_CELLS``."""
    q = totals.size
    if q * int(totals.max()) <= _BLOCK_CELLS:
        return _smallest(owner, cand, d2, totals, kk)
    start = np.cumsum(totals) - totals
    picked = np.empty((q, kk), np.int64)
    kth = np.empty(q)
    order = np.argsort(totals, kind="stable")
    width = totals[order]
    a = 0
    while a < q:
        fits = (np.arange(1, q - a + 1) * width[a:]) <= _BLOCK_CELLS
        b = a + max(1, int(np.searchsorted(~fits, True)))
        sel = order[a:b]
        a = b
        idx = _ranges(start[sel], totals[sel])
        local = np.repeat(np.arange(sel.size), totals[sel])
        picked[sel], kth[sel] = _smallest(local, cand[idx], d2[idx], totals[sel], kk)
    return picked, kth


def _ranges(starts, lengths):
    """Concatenated ``arange(s, s + n)`` for each (s, n)."""
    return np.repeat(starts - np.cumsum(lengths) + lengths, lengths) + np.arange(lengths.sum())


def _smallest(owner, cand, d2, totals, kk):
    """Per query (``owner``: query-major pairs, ``totals`` pairs each, all > kk): the
    ``kk`` candidates of smallest ``(d2, cand)``, (q, kk), and the kk-th ``d2``, (q,)."""
    q = totals.size
    start = np.cumsum(totals) - totals
    col = np.arange(owner.size) - start[owner]
    dist = np.full((q, int(totals.max())), np.inf)
    who = np.full(dist.shape, np.iinfo(np.int64).max, np.int64)
    dist[owner, col], who[owner, col] = d2, cand
    part = np.argpartition(dist, kk - 1, axis=1)[:, :kk]
    d_sel = np.take_along_axis(dist, part, 1)
    c_sel = np.take_along_axis(who, part, 1)
    kth = d_sel.max(1)
    tied = (dist <= kth[:, None]).sum(1) > kk       # another candidate ties the kk-th
    for r in np.flatnonzero(tied):                   # rare: floats seldom tie
        o = np.lexsort((who[r], dist[r]))[:kk]
        d_sel[r], c_sel[r] = dist[r, o], who[r, o]
    rows = np.repeat(np.arange(q), kk)
    o = np.lexsort((c_sel.reshape(-1), d_sel.reshape(-1), rows)).reshape(q, kk)
    flat_c, flat_d = c_sel.reshape(-1), d_sel.reshape(-1)
    return flat_c[o], flat_d[o][:, -1]


# ------------------------------------------------------------------ the metric

def screen_points(positions, view_projection, width: int, height: int):
    """World ``positions`` (n, 3) seen through ``view_projection`` (4, 4, OpenGL clip
    space): ``(xy, visible)``, (n, 2) float64 pixels and (n,) bool (inside the
    frustum)."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    vp = np.asarray(view_projection, np.float64)
    if vp.shape != (4, 4) or not np.isfinite(vp).all():
        raise CrowdError(f"repetition: view_projection must be a finite 4x4 matrix, got "
                         f"{vp.shape}")
    clip = p @ vp[:3, :3].T + vp[:3, 3]
    w = p @ vp[3, :3] + vp[3, 3]
    front = w > 1e-9
    ndc = clip / np.where(front, w, 1.0)[:, None]
    visible = front & (np.abs(ndc) <= 1.0).all(1)
    xy = np.stack([(ndc[:, 0] + 1) * 0.5 * width, (ndc[:, 1] + 1) * 0.5 * height], 1)
    return xy, visible


def stream_periods(config) -> np.ndarray:
    """(S,) float64: the period in crowd frames of each of ``config``'s streams, ``inf``
    when it does not repeat. A stream repeats when every clip its tree plays loops with
    one period (the clip's length at the player's speed) and no state machine (whose
    states change with triggers and parameters) is in it; at the stream's speed the
    period is that over the speed."""
    from ..anim.controllers import ClipPlayer
    from ..anim.state_machine import StateMachine
    out = np.full(len(config.streams), np.inf)
    for s, d in enumerate(config.streams):
        stack, periods, ok = [d.root], set(), True
        while stack and ok:
            node = stack.pop()
            if isinstance(node, StateMachine):
                ok = False
            elif isinstance(node, ClipPlayer):
                clip = config.clips.get(node.clip)
                if clip is None or not clip.loop or node.speed == 0:
                    ok = False
                else:
                    periods.add(round(clip.frames_at(config.fps) / abs(node.speed), 6))
            stack.extend(node.children())
        if ok and len(periods) == 1:
            out[s] = periods.pop() / d.speed
    return out


def colors_shown(color, palette=None) -> np.ndarray:
    """(n, 3 + 12) the colours an agent shows: its colour (n, 3) and its palette
    colours (n, 4, 3; -1 where none), side by side, compared channel by channel."""
    color = np.asarray(color, np.float64).reshape(-1, 3)
    if palette is None:
        return color
    return np.concatenate([color, np.asarray(palette, np.float64).reshape(len(color), -1)], 1)


def pairs_alike(i, j, kind, ref, offset, look, color, settings: RepetitionSettings,
                period=None):
    """(len(i),) bool: agents ``i[p]`` and ``j[p]`` look alike (module docstring);
    ``period``: (S,) the streams' periods (:func:`stream_periods`; None: none
    repeats)."""
    kind, ref, offset = np.asarray(kind), np.asarray(ref), np.asarray(offset)
    look, color = np.asarray(look), np.asarray(color, np.float64)
    same = (kind[i] == kind[j]) & (kind[i] != TRANSITION) & (ref[i] == ref[j])
    d = np.abs(offset[i].astype(np.float64) - offset[j])
    if period is not None and len(period):
        p = np.asarray(period, np.float64)[np.clip(ref[i], 0, len(period) - 1)]
        loops = (kind[i] == STREAM) & np.isfinite(p)
        r = np.mod(d[loops], p[loops])
        d[loops] = np.minimum(r, p[loops] - r)
    same &= (kind[i] == UNIQUE) | (d <= settings.offset_tolerance + 1e-9)
    if settings.appearance:
        same &= look[i] == look[j]
        same &= (np.abs(color[i] - color[j]) <= settings.color_tolerance + 1e-9).all(1)
    return same


def screen_neighbours(positions, view_projection,
                      settings: RepetitionSettings = RepetitionSettings()) -> tuple:
    """``(idx, nb)``: the agents in view (ids into ``positions``) and the ``settings.k``
    nearest of each on screen (indices into ``idx``, -1 none)."""
    xy, vis = screen_points(positions, view_projection, settings.width, settings.height)
    idx = np.flatnonzero(vis)
    return idx, nearest_neighbours(xy[idx], settings.k)


def frame_repetition(positions, kind, ref, offset, look, color, view_projection,
                     settings: RepetitionSettings = RepetitionSettings(), period=None,
                     neighbours=None):
    """One frame: ``(share, visible, pairs)``; share is None without a pair. Arrays are
    per agent: positions (n, 3) metres, kind/ref/offset as ``AgentState``, look (n,)
    int (body), color (n, 3); ``period`` as :func:`pairs_alike`; ``neighbours``:
    :func:`screen_neighbours` of these positions when known (agents that did not move)."""
    idx, nb = screen_neighbours(positions, view_projection, settings) if neighbours is None \
        else neighbours
    valid = nb >= 0
    pairs = int(valid.sum())
    if not pairs:
        return None, int(idx.size), 0
    i = idx[np.repeat(np.arange(idx.size), valid.sum(1))]
    j = idx[nb[valid]]
    alike = pairs_alike(i, j, kind, ref, offset, look, color, settings, period)
    return float(alike.sum()) / pairs, int(idx.size), pairs


def combine(parts) -> Repetition:
    """One :class:`Repetition` of several (frames in order; the first one's settings),
    e.g. frames measured one at a time as a crowd runs."""
    parts = list(parts)
    if not parts:
        raise CrowdError("repetition: nothing measured to combine")
    results = [(v, n, p) for r in parts for v, n, p in zip(r.per_frame, r.visible, r.pairs)]
    return _report([f for r in parts for f in r.frames], results, parts[0].settings)


def _report(frames, results, settings) -> Repetition:
    shares = [r[0] for r in results]
    kept = [s for s in shares if s is not None]
    return Repetition(float(np.mean(kept)) if kept else None, tuple(int(f) for f in frames),
                      tuple(shares), tuple(r[1] for r in results),
                      tuple(r[2] for r in results), settings)


def crowd_repetition(view, view_projection, look=None,
                     settings: RepetitionSettings = RepetitionSettings()) -> Repetition:
    """The metric of a running crowd at its current frame (``view``: ``crowd.view``).
    ``look``: (N,) int body per agent; default the crowd's (``view.agent_body``: the
    mesh variant and props of each, :mod:`.bodies`)."""
    a = view.agents
    look = view.agent_body if look is None else look
    r = frame_repetition(a.position, a.kind, a.ref, a.offset, look,
                         colors_shown(a.color, getattr(a, "palette", None)),
                         view_projection, settings, stream_periods(view.config))
    return _report([view.frame], [r], settings)


def measure_frames(first: int, last: int, count: int) -> list:
    """At most ``count`` frames spread evenly over ``first .. last`` (both ends)."""
    if last < first:
        raise CrowdError(f"repetition: empty frame range {first}..{last}")
    if count < 1:
        raise CrowdError(f"repetition: frames to measure must be >= 1, got {count}")
    return sorted({int(round(v)) for v in np.linspace(first, last, count)})


def recording_repetition(rec, view_projection, frames=None, look=None, agents=None,
                         settings: RepetitionSettings = RepetitionSettings()) -> Repetition:
    """The metric of a recorded shot (:class:`~.recording.Recording`) at ``frames``
    (default: ``settings.frames`` spread over the shot), from what each agent plays and
    where it stands at each of them; ``agents``: ids measured (default all)."""
    steps = recording_repetition_steps(rec, view_projection, frames, look, agents, settings)
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value


def recording_repetition_steps(rec, view_projection, frames=None, look=None, agents=None,
                               settings: RepetitionSettings = RepetitionSettings()):
    """:func:`recording_repetition` as a generator: yields ``(done, total)`` after each
    frame measured and returns the :class:`Repetition`. Its input is checked when it
    is called."""
    frames = measure_frames(rec.first, rec.last, settings.frames) if frames is None \
        else list(frames)
    bad = [f for f in frames if not rec.first <= f <= rec.last]
    if bad:
        raise CrowdError(f"repetition: frame {bad[0]} is outside the shot "
                         f"{rec.first}..{rec.last}")
    look = body_keys(rec.config, rec.agent_skeleton)[1] if look is None \
        else np.asarray(look)
    agents = np.arange(rec.agent_count, dtype=np.int64) if agents is None \
        else np.asarray(agents, np.int64)
    return _recording_steps(rec, view_projection, frames, look, agents, settings)


def _recording_steps(rec, view_projection, frames, look, agents, settings):
    period = stream_periods(rec.config)
    shown = colors_shown(rec.color, rec.palettes)
    results, seen = [], None            # seen: the last positions and their neighbours
    for f in frames:
        seg = _last_at(rec.segment_agent, rec.segment_frame, agents, f)
        kind, ref, off = rec.segment_kind[seg], rec.segment_ref[seg], rec.segment_offset[seg]
        pos = rec.position[agents]
        if rec.move_agent.size:
            mv = _last_at(rec.move_agent, rec.move_frame, agents, f, missing=True)
            has = mv >= 0
            pos[has] = rec.move_position[mv[has]]
        if seen is None or not np.array_equal(seen[0], pos):    # nobody moved: the same
            seen = (pos, screen_neighbours(pos, view_projection, settings))
        results.append(frame_repetition(pos, kind, ref, off, look[agents], shown[agents],
                                        view_projection, settings, period, seen[1]))
        yield len(results), len(frames)
    return _report(frames, results, settings)


def _last_at(owner, frame, agents, at, missing=False):
    """Per agent, the index of its last entry (entries sorted by (owner, frame)) at or
    before frame ``at``; -1 where it has none (only with ``missing``)."""
    owner = np.asarray(owner, np.int64)
    frame = np.asarray(frame, np.int64)
    span = int(max(frame.max(initial=0), at)) - int(min(frame.min(initial=0), at)) + 2
    base = int(min(frame.min(initial=0), at))
    key = owner * span + (frame - base)
    pos = np.searchsorted(key, agents * span + (at - base), side="right") - 1
    if not missing:
        return pos
    ok = pos >= 0
    ok[ok] = owner[pos[ok]] == agents[ok]
    return np.where(ok, pos, -1)
