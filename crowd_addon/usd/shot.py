"""The exported agents of a :class:`~crowd_addon.core.shots.recording.Recording`, as the USD
layout needs them (pure numpy, no pxr).

An agent is *static* when it plays one ``(stream, offset)`` for the whole shot: it
shares an offset animation. Every other agent plays a sequence of :class:`Pieces`:
stretches of the shot on a stream at an offset, on a unique, or blending (a
transition); only the blending frames are its own, rebuilt from the recording. An
agent that looks at something (its look weight above 0 at some frame) is not static
either: the frames it looks are *aim* pieces (:data:`AIM`), its own poses with the
look's turn in its chain joints (``Recording.looked_pair_poses``), whatever it plays
underneath; its other frames stay pieces of what it plays.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..core.runtime.agents import STREAM, TRANSITION, UNIQUE
from ..core.meshes.bodies import body_keys
from ..core.runtime.pools import stream_key

__all__ = ["Shot", "Pieces", "STREAM", "UNIQUE", "TRANSITION", "AIM"]

#: a piece of frames an agent looks at something: its own poses, look applied
AIM = 3


@dataclass(frozen=True)
class Pieces:
    """What the non-static agents play, piece by piece, sorted by (agent, frame); each
    piece covers shot frames ``start .. end - 1`` and (k,) arrays hold:

    agent : position of the agent in :attr:`Shot.agents`; start, end : int64 frames;
    kind : STREAM (``ref`` a stream at ``offset``), UNIQUE (``ref`` a unique) or
    TRANSITION (its frames are the agent's own blend) or AIM (its frames are the agent's
    own poses with its look; ref -1); ref, offset : int64.
    """

    agent: np.ndarray
    start: np.ndarray
    end: np.ndarray
    kind: np.ndarray
    ref: np.ndarray
    offset: np.ndarray

    @property
    def count(self) -> int:
        return int(self.agent.size)


class Shot:
    """Agents ``agents`` (ids) of ``recording``.

    Attributes
    ----------
    recording : the Recording; first, last, fps, max_offset : its own.
    agents : (n,) int64 ids; agent_skeleton : (n,) int64 skeleton index per agent;
    agent_body : (n,) int64 body index per agent (mesh variant and props,
    :func:`~crowd_addon.core.meshes.bodies.body_keys` of all the recording's agents).
    static : (n,) bool; stream, offset : (n,) int64 of static agents (-1 otherwise).
    looking : (n,) bool, the agent looks at something at some shot frame (never
    static).
    position : (n, 3) float32, heading : (n,) float32 radians, color : (n, 3) float32
    RGB, at ``first``; scale : (n,) float32 body scales and palette (n, 4, 3) float32
    palette colours (-1: none), constant.
    moving : (n,) bool, position or heading changed during the shot.
    """

    def __init__(self, recording, agents):
        rec = self.recording = recording
        ids = self.agents = np.asarray(agents, np.int64)
        self.first, self.last, self.fps = rec.first, rec.last, rec.fps
        self.substeps = rec.substeps
        self.max_offset = rec.max_offset
        self.agent_skeleton = rec.agent_skeleton[ids]
        self.agent_body = body_keys(rec.config, rec.agent_skeleton)[1][ids]
        self.looking = rec.looking[ids]
        self.static = rec.static[ids] & ~self.looking
        _, ref, off = rec.playing(rec.first, ids)
        self.stream = np.where(self.static, ref, -1).astype(np.int64)
        self.offset = np.where(self.static, off, -1).astype(np.int64)
        self.position, self.heading = rec.position[ids], rec.heading[ids]
        self.color = rec.color[ids]
        self.scale = rec.scales[ids]
        self.palette = rec.palettes[ids]
        self.moving = rec.moving[ids]

    @property
    def frames(self) -> np.ndarray:
        return self.recording.frames

    @property
    def keys(self) -> np.ndarray:
        """(n,) int64 each static agent's ``(stream, offset)`` key
        (:func:`~crowd_addon.core.runtime.pools.stream_key`; meaningless for the
        others)."""
        return stream_key(self.stream, self.offset, self.max_offset)

    def agent_poses(self, which) -> np.ndarray:
        """``(frames, k, B, 10)`` float32 local poses of agents ``which`` (positions in
        :attr:`agents`) at every shot frame."""
        return self.recording.agent_poses(self.frames, self.agents[which])

    @cached_property
    def pieces(self) -> Pieces:
        """The recording's segments of the non-static agents cut to the shot."""
        rec = self.recording
        pos = np.full(rec.agent_count, -1, np.int64)
        pos[self.agents] = np.arange(self.agents.size)
        seg = np.flatnonzero(pos[rec.segment_agent] >= 0)
        seg = seg[~self.static[pos[rec.segment_agent[seg]]]]
        agent = rec.segment_agent[seg]
        frame = rec.segment_frame[seg]
        same = np.r_[agent[1:] == agent[:-1], False]
        end = np.where(same, np.r_[frame[1:], 0], rec.last + 1)
        start = np.maximum(frame, rec.first)
        keep = start < end
        seg = seg[keep]
        return self._aims(Pieces(pos[agent[keep]], start[keep], end[keep],
                                 rec.segment_kind[seg].astype(np.int64),
                                 rec.segment_ref[seg], rec.segment_offset[seg]))

    def _aims(self, p: Pieces) -> Pieces:
        """``p`` with the frames looking agents look cut out as AIM pieces (runs of
        frames with a look weight above 0, across what they play underneath)."""
        looking = np.flatnonzero(self.looking)
        if not looking.size:
            return p
        rec, first, span = self.recording, self.first, self.last - self.first + 1
        row = np.full(self.agents.size, -1, np.int64)
        row[looking] = np.arange(looking.size)
        frame = np.tile(self.frames, looking.size)
        agent = np.repeat(self.agents[looking], span)
        aim = (rec.look_weights(frame, agent) > 0).reshape(looking.size, span)
        code = np.empty((looking.size, span), np.int64)        # the piece at each frame
        mine = np.flatnonzero(row[p.agent] >= 0)
        for j, r, a, b in zip(mine.tolist(), row[p.agent[mine]].tolist(),
                              (p.start[mine] - first).tolist(), (p.end[mine] - first).tolist()):
            code[r, a:b] = j
        code[aim] = -1
        change = np.ones(code.shape, bool)
        change[:, 1:] = code[:, 1:] != code[:, :-1]
        r, c = np.nonzero(change)                                # by agent, then frame
        end = np.r_[c[1:], span]
        end[np.r_[r[1:] != r[:-1], True]] = span
        piece = code[r, c]
        src = np.maximum(piece, 0)
        kind = np.where(piece < 0, AIM, p.kind[src])
        new = Pieces(looking[r], first + c, first + end, kind,
                     np.where(piece < 0, -1, p.ref[src]),
                     np.where(piece < 0, 0, p.offset[src]))
        rest = np.flatnonzero(row[p.agent] < 0)
        cols = [np.concatenate([getattr(p, k)[rest], getattr(new, k)])
                for k in ("agent", "start", "end", "kind", "ref", "offset")]
        order = np.lexsort((cols[1], cols[0]))
        return Pieces(*(col[order] for col in cols))

    def piece_poses(self, pieces) -> np.ndarray:
        """``(sum of lengths * N, B, 10)`` float32 poses of the samples of ``pieces``
        (indices into :attr:`pieces`; ``N`` samples a frame, each frame's in time order),
        piece after piece."""
        p, n = self.pieces, self.substeps
        length = p.end[pieces] - p.start[pieces]
        frame = np.repeat(p.start[pieces] - np.cumsum(length) + length, length) + \
            np.arange(int(length.sum()))
        agent = np.repeat(self.agents[p.agent[pieces]], length)
        return self.recording.looked_pair_poses(np.repeat(frame, n), np.repeat(agent, n),
                                                np.tile(np.arange(n), frame.size))

    def agent_transforms(self, which) -> tuple:
        """``(position (frames, k, 3), heading (frames, k))`` float32 of agents ``which``."""
        return self.recording.agent_transforms(self.frames, self.agents[which])

    def stream_events(self, stream: int) -> list:
        """``(name, frame)`` tags stream ``stream``'s head crossed, in frame order."""
        s, names, frames = self.recording.stream_events
        keep = s == stream
        return [(str(n), int(f)) for n, f in zip(names[keep], frames[keep].tolist())]
