"""Run a crowd over a shot and keep what the USD layout needs (pure numpy, no pxr).

What is kept, per the paper's model (DESIGN.md s.1):

- every stream's evaluated timeline, i.e. its pose history unrolled: the head's
  local pose at each frame ``first - (M - 1) .. last`` (an agent at offset ``O`` shows
  frame ``F - O``, so these frames cover every offset over the shot);
- the event tags each stream head crossed in those frames;
- per agent, whether it plays one ``(stream, offset)`` for the whole shot (*static*:
  it will share an offset animation) or not (*dynamic*: it transitions, is cut to
  another animation, or plays a unique at some frame). For dynamic agents only the
  frames where they are not plain streamed are stored (their pose then); elsewhere
  their pose is the stream timeline at ``F - O``;
- agent transforms, with the agents whose position or heading changed in the shot.

Nothing here costs per agent per frame beyond a few vectorised comparisons.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.agents import STREAM
from ..core.errors import CrowdError

__all__ = ["ShotRecording", "record_shot", "agent_skeletons"]


@dataclass
class _FrameRecord:
    """Exported agents (positions in ``ShotRecording.agents``) not at their frame-first
    ``(stream, offset)``: their kind/ref/offset, and the local poses ``(k, B, 10)`` of
    those whose kind is not STREAM (in ``idx`` order)."""

    idx: np.ndarray
    kind: np.ndarray
    ref: np.ndarray
    offset: np.ndarray
    poses: np.ndarray


@dataclass
class ShotRecording:
    """A crowd's shot ``first .. last`` (frames, inclusive), ready to be written.

    Attributes
    ----------
    first, last : int frames; ``frames = last - first + 1``.
    max_offset : M.
    fps : float.
    agents : (n,) int64 ids of the exported agents.
    agent_skeleton : (n,) int64 skeleton index (``list(config.skeletons)``) per agent.
    stream_skeleton : (S,) int64 skeleton index per stream.
    stream_poses : (frames + M - 1, S, B, 10) float32; row ``k`` is frame
        ``first - (M - 1) + k`` of every stream.
    stream_events : list of S lists of ``(name, frame)`` tags crossed by the stream
        head at those frames, in frame order.
    static : (n,) bool, plays ``(stream[i], offset[i])`` at every frame of the shot.
    stream, offset : (n,) int64 reference at ``first`` (``-1`` where not streamed then).
    position : (n, 3) float32, heading : (n,) float32 radians, at ``first``.
    moving : (n,) bool, position or heading changed during the shot.
    """

    first: int
    last: int
    max_offset: int
    fps: float
    agents: np.ndarray
    agent_skeleton: np.ndarray
    stream_skeleton: np.ndarray
    stream_poses: np.ndarray
    stream_events: list
    static: np.ndarray
    stream: np.ndarray
    offset: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    moving: np.ndarray
    _records: list = field(default_factory=list, repr=False)
    _moves: list = field(default_factory=list, repr=False)

    @property
    def frames(self) -> np.ndarray:
        """(frames,) int64 shot frames ``first .. last``."""
        return np.arange(self.first, self.last + 1)

    @property
    def stream_frames(self) -> np.ndarray:
        """(frames + M - 1,) int64 frames of ``stream_poses`` rows."""
        return np.arange(self.first - self.max_offset + 1, self.last + 1)

    def agent_poses(self, which) -> np.ndarray:
        """Local poses ``(frames, k, B, 10)`` float32 of exported agents ``which``
        (positions in :attr:`agents`) at every shot frame, as the crowd showed them."""
        which = np.asarray(which, np.int64)
        frames = self.frames
        base = self.first - self.max_offset + 1
        out = np.empty((frames.size, which.size) + self.stream_poses.shape[2:], np.float32)
        slot = np.full(self.agents.size, -1, np.int64)
        slot[which] = np.arange(which.size)
        for t, rec in enumerate(self._records):
            ref, off = self.stream[which].copy(), self.offset[which].copy()
            streamed = np.ones(which.size, bool)
            s = slot[rec.idx]
            mine = s >= 0
            st = mine & (rec.kind == STREAM)
            ref[s[st]], off[s[st]] = rec.ref[st], rec.offset[st]
            own = mine[rec.kind != STREAM]
            own_slots = s[mine & (rec.kind != STREAM)]
            streamed[own_slots] = False
            out[t, streamed] = self.stream_poses[frames[t] - off[streamed] - base,
                                                 ref[streamed]]
            out[t, own_slots] = rec.poses[own]
        return out

    def agent_transforms(self, which) -> tuple:
        """``(position (frames, k, 3) float32, heading (frames, k) float32)`` of
        exported agents ``which`` at every shot frame."""
        which = np.asarray(which, np.int64)
        t = self.last - self.first + 1
        pos = np.broadcast_to(self.position[which], (t,) + self.position[which].shape).copy()
        head = np.broadcast_to(self.heading[which], (t, which.size)).copy()
        slot = np.full(self.agents.size, -1, np.int64)
        slot[which] = np.arange(which.size)
        for k, (idx, p, h) in enumerate(self._moves):
            s = slot[idx]
            mine = s >= 0
            pos[k, s[mine]], head[k, s[mine]] = p[mine], h[mine]
        return pos, head


def record_shot(crowd, agents, first: int, last: int, on_frame=None,
                progress=None) -> ShotRecording:
    """Advance ``crowd`` to ``first`` then through ``last``, recording the shot.

    Parameters
    ----------
    crowd : a :class:`~crowd_addon.core.crowd.Crowd`; it is advanced (and reset to its
        configured start first if it is already past ``first``).
    agents : (n,) int64 agent ids to record.
    first, last : shot frames, ``crowd.config.start_frame <= first <= last`` (checked
        by the caller).
    on_frame : optional ``on_frame(crowd, frame)`` called before each step with the
        frame the step evaluates; it may request transitions, set triggers and
        parameters, move agents. An exception in it stops the export (CrowdError
        naming the frame).
    progress : optional ``progress(stage, done, total)``.
    """
    if crowd.frame > first:
        crowd.reset()
    total = last - crowd.frame
    done = 0
    while crowd.frame < first:
        _step(crowd, on_frame)
        done += 1
        _report(progress, done, total)
    rec = _start(crowd, np.asarray(agents, np.int64), first, last)
    while crowd.frame < last:
        _step(crowd, on_frame)
        _capture(crowd, rec)
        done += 1
        _report(progress, done, total)
    return rec


def agent_skeletons(crowd, ids) -> np.ndarray:
    """(n,) int64 skeleton index (into ``list(config.skeletons)``) of agents ``ids``:
    that of the animation they were configured with (transitions never change it)."""
    cfg = crowd.config
    st = np.asarray(cfg.agent_stream, np.int64)[ids]
    root = np.where(st >= 0, st, crowd.S + np.asarray(cfg.agent_unique, np.int64)[ids])
    return crowd.root_skeleton[root].astype(np.int64)


def _report(progress, done, total):
    if progress is not None:
        progress("simulate", done, total)


def _step(crowd, on_frame):
    if on_frame is not None:
        frame = crowd.frame + 1
        try:
            on_frame(crowd, frame)
        except Exception as e:  # noqa: BLE001 - reported with its frame, stops the export
            raise CrowdError(f"on_frame callback failed at frame {frame}: "
                             f"{type(e).__name__}: {e}") from e
    crowd.step()


def _start(crowd, ids, first, last) -> ShotRecording:
    m, s = crowd.M, crowd.S
    rows = last - first + m
    poses = np.empty((rows, s) + crowd.history.shape[2:], np.float32)
    for k, f in enumerate(range(first - m + 1, first + 1)):
        poses[k] = crowd.history[f % m]
    kind = crowd.agent_kind[ids]
    streamed = kind == STREAM
    rec = ShotRecording(
        first=first, last=last, max_offset=m, fps=crowd.fps, agents=ids,
        agent_skeleton=agent_skeletons(crowd, ids), stream_skeleton=crowd.root_skeleton[:s],
        stream_poses=poses, stream_events=[[] for _ in range(s)],
        static=streamed.copy(),
        stream=np.where(streamed, crowd.agent_ref[ids], -1).astype(np.int64),
        offset=np.where(streamed, crowd.agent_offset[ids], -1).astype(np.int64),
        position=np.asarray(crowd.agent_position, np.float32)[ids].copy(),
        heading=np.asarray(crowd.agent_heading, np.float32)[ids].copy(),
        moving=np.zeros(ids.size, bool))
    _add_events(crowd, rec, first - m + 1)
    _record_frame(crowd, rec)
    return rec


def _capture(crowd, rec):
    f = crowd.frame
    rec.stream_poses[f - (rec.first - rec.max_offset + 1)] = crowd.history[f % rec.max_offset]
    _add_events(crowd, rec, f)
    _record_frame(crowd, rec)


def _add_events(crowd, rec, since):
    streams, names, frames = crowd.stream_events(since)
    order = np.argsort(frames, kind="stable")
    for s, n, f in zip(streams[order].tolist(), names[order], frames[order].tolist()):
        rec.stream_events[s].append((str(n), int(f)))


def _record_frame(crowd, rec):
    ids = rec.agents
    kind = crowd.agent_kind[ids]
    ref = crowd.agent_ref[ids]
    off = crowd.agent_offset[ids]
    changed = (kind != STREAM) | (ref != rec.stream) | (off != rec.offset)
    idx = np.flatnonzero(changed)
    own = idx[kind[idx] != STREAM]
    rec._records.append(_FrameRecord(idx, kind[idx], ref[idx].astype(np.int64),
                                     off[idx].astype(np.int64),
                                     crowd.agent_poses(ids[own])))
    rec.static[idx] = False
    pos = np.asarray(crowd.agent_position, np.float32)[ids]
    head = np.asarray(crowd.agent_heading, np.float32)[ids]
    moved = np.flatnonzero((pos != rec.position).any(1) | (head != rec.heading))
    rec._moves.append((moved, pos[moved], head[moved]))
    rec.moving[moved] = True
