"""Agent placement policy: points of a source -> agents (heading, stream, offset, colour).

An agent source gives world positions (metres) and base headings (radians about
+Z) of its points; :func:`place_agents` turns them into an :class:`AgentSet` by the
source's :class:`PlacementPolicy`: a heading (fixed angle added to the base, a
per-point value, or facing a target), a stream per agent (seeded random by weight,
per point, or one named stream), an offset in ``0 .. M-1`` frames (uniform, normal,
or per point) and a colour (a base colour varied at random, or per point). Random
choices are seeded, so the same inputs give the same agents. Per-point values come
from a callback (the Blender side reads mesh attributes,
``crowd_addon.blender.agents``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .agents import assign_offsets, assign_streams, check_offsets
from .errors import CrowdError

__all__ = ["AgentSet", "PlacementPolicy", "place_agents", "z_angle", "FORWARD",
           "SOURCE_SEED"]

#: the character's rest-pose facing per ``forward_axis`` setting (x, y)
FORWARD = {"NEG_Y": (0.0, -1.0), "POS_Y": (0.0, 1.0), "POS_X": (1.0, 0.0),
           "NEG_X": (-1.0, 0.0)}
#: seed stride between agent sources: source ``i`` draws from ``seed + i * SOURCE_SEED``
SOURCE_SEED = 7919


@dataclass(frozen=True)
class AgentSet:
    """Agents as arrays: positions (n, 3) float32 metres, headings (n,) float32
    radians, streams (n,) int32 stream indices, offsets (n,) int32 frames, colors
    (n, 3) float32 0..1."""

    positions: np.ndarray
    headings: np.ndarray
    streams: np.ndarray
    offsets: np.ndarray
    colors: np.ndarray

    @property
    def count(self) -> int:
        return int(self.offsets.shape[0])

    @staticmethod
    def concatenate(sets):
        """One :class:`AgentSet` of ``sets`` in order (empty for none)."""
        if not sets:
            return AgentSet(np.zeros((0, 3), np.float32), np.zeros(0, np.float32),
                            np.zeros(0, np.int32), np.zeros(0, np.int32),
                            np.zeros((0, 3), np.float32))
        return AgentSet(*(np.concatenate([getattr(s, f) for s in sets])
                          for f in ("positions", "headings", "streams", "offsets", "colors")))


@dataclass(frozen=True)
class PlacementPolicy:
    """How a source's points become agents (the settings of an agent source).

    heading_mode : ``"FIXED"`` (base heading + ``heading`` radians), ``"ATTRIBUTE"``
        (base heading + per-point ``heading_attribute``) or ``"TARGET"`` (face
        ``target``, a world position (3,), None when not chosen).
    stream_mode : ``"RANDOM"`` (by the stream weights), ``"ATTRIBUTE"`` (per-point
        stream index ``stream_attribute``) or ``"FIXED"`` (the stream ``stream_name``).
    offset_mode : ``"UNIFORM"``, ``"NORMAL"`` (``offset_mean``, ``offset_std`` in
        frames; negative: the defaults of :func:`.agents.assign_offsets`) or
        ``"ATTRIBUTE"`` (per-point ``offset_attribute``).
    color_mode : ``"RANDOM"`` (``color`` (3,) 0..1 moved toward a random colour by
        ``color_variation``) or ``"ATTRIBUTE"`` (per-point ``color_attribute``).
    """

    heading_mode: str = "FIXED"
    heading: float = 0.0
    heading_attribute: str = "heading"
    target: tuple | None = None
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


def z_angle(matrix: np.ndarray) -> np.ndarray:
    """Rotation about +Z (radians) of 4x4 world matrices ``(..., 4, 4)``: (...,)."""
    return np.arctan2(matrix[..., 1, 0], matrix[..., 0, 0])


def place_agents(what: str, positions: np.ndarray, base_heading: np.ndarray,
                 policy: PlacementPolicy, *, streams, stream_weights, max_offset: int,
                 seed: int, forward_axis: str = "NEG_Y", attribute=None) -> AgentSet:
    """The agents of one source's points.

    Parameters
    ----------
    what : the source in error messages (e.g. ``"agent source 'seats'"``).
    positions : (n, 3) world positions; base_heading : (n,) radians about +Z.
    policy : the source's :class:`PlacementPolicy`.
    streams : stream names (index = stream id); stream_weights : (S,) weights.
    max_offset : M. seed : int. forward_axis : key of :data:`FORWARD`.
    attribute : ``attribute(name, kind)`` -> per-point values of the point attribute
        ``name``: kind ``"float"`` (n,), ``"int"`` (n,) or ``"color"`` (n, >= 3);
        raises a :class:`CrowdError` when the source has no such attribute.
    """
    pos = np.asarray(positions, np.float64)
    n = pos.shape[0]
    p = policy

    def values(name, kind):
        if attribute is None:
            raise CrowdError(f"{what}: this source has no point attributes "
                             f"(wanted {name!r})")
        return attribute(name, kind)

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
    heading = np.mod(heading + np.pi, 2 * np.pi) - np.pi

    if p.stream_mode == "ATTRIBUTE":
        st = values(p.stream_attribute, "int").astype(np.int64)
        bad = np.flatnonzero((st < 0) | (st >= len(streams)))
        if bad.size:
            raise CrowdError(f"{what}: attribute {p.stream_attribute!r} gives stream "
                             f"{int(st[bad[0]])} at point {int(bad[0])}; streams are "
                             f"0..{len(streams) - 1} ({list(streams)})")
    elif p.stream_mode == "FIXED":
        if p.stream_name not in streams:
            raise CrowdError(f"{what}: unknown stream {p.stream_name!r} "
                             f"(streams: {list(streams)})")
        st = np.full(n, list(streams).index(p.stream_name))
    else:
        try:
            st = assign_streams(n, len(streams), stream_weights, seed)
        except CrowdError as e:
            raise CrowdError(f"{what}: {e}") from None

    if p.offset_mode == "ATTRIBUTE":
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
    return AgentSet(pos.astype(np.float32), np.asarray(heading).astype(np.float32),
                    np.asarray(st, np.int32), np.asarray(off, np.int32),
                    np.asarray(col, np.float32))
