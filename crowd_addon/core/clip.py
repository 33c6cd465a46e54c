"""Clips (sampled local SQT keys with event tags) and the packed clip bank.

A :class:`Clip` is authoring data: keys ``(F, B, 10)`` sampled at integer frames
``0 .. F-1`` of the clip, its fps, looping or clamped, and event tags
``(name, frame)``. Clip time is in frames (float). A looping clip repeats with a
period of ``F - 1`` frames (its last key is the same instant as its first, as a
cyclic Blender action with matching ends); a clamped clip holds its last key.

:class:`ClipBank` packs every clip of a crowd into one float32 array so that any
number of (clip, time) pairs is sampled with a handful of numpy calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import pose as sqt
from .errors import CrowdError
from .quaternion import normalize_if_needed

__all__ = ["Clip", "ClipBank"]


@dataclass(frozen=True, eq=False)
class Clip:
    """Sampled animation of one skeleton.

    Parameters
    ----------
    name : str
    keys : (F, B, 10) local SQT per frame and bone (see :mod:`.pose`), F >= 2.
        Rotations are normalised on construction; zero-length or non-finite keys are
        rejected with the frame and bone named.
    fps : float, frames per second the keys were sampled at.
    loop : bool, repeat (period F - 1) or clamp to the last key.
    events : sequence of ``(name, frame)`` tags, ``0 <= frame <= F - 1``.
    """

    name: str
    keys: np.ndarray
    fps: float = 30.0
    loop: bool = True
    events: tuple = ()
    bone_names: tuple = field(default=None)

    def __post_init__(self):
        name = str(self.name)
        if not name:
            raise CrowdError("clip: empty name")
        raw = self.keys
        if isinstance(raw, np.ndarray) and raw.dtype in (np.float32, np.float64):
            keys = raw          # checked in its own precision (float32 -> 64 is exact)
        else:
            keys = np.asarray(raw, dtype=np.float64)
        if keys.ndim != 3 or keys.shape[2] != sqt.WIDTH:
            raise CrowdError(f"clip {name!r}: keys must be (frames, bones, {sqt.WIDTH}), "
                             f"got {keys.shape}")
        if keys.shape[0] < 2:
            raise CrowdError(f"clip {name!r}: needs at least 2 keys, got {keys.shape[0]} "
                             "(a zero-length clip has no duration)")
        if keys.shape[1] < 1:
            raise CrowdError(f"clip {name!r}: has no bones")
        if self.bone_names is not None and len(self.bone_names) != keys.shape[1]:
            raise CrowdError(f"clip {name!r}: {len(self.bone_names)} bone names for "
                             f"{keys.shape[1]} bones")
        if not np.isfinite(keys).all():
            f, b = np.argwhere(~np.isfinite(keys).all(axis=-1))[0]
            raise CrowdError(f"clip {name!r}: non-finite key at frame {f}, "
                             f"bone {self._bone_label(b)}")
        # rotation lengths as normalize_if_needed computes them (the sum of the four
        # squares in order), one component plane at a time: a reduction over a
        # trailing axis of 4 is slow in numpy
        q = [keys[..., i].astype(np.float64) for i in range(sqt.ROT.start, sqt.ROT.stop)]
        qn = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])[..., None]
        if (qn < 1e-6).any():
            f, b = np.argwhere(qn[..., 0] < 1e-6)[0]
            raise CrowdError(f"clip {name!r}: zero rotation quaternion at frame {f}, "
                             f"bone {self._bone_label(b)}")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise CrowdError(f"clip {name!r}: fps must be positive, got {self.fps}")
        packed = (keys if keys is raw else np.asarray(raw)).astype(np.float32)
        if (np.abs(qn - 1) > 1e-6).any():     # else they are what it would return
            packed[..., sqt.ROT] = normalize_if_needed(keys[..., sqt.ROT])
        events = []
        for ev in self.events:
            try:
                ev_name, frame = ev
                frame = float(frame)
            except (TypeError, ValueError):
                raise CrowdError(f"clip {name!r}: event tag {ev!r} is not (name, frame)") \
                    from None
            if not str(ev_name):
                raise CrowdError(f"clip {name!r}: event tag with an empty name")
            if not (0 <= frame <= keys.shape[0] - 1):
                raise CrowdError(f"clip {name!r}: event {ev_name!r} at frame {frame} is "
                                 f"outside 0..{keys.shape[0] - 1}")
            events.append((str(ev_name), frame))
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "keys", packed)
        object.__setattr__(self, "fps", float(self.fps))
        object.__setattr__(self, "loop", bool(self.loop))
        object.__setattr__(self, "events", tuple(sorted(events, key=lambda e: e[1])))
        if self.bone_names is not None:
            object.__setattr__(self, "bone_names", tuple(self.bone_names))

    def _bone_label(self, b):
        return repr(self.bone_names[b]) if self.bone_names is not None else str(int(b))

    @property
    def frame_count(self) -> int:
        return int(self.keys.shape[0])

    @property
    def bone_count(self) -> int:
        return int(self.keys.shape[1])

    @property
    def duration(self) -> float:
        """Length in frames (the loop period for looping clips)."""
        return float(self.keys.shape[0] - 1)

    def sample(self, t) -> np.ndarray:
        """Poses ``(*t.shape, B, 10)`` at clip times ``t`` (frames, float)."""
        bank = ClipBank([self])
        t = np.asarray(t, dtype=np.float64)
        out = bank.sample(np.zeros(t.size, np.int64), t.reshape(-1))
        return out.reshape(t.shape + out.shape[1:])


class ClipBank:
    """All clips of a crowd packed for vectorised sampling.

    Attributes
    ----------
    keys : (K + 1, B_max, 10) float32, every clip's keys back to back (bones beyond
        a clip's skeleton are identity), plus one identity row at the end.
    start, frames : (C,) int64, first row and key count per clip.
    loop : (C,) bool.
    tag_clip, tag_frame, tag_name : flattened event tags, sorted by clip;
        ``tag_start[c]:tag_start[c + 1]`` are clip ``c``'s tags; names index ``tag_names``.
    """

    def __init__(self, clips, bone_count: int | None = None):
        clips = list(clips)
        self.clips = clips
        b = max([c.bone_count for c in clips] + [bone_count or 1])
        self.bone_count = b
        frames = np.array([c.frame_count for c in clips], np.int64)
        self.frames = frames
        self.start = np.concatenate([[0], np.cumsum(frames)[:-1]]).astype(np.int64) \
            if clips else np.zeros(0, np.int64)
        keys = sqt.identity_pose((int(frames.sum()) + 1, b))
        for c, s in zip(clips, self.start):
            keys[s:s + c.frame_count, :c.bone_count] = c.keys
        self.keys = keys
        self.loop = np.array([c.loop for c in clips], bool)
        self.period = np.maximum(frames - 1, 1).astype(np.float64)
        names = sorted({e[0] for c in clips for e in c.events})
        self.tag_names = names
        name_id = {n: i for i, n in enumerate(names)}
        tc, tf, tn, ts = [], [], [], [0]
        for i, c in enumerate(clips):
            for ev_name, fr in c.events:
                tc.append(i)
                tf.append(fr)
                tn.append(name_id[ev_name])
            ts.append(len(tc))
        self.tag_clip = np.array(tc, np.int64)
        self.tag_frame = np.array(tf, np.float64)
        self.tag_name = np.array(tn, np.int64)
        self.tag_start = np.array(ts, np.int64)

    def index(self, name: str) -> int:
        for i, c in enumerate(self.clips):
            if c.name == name:
                return i
        raise CrowdError(f"unknown clip {name!r}")

    def local_time(self, clip_ids: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Clip-local time in ``[0, F - 1]`` (wrapped when looping, else clamped)."""
        period = self.period[clip_ids]
        last = (self.frames[clip_ids] - 1).astype(np.float64)
        return np.where(self.loop[clip_ids], np.mod(t, period), np.clip(t, 0.0, last))

    def sample(self, clip_ids: np.ndarray, t: np.ndarray, out: np.ndarray | None = None):
        """Sample clips at times.

        Parameters
        ----------
        clip_ids : (n,) int clip indices.
        t : (n,) float clip times in frames (any value; wrapped or clamped).

        Returns
        -------
        (n, B_max, 10) float32 local poses (lerp + shortest-arc nlerp between keys).
        """
        clip_ids = np.asarray(clip_ids, np.int64)
        u = self.local_time(clip_ids, np.asarray(t, np.float64))
        i0 = np.floor(u).astype(np.int64)
        last = self.frames[clip_ids] - 1
        i0 = np.minimum(i0, last)
        i1 = np.minimum(i0 + 1, last)
        f = (u - i0).astype(np.float32)
        base = self.start[clip_ids]
        if out is None:
            out = np.empty((clip_ids.size,) + self.keys.shape[1:], np.float32)
        np.take(self.keys, base + i0, axis=0, out=out)
        # at integer times (the common case: speed 1 at whole frames) the key is the pose
        frac = np.flatnonzero(f)
        if frac.size:
            b = self.keys[(base + i1)[frac]]
            out[frac] = sqt.blend2(out[frac], b, f[frac])
        return out

    def crossings(self, clip_ids: np.ndarray, t0: np.ndarray, t1: np.ndarray):
        """Event tags crossed when clip time goes from ``t0`` (excluded) to ``t1``.

        Parameters
        ----------
        clip_ids, t0, t1 : (n,) arrays; ``t1 >= t0`` is the forward direction
            (backward motion crosses nothing).

        Returns
        -------
        (which, tag) : int arrays of equal length; ``which`` indexes the inputs, ``tag``
            the flattened tag arrays. A tag crossed several times in one step is
            reported once.
        """
        clip_ids = np.asarray(clip_ids, np.int64)
        counts = self.tag_start[clip_ids + 1] - self.tag_start[clip_ids]
        if counts.sum() == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        which = np.repeat(np.arange(len(clip_ids)), counts)
        first = np.repeat(self.tag_start[clip_ids], counts)
        tag = first + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        c = clip_ids[which]
        tau = self.tag_frame[tag]
        a = np.asarray(t0, np.float64)[which]
        b = np.asarray(t1, np.float64)[which]
        p = self.period[c]
        last = (self.frames[c] - 1).astype(np.float64)
        looped = np.floor((b - tau) / p) - np.floor((a - tau) / p) > 0
        ac = np.clip(a, -np.inf, last)
        bc = np.clip(b, -np.inf, last)
        clamped = (ac < tau) & (tau <= bc)
        hit = np.where(self.loop[c], looped, clamped) & (b > a)
        return which[hit], tag[hit]
