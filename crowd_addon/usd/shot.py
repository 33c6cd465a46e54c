"""The exported agents of a :class:`~crowd_addon.core.recording.Recording`, as the USD
layout needs them (pure numpy, no pxr).

An agent is *static* when it plays one ``(stream, offset)`` for the whole shot: it
shares an offset animation. Every other agent (a transition, a cut, a unique at some
frame) gets its own animation, its poses rebuilt from the recording.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Shot"]


class Shot:
    """Agents ``agents`` (ids) of ``recording``.

    Attributes
    ----------
    recording : the Recording; first, last, fps, max_offset : its own.
    agents : (n,) int64 ids; agent_skeleton : (n,) int64 skeleton index per agent.
    static : (n,) bool; stream, offset : (n,) int64 of static agents (-1 otherwise).
    position : (n, 3) float32, heading : (n,) float32 radians at ``first``.
    moving : (n,) bool, position or heading changed during the shot.
    """

    def __init__(self, recording, agents):
        rec = self.recording = recording
        ids = self.agents = np.asarray(agents, np.int64)
        self.first, self.last, self.fps = rec.first, rec.last, rec.fps
        self.max_offset = rec.max_offset
        self.agent_skeleton = rec.agent_skeleton[ids]
        self.static = rec.static[ids]
        _, ref, off = rec.playing(rec.first, ids)
        self.stream = np.where(self.static, ref, -1).astype(np.int64)
        self.offset = np.where(self.static, off, -1).astype(np.int64)
        self.position, self.heading = rec.position[ids], rec.heading[ids]
        self.moving = rec.moving[ids]

    @property
    def frames(self) -> np.ndarray:
        return self.recording.frames

    def agent_poses(self, which) -> np.ndarray:
        """``(frames, k, B, 10)`` float32 local poses of agents ``which`` (positions in
        :attr:`agents`) at every shot frame."""
        return self.recording.agent_poses(self.frames, self.agents[which])

    def agent_transforms(self, which) -> tuple:
        """``(position (frames, k, 3), heading (frames, k))`` float32 of agents ``which``."""
        return self.recording.agent_transforms(self.frames, self.agents[which])

    def stream_events(self, stream: int) -> list:
        """``(name, frame)`` tags stream ``stream``'s head crossed, in frame order."""
        s, names, frames = self.recording.stream_events
        keep = s == stream
        return [(str(n), int(f)) for n, f in zip(names[keep], frames[keep].tolist())]
