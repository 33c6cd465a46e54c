"""Clips (sampled local SQT keys with event tags) and the packed clip bank.

A :class:`Clip` is authoring data: keys ``(F, B, 10)`` sampled at integer frames
``0 .. F-1`` of the clip, its fps, looping or clamped, event tags ``(name, frame)``
and optionally the names of the bones its key columns belong to. Clip time is in
*clip frames* (float): key ``k`` is clip frame ``k``, ``1 / clip.fps`` seconds after
key ``k - 1``. A looping clip repeats with a period of ``F - 1`` clip frames (its last
key is the same instant as its first, as a cyclic Blender action with matching ends);
a clamped clip holds its last key.

A crowd plays a clip at the clip's own rate: ``crowd fps`` frames of the crowd are
``clip.fps`` clip frames (:meth:`Clip.frames_at`; the clip player converts, see
``controllers.ClipPlayer``). A clip with bone names is bound to each skeleton that
plays it by name (:meth:`Clip.bone_order`), one without by index.

:class:`ClipBank` packs every clip of a crowd into one float32 array so that any
number of (clip, time) pairs is sampled with a handful of numpy calls; a clip whose
bones a skeleton lists in another order gets one more entry, its key columns in that
skeleton's order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..base import pose as sqt
from ..base.errors import CrowdError
from ..base.quaternion import normalize_if_needed

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
    fps : float, frames per second the keys were sampled at (a crowd plays the clip at
        this rate, whatever its own fps).
    loop : bool, repeat (period F - 1) or clamp to the last key.
    events : sequence of ``(name, frame)`` tags, ``0 <= frame <= F - 1`` (clip frames).
    bone_names : None, or the B unique names of the bones the key columns belong to:
        the clip is then matched to a skeleton by name (any order); without names, by
        index (the bone counts must agree).
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
        if self.bone_names is not None:
            seen = {}
            for i, n in enumerate(self.bone_names):
                if n in seen:
                    raise CrowdError(f"clip {name!r}: duplicate bone name {n!r} (columns "
                                     f"{seen[n]} and {i})")
                seen[n] = i
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
        """Length in clip frames (the loop period for looping clips)."""
        return float(self.keys.shape[0] - 1)

    @property
    def seconds(self) -> float:
        """Length in seconds."""
        return self.duration / self.fps

    def frames_at(self, fps: float) -> float:
        """Length in frames at ``fps`` (e.g. the crowd's): how long the clip plays there."""
        return self.duration * float(fps) / self.fps

    def bone_order(self, skeleton) -> np.ndarray | None:
        """Key column of each of ``skeleton``'s bones, or None when the columns are the
        skeleton's bones already (same names in the same order, or no names and the
        same bone count).

        Raises CrowdError naming the clip, the skeleton and the bones when the clip
        names bones the skeleton lacks or lacks bones it has (without names: when the
        bone counts differ).
        """
        want = tuple(skeleton.bone_names)
        if self.bone_names is None or self.bone_names == want:
            if self.bone_count != len(want):
                raise CrowdError(f"clip {self.name!r} has {self.bone_count} bones but "
                                 f"skeleton {skeleton.name!r} has {len(want)}")
            return None
        column = {n: i for i, n in enumerate(self.bone_names)}
        known = set(want)
        extra = [n for n in self.bone_names if n not in known]
        missing = [n for n in want if n not in column]
        if extra or missing:
            parts = []
            if extra:
                parts.append(f"names bones the skeleton lacks {_first(extra)}")
            if missing:
                parts.append(f"lacks bones the skeleton has {_first(missing)}")
            raise CrowdError(f"clip {self.name!r} ({self.bone_count} bones) does not match "
                             f"skeleton {skeleton.name!r} ({len(want)} bones): it "
                             + " and ".join(parts))
        return np.array([column[n] for n in want], np.int64)

    def sample(self, t) -> np.ndarray:
        """Poses ``(*t.shape, B, 10)`` at clip times ``t`` (clip frames, float)."""
        bank = ClipBank([self])
        t = np.asarray(t, dtype=np.float64)
        out = bank.sample(np.zeros(t.size, np.int64), t.reshape(-1))
        return out.reshape(t.shape + out.shape[1:])


def _first(names, most=5) -> str:
    """The first ``most`` of ``names`` for a message, and how many more there are."""
    more = len(names) - most
    return f"{list(names[:most])}" + (f" (and {more} more)" if more > 0 else "")


class ClipBank:
    """All clips of a crowd packed for vectorised sampling.

    Parameters
    ----------
    clips : the clips; entries ``0 .. C-1`` are these clips, key columns as stored.
    bone_count : the row width in bones (at least every clip's bone count).
    fps : the crowd's frame rate: ``rate[e] = clip fps / fps`` converts crowd frames
        into clip frames. None: rate 1 (times are clip frames).
    uses : ``(clip name, skeleton)`` pairs that will be played (e.g. from
        :func:`~.config.validate_config`): a clip whose bones the skeleton lists in
        another order gets an entry with its columns in the skeleton's order, one per
        distinct (clip, order). :meth:`entry` adds a missing one on demand (repacking).

    Attributes
    ----------
    keys : (K + 1, B_max, 10) float32, every entry's keys back to back (bones beyond
        a clip's skeleton are identity), plus one identity row at the end.
    entry_clip : (E,) int64, the clip of each entry.
    start, frames : (E,) int64, first row and key count per entry.
    loop : (E,) bool. rate : (E,) float64, clip frames per crowd frame.
    tag_clip, tag_frame, tag_name : flattened event tags, sorted by entry (frames in
        clip frames); ``tag_start[e]:tag_start[e + 1]`` are entry ``e``'s tags; names
        index ``tag_names``.
    """

    def __init__(self, clips, bone_count: int | None = None, *, fps: float | None = None,
                 uses=()):
        clips = list(clips)
        self.clips = clips
        self.fps = None if fps is None else float(fps)
        self.bone_count = max([c.bone_count for c in clips] + [bone_count or 1])
        self._names = {}
        for i, c in enumerate(clips):
            self._names.setdefault(c.name, i)
        self._entries = [(i, None) for i in range(len(clips))]
        self._remapped = {}
        self.sub_keys = None           # .sub_keys.SubKeys: see :meth:`resample`
        for name, skeleton in uses:
            self._add(self.index(name), skeleton)
        self._pack()

    def _add(self, clip: int, skeleton):
        """The entry of clip ``clip`` in ``skeleton``'s bone order (added if new), and
        whether it was added."""
        order = self.clips[clip].bone_order(skeleton)
        if order is None:
            return clip, False
        key = (clip, order.tobytes())
        if key in self._remapped:
            return self._remapped[key], False
        self._remapped[key] = len(self._entries)
        self._entries.append((clip, order))
        return self._remapped[key], True

    def _pack(self):
        clips, entries = self.clips, self._entries
        of = [clips[i] for i, _ in entries]
        self.entry_clip = np.array([i for i, _ in entries], np.int64)
        frames = np.array([c.frame_count for c in of], np.int64)
        self.frames = frames
        self.start = np.concatenate([[0], np.cumsum(frames)[:-1]]).astype(np.int64) \
            if entries else np.zeros(0, np.int64)
        keys = sqt.identity_pose((int(frames.sum()) + 1, self.bone_count))
        for (_, order), c, s in zip(entries, of, self.start):
            keys[s:s + c.frame_count, :c.bone_count] = c.keys if order is None \
                else c.keys[:, order]
        self.keys = keys
        self.key_deltas = sqt.next_key_deltas(keys, self.start, frames)
        if self.sub_keys is not None:
            self.sub_keys.grow(len(entries))
        self.loop = np.array([c.loop for c in of], bool)
        self.period = np.maximum(frames - 1, 1).astype(np.float64)
        self.rate = np.array([1.0 if self.fps is None else c.fps / self.fps for c in of],
                             np.float64)
        names = sorted({e[0] for c in clips for e in c.events})
        self.tag_names = names
        name_id = {n: i for i, n in enumerate(names)}
        tc, tf, tn, ts = [], [], [], [0]
        for e, c in enumerate(of):
            for ev_name, fr in c.events:
                tc.append(e)
                tf.append(fr)
                tn.append(name_id[ev_name])
            ts.append(len(tc))
        self.tag_clip = np.array(tc, np.int64)
        self.tag_frame = np.array(tf, np.float64)
        self.tag_name = np.array(tn, np.int64)
        self.tag_start = np.array(ts, np.int64)

    def index(self, name: str) -> int:
        """Entry of clip ``name`` with its key columns as stored."""
        i = self._names.get(name)
        if i is None:
            raise CrowdError(f"unknown clip {name!r}")
        return i

    def entry(self, name: str, skeleton=None) -> int:
        """Entry of clip ``name`` played by ``skeleton``: its key columns in the
        skeleton's bone order (see :meth:`Clip.bone_order`, which raises on bones that
        do not match). Without a skeleton, :meth:`index`."""
        i = self.index(name)
        if skeleton is None:
            return i
        e, added = self._add(i, skeleton)
        if added:
            self._pack()
        return e

    def resample(self, entries):
        """Resample ``entries`` at sub-frames (:mod:`.sub_keys`) for streams whose time
        moves on its grid; replaces any earlier resampling."""
        from .sub_keys import SubKeys
        self.sub_keys = SubKeys(self, entries) if len(entries) else None

    def local_time(self, clip_ids: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Clip-local time in ``[0, F - 1]`` (wrapped when looping, else clamped)."""
        period = self.period[clip_ids]
        last = (self.frames[clip_ids] - 1).astype(np.float64)
        return np.where(self.loop[clip_ids], np.mod(t, period), np.clip(t, 0.0, last))

    def sample(self, clip_ids: np.ndarray, t: np.ndarray, out: np.ndarray | None = None):
        """Sample clips at times.

        Parameters
        ----------
        clip_ids : (n,) int entry indices.
        t : (n,) float clip times in clip frames (any value; wrapped or clamped).

        Returns
        -------
        (n, B_max, 10) float32 local poses (lerp + shortest-arc nlerp between keys).
        """
        clip_ids = np.asarray(clip_ids, np.int64)
        u = self.local_time(clip_ids, np.asarray(t, np.float64))
        if self.sub_keys is not None:        # speed streams' clips: keys on a sub-frame grid
            return self.sub_keys.sample(self, clip_ids, u, out)
        return self.interpolate(clip_ids, u, out)

    def interpolate(self, clip_ids, u, out=None):
        """:meth:`sample` at clip-local times ``u`` (:meth:`local_time`)."""
        i0 = np.floor(u).astype(np.int64)
        last = self.frames[clip_ids] - 1
        i0 = np.minimum(i0, last)
        f = (u - i0).astype(np.float32)
        base = self.start[clip_ids]
        if out is None:
            out = np.empty((clip_ids.size,) + self.keys.shape[1:], np.float32)
        # mode="clip": the indices are valid, and numpy buffers ``out`` in "raise" mode
        np.take(self.keys, base + i0, axis=0, out=out, mode="clip")
        # at integer times (the common case: speed 1 at whole frames) the key is the pose;
        # between keys, the step to the next key is stored on the shortest arc
        # (``key_deltas``), so the blend is blend2's arithmetic without its sign test and
        # its subtraction (the same floats)
        frac = np.flatnonzero(f)
        if frac.size == clip_ids.size:          # every one between keys: in place
            b = np.take(self.key_deltas, base + i0, axis=0, mode="clip")
            b *= f[:, None, None]
            out += b
            sqt.normalize_rotations(out)
        elif frac.size:
            b = self.key_deltas[(base + i0)[frac]]
            b *= f[frac][:, None, None]
            b += out[frac]
            out[frac] = sqt.normalize_rotations(b)
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
