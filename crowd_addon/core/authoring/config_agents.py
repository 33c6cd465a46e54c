"""A :class:`~.config.CrowdConfig`'s agents: :class:`AgentsMixin`, the methods of the
configuration that add streamed agents (:meth:`~AgentsMixin.add_agents`: a stream,
offset, position, heading, colour and optionally a scale, palette, mesh variant and
props each) and read its per-agent arrays with their defaults filled in; and
:data:`PALETTE_COLUMNS`, the palette colours an agent carries. ``CrowdConfig``
inherits them.
"""

from __future__ import annotations

import numpy as np

from ..base.errors import CrowdError
from ..runtime.agents import assign_offsets, assign_streams

__all__ = ["AgentsMixin", "PALETTE_COLUMNS"]

#: Palette colours an agent carries (one per palette material of its character, at
#: most this many: the GPU packs them in one texel).
PALETTE_COLUMNS = 4


class AgentsMixin:
    """The agents of :class:`~.config.CrowdConfig`: adding them, and their per-agent
    arrays with defaults."""

    @property
    def agent_count(self) -> int:
        return int(self.agent_offset.shape[0])

    @property
    def palette(self) -> np.ndarray:
        """(N, 4, 3) float32 palette colours per agent: :attr:`agent_palette`, or -1
        (none) when it is empty."""
        p = np.asarray(self.agent_palette, np.float32).reshape(-1, PALETTE_COLUMNS, 3)
        return p if p.shape[0] else np.full((self.agent_count, PALETTE_COLUMNS, 3), -1.0,
                                            np.float32)

    @property
    def variant_ids(self) -> np.ndarray:
        """(N,) int16 mesh variant per agent: :attr:`agent_variant`, or zeros."""
        v = np.asarray(self.agent_variant, np.int16).reshape(-1)
        return v if v.size else np.zeros(self.agent_count, np.int16)

    @property
    def prop_masks(self) -> np.ndarray:
        """(N,) uint8 props per agent (a bit each): :attr:`agent_props`, or zeros."""
        m = np.asarray(self.agent_props, np.uint8).reshape(-1)
        return m if m.size else np.zeros(self.agent_count, np.uint8)

    @property
    def scales(self) -> np.ndarray:
        """(N,) float32 scale per agent: :attr:`agent_scale`, or ones when it is empty."""
        s = np.asarray(self.agent_scale, np.float32).reshape(-1)
        return s if s.size else np.ones(self.agent_count, np.float32)

    def add_agents(self, count, streams=None, stream_weights=None, offsets="uniform",
                   offset_mean=None, offset_std=None, positions=None, headings=None,
                   colors=None, seed=None, scales=None, palette=None, variants=None,
                   props=None):
        """Append ``count`` streamed agents.

        ``streams``: None (all streams, drawn with ``stream_weights``), an int, a
        name, or an array of stream indices per agent. ``offsets``: ``"uniform"``,
        ``"normal"`` or an array. ``variants``: each agent's mesh variant, ``props``
        the props it carries (a bit per prop of its character; :mod:`.bodies`); None:
        variant 0 and no props. Returns the new agents' ids.
        """
        seed = self.seed + self.agent_count if seed is None else seed
        names = [s.name for s in self.streams]
        if streams is None:
            st = assign_streams(count, len(self.streams), stream_weights, seed)
        elif isinstance(streams, (str, int, np.integer)):
            idx = names.index(streams) if isinstance(streams, str) and streams in names \
                else streams
            if isinstance(idx, str) or not 0 <= int(idx) < len(names):
                raise CrowdError(f"agents: unknown stream {streams!r}")
            st = np.full(count, int(idx), np.int32)
        else:
            st = np.asarray(streams, np.int32)
            if st.shape != (count,):
                raise CrowdError(f"agents: {st.shape} streams for {count} agents")
        if isinstance(offsets, str):
            off = assign_offsets(count, self.max_offset, offsets, seed + 1, offset_mean,
                                 offset_std)
        else:
            off = assign_offsets(count, self.max_offset, "given", offsets=offsets)
        pos = np.zeros((count, 3), np.float32) if positions is None else \
            np.asarray(positions, np.float32).reshape(count, 3)
        head = np.zeros(count, np.float32) if headings is None else \
            np.asarray(headings, np.float32).reshape(count)
        if colors is None:
            col = np.random.default_rng(seed + 2).uniform(0.35, 1.0, (count, 3))
        else:
            col = np.asarray(colors, np.float32).reshape(count, 3)
        first = self.agent_count
        if scales is not None or np.asarray(self.agent_scale).size:
            old = self.scales
            new = np.ones(count, np.float32) if scales is None else \
                np.asarray(scales, np.float32).reshape(count)
            self.agent_scale = np.concatenate([old, new]).astype(np.float32)
        for name, given, dtype in (("agent_variant", variants, np.int16),
                                   ("agent_props", props, np.uint8)):
            if given is not None or np.asarray(getattr(self, name)).size:
                old = self.variant_ids if name == "agent_variant" else self.prop_masks
                arr = np.zeros(count, np.int64) if given is None else \
                    np.asarray(given).reshape(count)
                top = np.iinfo(dtype).max
                if arr.size and not (np.issubdtype(arr.dtype, np.integer)
                                     and 0 <= arr.min() and arr.max() <= top):
                    raise CrowdError(f"agents: {name[6:]} must be integers in 0..{top}, got "
                                     f"{arr.dtype} {arr.min()}..{arr.max()}")
                new = arr.astype(dtype)
                setattr(self, name, np.concatenate([old, new]).astype(dtype))
        if palette is not None or np.asarray(self.agent_palette).size:
            old = self.palette
            new = np.full((count, PALETTE_COLUMNS, 3), -1.0, np.float32) if palette is None \
                else np.asarray(palette, np.float32).reshape(count, PALETTE_COLUMNS, 3)
            self.agent_palette = np.concatenate([old, new]).astype(np.float32)
        self.agent_stream = np.concatenate([self.agent_stream, st]).astype(np.int32)
        self.agent_unique = np.concatenate([self.agent_unique,
                                            np.full(count, -1, np.int32)]).astype(np.int32)
        self.agent_offset = np.concatenate([self.agent_offset, off]).astype(np.int32)
        self.agent_position = np.concatenate([self.agent_position, pos]).astype(np.float32)
        self.agent_heading = np.concatenate([self.agent_heading, head]).astype(np.float32)
        self.agent_color = np.concatenate([self.agent_color, col]).astype(np.float32)
        return np.arange(first, first + count)
