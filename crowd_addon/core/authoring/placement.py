"""Agent placement policy: points of a source -> agents (heading, character, stream,
offset, colour, scale).

An agent source gives world positions (metres) and base headings (radians about
+Z) of its points; :func:`place_agents` turns them into an :class:`AgentSet` by the
source's :class:`PlacementPolicy`: a heading (fixed angle added to the base, a
per-point value, or facing a target), a character per agent (seeded random by the
characters' weights, per point, or one named character), a stream of *that
character* per agent (seeded random by its streams' weights, per point as an index
among its streams, or one named stream), an offset in ``0 .. M-1`` frames (uniform,
normal, or per point) and a colour (a base colour varied at random, or per point).
Random choices are seeded, so the same inputs give the same agents. Per-point values
come from a callback (the Blender side reads mesh attributes,
``crowd_addon.blender.agents``). Each agent's mesh variant, props and palette colours
are drawn in :mod:`.appearance`.

The crowd's stream list is the characters' streams one character after the other
(:class:`CharacterStreams` in order). A character's streams are *templates*: one with
timing variation (:class:`~.variety.Timing`) is several streams in the list, its
variants in order (:func:`.variety.expand`); the policy picks a template per agent
and :func:`.variety.choose_variants` one of its variants. An agent's stream index is
its character's first stream, plus its template's first, plus its variant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..runtime.agents import assign_offsets, assign_streams, check_offsets
from .appearance import bodies, palettes
from .config_agents import PALETTE_COLUMNS
from ..base.errors import CrowdError
from ..variety.timing import Timing, choose_variants, spread_offsets

__all__ = ["AgentSet", "CharacterStreams", "Palette", "PlacementPolicy", "place_agents",
           "z_angle", "FORWARD", "SOURCE_SEED", "CHARACTER_SEED"]

#: the character's rest-pose facing per ``forward_axis`` setting (x, y)
FORWARD = {"NEG_Y": (0.0, -1.0), "POS_Y": (0.0, 1.0), "POS_X": (1.0, 0.0),
           "NEG_X": (-1.0, 0.0)}
#: seed stride between agent sources: source ``i`` draws from ``seed + i * SOURCE_SEED``
SOURCE_SEED = 7919
#: seed stride between characters: the streams of character ``k`` are drawn from
#: ``seed + k * CHARACTER_SEED`` (character 0 draws as a crowd of one character did)
CHARACTER_SEED = 104729
#: added to a source's seed for the draw of characters by weight (offsets use ``+ 1``,
#: colours ``+ 2``)
_CHARACTER_DRAW = 3
#: added to a character's stream seed for the draw of variants, plus the template's
#: index
_VARIANT_DRAW = 7
#: added to a source's seed for the draw of scales
_SCALE_DRAW = 4


@dataclass(frozen=True)
class AgentSet:
    """Agents as arrays: positions (n, 3) float32 metres, headings (n,) float32
    radians, streams (n,) int32 stream indices, offsets (n,) int32 frames, colors
    (n, 3) float32 0..1, characters (n,) int32 character indices, scales (n,) float32
    uniform body scales, palette (n, PALETTE_COLUMNS, 3) float32 the colour of each of
    the agent's character's palette materials (-1 where it has none), variants (n,)
    int16 mesh variants, props (n,) uint8 the props each carries (a bit each;
    :mod:`.bodies`)."""

    positions: np.ndarray
    headings: np.ndarray
    streams: np.ndarray
    offsets: np.ndarray
    colors: np.ndarray
    characters: np.ndarray
    scales: np.ndarray
    palette: np.ndarray
    variants: np.ndarray
    props: np.ndarray

    @property
    def count(self) -> int:
        return int(self.offsets.shape[0])

    def add_to(self, cfg):
        """Append these agents to ``cfg`` (a ``CrowdConfig``); their ids."""
        return cfg.add_agents(self.count, streams=self.streams, offsets=self.offsets,
                              positions=self.positions, headings=self.headings,
                              colors=self.colors,
                              scales=self.scales if (self.scales != 1).any() else None,
                              palette=self.palette if (self.palette >= 0).any() else None,
                              variants=self.variants if self.variants.any() else None,
                              props=self.props if self.props.any() else None)

    @staticmethod
    def concatenate(sets):
        """One :class:`AgentSet` of ``sets`` in order (empty for none)."""
        if not sets:
            return AgentSet(np.zeros((0, 3), np.float32), np.zeros(0, np.float32),
                            np.zeros(0, np.int32), np.zeros(0, np.int32),
                            np.zeros((0, 3), np.float32), np.zeros(0, np.int32),
                            np.zeros(0, np.float32),
                            np.zeros((0, PALETTE_COLUMNS, 3), np.float32),
                            np.zeros(0, np.int16), np.zeros(0, np.uint8))
        return AgentSet(*(np.concatenate([getattr(s, f) for s in sets])
                          for f in ("positions", "headings", "streams", "offsets", "colors",
                                    "characters", "scales", "palette", "variants", "props")))


@dataclass(frozen=True)
class Palette:
    """Colours for one material slot of a character's body (``material``: the
    material's name): each agent gets one of ``colors`` ((k, 3) 0..1), at random
    (``mode`` ``"RANDOM"``, seeded) or by an INT point attribute (``"ATTRIBUTE"``:
    ``attribute`` gives the index into ``colors``, e.g. a team or a section)."""

    material: str
    colors: tuple
    mode: str = "RANDOM"
    attribute: str = "team"


@dataclass(frozen=True)
class CharacterStreams:
    """A character as the placement sees it: its ``name``, its streams' (templates')
    names and weights (in the crowd's order), its ``weight``, the relative share of
    agents a source drawing characters by weight gives it, and per template its
    :class:`~.variety.Timing` (empty: none; the crowd's list holds
    ``timing.count`` streams per template); ``palettes``: up to
    :data:`PALETTE_COLUMNS` :class:`Palette` s of its body's materials;
    ``variant_weights``: the relative share of agents of each of its mesh variants
    (empty: one body), drawn at random (``variant_mode`` ``"RANDOM"``, seeded) or read
    from the INT point attribute ``variant_attribute`` (``"ATTRIBUTE"``);
    ``prop_shares``: per prop (:mod:`.bodies`) the share of its agents, 0..1, that
    carry it (each drawn on its own, seeded)."""

    name: str
    streams: tuple = ()
    stream_weights: tuple = ()
    weight: float = 1.0
    timings: tuple = ()
    palettes: tuple = ()
    variant_weights: tuple = ()
    variant_mode: str = "RANDOM"
    variant_attribute: str = "variant"
    prop_shares: tuple = ()

    def timing(self, i: int) -> Timing:
        return self.timings[i] if self.timings else Timing()

    @property
    def variant_counts(self) -> np.ndarray:
        """(templates,) int64 streams each template is in the crowd's list."""
        return np.array([self.timing(i).count for i in range(len(self.streams))], np.int64)

    @property
    def stream_count(self) -> int:
        """Streams of this character in the crowd's list."""
        return int(self.variant_counts.sum())


@dataclass(frozen=True)
class PlacementPolicy:
    """How a source's points become agents (the settings of an agent source).

    heading_mode : ``"FIXED"`` (base heading + ``heading`` radians), ``"ATTRIBUTE"``
        (base heading + per-point ``heading_attribute``) or ``"TARGET"`` (face
        ``target``, a world position (3,), None when not chosen).
    character_mode : ``"WEIGHTS"`` (by the characters' weights), ``"ATTRIBUTE"``
        (per-point character index ``character_attribute``) or ``"FIXED"`` (the
        character ``character_name``).
    stream_mode : among the streams of each agent's character: ``"RANDOM"`` (by their
        weights), ``"ATTRIBUTE"`` (per-point index among them, ``stream_attribute``)
        or ``"FIXED"`` (the stream ``stream_name``, which must be the character's).
    offset_mode : ``"UNIFORM"``, ``"NORMAL"`` (``offset_mean``, ``offset_std`` in
        frames; negative: the defaults of :func:`.agents.assign_offsets`),
        ``"SPREAD"`` (neighbours on the same stream kept out of step:
        :func:`.variety.spread_offsets`) or ``"ATTRIBUTE"`` (per-point
        ``offset_attribute``).
    color_mode : ``"RANDOM"`` (``color`` (3,) 0..1 moved toward a random colour by
        ``color_variation``) or ``"ATTRIBUTE"`` (per-point ``color_attribute``).
    scale_min, scale_max : each agent's uniform body scale, drawn uniformly in this
        range (1, 1: none); seeded like every other draw.
    """

    heading_mode: str = "FIXED"
    heading: float = 0.0
    heading_attribute: str = "heading"
    target: tuple | None = None
    character_mode: str = "WEIGHTS"
    character_attribute: str = "character"
    character_name: str = ""
    stream_mode: str = "RANDOM"
    stream_attribute: str = "stream"
    stream_name: str = ""
    offset_mode: str = "UNIFORM"
    offset_mean: float = -1.0
    offset_std: float = -1.0
    offset_attribute: str = "offset"
    color_mode: str = "RANDOM"
    color: tuple = (0.8, 0.8, 0.8)
    color_variation: float = 0.5
    color_attribute: str = "Col"
    scale_min: float = 1.0
    scale_max: float = 1.0


def z_angle(matrix: np.ndarray) -> np.ndarray:
    """Rotation about +Z (radians) of 4x4 world matrices ``(..., 4, 4)``: (...,)."""
    return np.arctan2(matrix[..., 1, 0], matrix[..., 0, 0])


def place_agents(what: str, positions: np.ndarray, base_heading: np.ndarray,
                 policy: PlacementPolicy, *, characters, max_offset: int, seed: int,
                 forward_axis: str = "NEG_Y", attribute=None) -> AgentSet:
    """The agents of one source's points.

    Parameters
    ----------
    what : the source in error messages (e.g. ``"agent source 'seats'"``).
    positions : (n, 3) world positions; base_heading : (n,) radians about +Z.
    policy : the source's :class:`PlacementPolicy`.
    characters : sequence of :class:`CharacterStreams`, in the crowd's order (the
        crowd's streams are theirs, one character after the other).
    max_offset : M. seed : int. forward_axis : key of :data:`FORWARD`.
    attribute : ``attribute(name, kind)`` -> per-point values of the point attribute
        ``name``: kind ``"float"`` (n,), ``"int"`` (n,) or ``"color"`` (n, >= 3);
        raises a :class:`CrowdError` when the source has no such attribute.
    """
    pos = np.asarray(positions, np.float64)
    n = pos.shape[0]
    p = policy
    characters = tuple(characters)

    def values(name, kind):
        if attribute is None:
            raise CrowdError(f"{what}: this source has no point attributes "
                             f"(wanted {name!r})")
        return attribute(name, kind)

    heading = _headings(what, pos, base_heading, p, forward_axis, values)
    char = _characters(what, n, p, characters, seed, values)
    st = _streams(what, n, p, characters, char, seed, values)

    if p.offset_mode == "SPREAD":
        off = spread_offsets(pos, st, max_offset, seed + 1)
    elif p.offset_mode == "ATTRIBUTE":
        off = values(p.offset_attribute, "int")
        try:
            check_offsets(off, max_offset, f"{what}: point")
        except CrowdError as e:
            raise CrowdError(f"{e} (attribute {p.offset_attribute!r})") from None
    else:
        mean = None if p.offset_mean < 0 else p.offset_mean
        std = None if p.offset_std < 0 else p.offset_std
        off = assign_offsets(n, max_offset, p.offset_mode.lower(), seed + 1, mean, std)

    if p.color_mode == "ATTRIBUTE":
        col = values(p.color_attribute, "color")[:, :3]
    else:
        rnd = np.random.default_rng(seed + 2).uniform(0.0, 1.0, (n, 3))
        base = np.asarray(p.color, np.float64)
        col = base + p.color_variation * (rnd - base)
    col = np.clip(col, 0.0, 1.0)
    lo, hi = float(p.scale_min), float(p.scale_max)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
        raise CrowdError(f"{what}: the scale range must be finite with 0 < min <= max, got "
                         f"{p.scale_min!r} .. {p.scale_max!r}")
    scale = np.full(n, lo, np.float32) if lo == hi else \
        np.random.default_rng(seed + _SCALE_DRAW).uniform(lo, hi, n).astype(np.float32)
    palette = palettes(what, n, characters, char, seed, values)
    variants, props = bodies(what, n, characters, char, seed, values)
    return AgentSet(pos.astype(np.float32), np.asarray(heading).astype(np.float32),
                    np.asarray(st, np.int32), np.asarray(off, np.int32),
                    np.asarray(col, np.float32), char, scale, palette, variants, props)


def _headings(what, pos, base_heading, p, forward_axis, values) -> np.ndarray:
    if p.heading_mode == "TARGET":
        if p.target is None:
            raise CrowdError(f"{what}: heading faces a target but none is chosen")
        d = np.asarray(p.target, np.float64)[None, :2] - pos[:, :2]
        fx, fy = FORWARD[forward_axis]
        heading = np.arctan2(d[:, 1], d[:, 0]) - np.arctan2(fy, fx)
    elif p.heading_mode == "ATTRIBUTE":
        heading = base_heading + values(p.heading_attribute, "float")
    else:
        heading = base_heading + p.heading
    return np.mod(heading + np.pi, 2 * np.pi) - np.pi


def _characters(what, n, p, characters, seed, values) -> np.ndarray:
    """(n,) int32 character index per point."""
    names = [c.name for c in characters]
    if not names:
        raise CrowdError(f"{what}: there are no characters to place")
    if p.character_mode == "ATTRIBUTE":
        ch = np.asarray(values(p.character_attribute, "int")).astype(np.int64)
        bad = np.flatnonzero((ch < 0) | (ch >= len(names)))
        if bad.size:
            raise CrowdError(f"{what}: attribute {p.character_attribute!r} gives character "
                             f"{int(ch[bad[0]])} at point {int(bad[0])}; characters are "
                             f"0..{len(names) - 1} ({names})")
        return ch.astype(np.int32)
    if p.character_mode == "FIXED":
        if p.character_name not in names:
            raise CrowdError(f"{what}: unknown character {p.character_name!r} "
                             f"(characters: {names})")
        return np.full(n, names.index(p.character_name), np.int32)
    w = np.array([c.weight for c in characters], np.float64)
    if not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
        raise CrowdError(f"{what}: character weights must be non-negative with a positive "
                         f"sum ({dict(zip(names, w.tolist()))})")
    rng = np.random.default_rng(seed + _CHARACTER_DRAW)
    return rng.choice(len(names), size=n, p=w / w.sum()).astype(np.int32)


def _streams(what, n, p, characters, char, seed, values) -> np.ndarray:
    """(n,) int32 stream index per point in the crowd's stream list: each point's
    template among its character's streams, by the policy's stream mode, then its
    variant of that template (:mod:`.variety`)."""
    counts = np.array([len(c.streams) for c in characters], np.int64)
    totals = np.array([c.stream_count for c in characters], np.int64)
    first = np.concatenate([[0], np.cumsum(totals)[:-1]])
    present = np.unique(char).tolist()
    for k in present:
        if counts[k] == 0:
            raise CrowdError(f"{what}: character {characters[k].name!r} has no streams "
                             "(its agents need one to play)")
    if p.stream_mode == "ATTRIBUTE":
        local = np.asarray(values(p.stream_attribute, "int")).astype(np.int64)
        bad = np.flatnonzero((local < 0) | (local >= counts[char]))
        if bad.size:
            i = int(bad[0])
            c = characters[char[i]]
            raise CrowdError(f"{what}: attribute {p.stream_attribute!r} gives stream "
                             f"{int(local[i])} at point {i}; character {c.name!r} has "
                             f"streams 0..{len(c.streams) - 1} ({list(c.streams)})")
    else:
        local = np.zeros(n, np.int64)
        for k in present:
            c, mine = characters[k], char == k
            if p.stream_mode == "FIXED":
                local[mine] = _named_stream(what, p.stream_name, c, characters)
                continue
            try:
                local[mine] = assign_streams(int(mine.sum()), len(c.streams),
                                             c.stream_weights or None,
                                             seed + k * CHARACTER_SEED)
            except CrowdError as e:
                raise CrowdError(f"{what}: character {c.name!r}: {e}") from None
    out = first[char] + local
    for k in present:                      # templates -> their variants
        c = characters[k]
        if c.stream_count == len(c.streams):
            continue
        starts = np.concatenate([[0], np.cumsum(c.variant_counts)[:-1]])
        mine = np.flatnonzero(char == k)
        out[mine] = first[k] + starts[local[mine]]
        for t in range(len(c.streams)):
            timing = c.timing(t)
            if timing.count == 1:
                continue
            these = mine[local[mine] == t]
            out[these] += choose_variants(these.size, timing,
                                          seed + k * CHARACTER_SEED + _VARIANT_DRAW + t)
    return out.astype(np.int32)


def _named_stream(what, name, character, characters) -> int:
    """Index of stream ``name`` among ``character``'s streams, or a CrowdError saying
    whose stream it is."""
    if name in character.streams:
        return list(character.streams).index(name)
    owners = [c.name for c in characters if name in c.streams]
    has = f"{character.name!r} has {list(character.streams)}"
    if not owners:
        raise CrowdError(f"{what}: unknown stream {name!r} (character {has})")
    raise CrowdError(f"{what}: stream {name!r} is not a stream of character "
                     f"{character.name!r} (it is a stream of {owners[0]!r}; {has})")
