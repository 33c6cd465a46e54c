"""Clip keys resampled at sub-frames, so streams that play at a speed other than 1 sample
their clips without interpolating every frame.

A stream at speed ``v`` (a speed variant, docs/variety.md) plays its tree at
``phase + v x F``: between keys at almost every frame, so every one of its clip players
blended two keys per bone each frame (a gather, a multiply-add and a normalisation over
every bone). Instead its time moves on a grid of ``1 / SUB_KEYS`` frame (:func:`on_grid`:
at most ``1 / (2 SUB_KEYS)`` frame, 2 ms at 30 fps, from the exact time), and the clips
its players play are resampled once, when the crowd is built, at every grid time
(:class:`SubKeys`): a player whose clip time lands on the grid (a clip at the crowd's
rate, speed 1 and a start on the grid, in a stream on the grid) takes its pose with
one gather, like a speed-1 stream at a whole frame. Any other time interpolates as
before. A grid key is the bank's own interpolation at that time, so both give the same
floats. Memory: ``(F - 1) x SUB_KEYS + 1`` poses per resampled clip entry of ``F``
keys, at most :data:`MAX_BYTES` in all (:attr:`SubKeys.nbytes`; ``crowd plan``
prints it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SUB_KEYS", "MAX_BYTES", "SubKeys", "on_grid", "sub_key_bytes"]

#: Grid steps per frame of the time of a stream at a speed other than 1.
SUB_KEYS = 8
#: The most bytes of resampled keys a crowd keeps: entries past it (long clips, many
#: of them) interpolate at the grid times instead, the same floats at a frame's cost.
MAX_BYTES = 256 << 20


def on_grid(times: np.ndarray) -> np.ndarray:
    """``times`` (frames) rounded to the nearest ``1 / SUB_KEYS`` frame (exact: a
    multiple of a power of two)."""
    return np.rint(np.asarray(times, np.float64) * SUB_KEYS) / SUB_KEYS


def sub_key_bytes(config) -> int:
    """Bytes of the keys a crowd of ``config`` (a CrowdConfig) resamples: each clip
    that a stream at another speed than 1 plays, in rows of the widest skeleton, within
    :data:`MAX_BYTES` (one entry per clip: a clip played in two bone orders has two,
    so this is an estimate)."""
    bones = max((s.bone_count for s in config.skeletons.values()), default=0)
    clips, todo = set(), [d.root for d in config.streams if d.speed != 1.0]
    while todo:
        node = todo.pop()
        todo.extend(node.children())
        if hasattr(node, "clip"):
            clips.add(node.clip)
    sizes = np.array([(clip.frame_count - 1) * SUB_KEYS + 1        # in the bank's order
                      for name, clip in config.clips.items() if name in clips],
                     np.int64) * bones * 40                  # 10 float32 a bone
    return int(sizes[np.cumsum(sizes) <= MAX_BYTES].sum())


class SubKeys:
    """The entries ``entries`` of ``bank`` (a :class:`~.clip.ClipBank`) resampled at
    every ``1 / SUB_KEYS`` clip frame of ``0 .. F - 1``, as many of them as fit in
    ``max_bytes``: ``keys`` (N, B, 10) float32, entry ``e``'s grid time
    ``j / SUB_KEYS`` at ``keys[start[e] + j]`` (``start`` -1: not resampled)."""

    def __init__(self, bank, entries, max_bytes: int = MAX_BYTES):
        entries = np.unique(np.asarray(list(entries), np.int64))
        count = (bank.frames[entries] - 1) * SUB_KEYS + 1
        pose = bank.keys.shape[1] * bank.keys.shape[2] * 4
        fits = np.cumsum(count) * pose <= max_bytes          # the first ones, in order
        entries, count = entries[fits], count[fits]
        self.start = np.full(bank.frames.size, -1, np.int64)
        self.start[entries] = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
        ids = np.repeat(entries, count)
        j = np.arange(ids.size) - np.repeat(self.start[entries], count)
        self.keys = bank.interpolate(ids, j / SUB_KEYS) if ids.size else \
            np.zeros((0,) + bank.keys.shape[1:], np.float32)

    @property
    def nbytes(self) -> int:
        return int(self.keys.nbytes)

    def grow(self, entries: int):
        """The bank now has ``entries`` entries (the new ones not resampled)."""
        extra = entries - self.start.size
        if extra > 0:
            self.start = np.concatenate([self.start, np.full(extra, -1, np.int64)])

    def sample(self, bank, clip_ids, u, out):
        """Poses of ``clip_ids`` at clip-local times ``u`` into ``out``: from the grid
        keys where ``u`` is on the grid of a resampled entry, interpolated by ``bank``
        elsewhere."""
        uq = u * SUB_KEYS
        j = np.rint(uq)
        start = self.start[clip_ids]
        on = (start >= 0) & (uq == j)
        if on.all():
            return np.take(self.keys, start + j.astype(np.int64), axis=0, out=out,
                           mode="clip")
        if on.any():
            if out is None:
                out = np.empty((clip_ids.size,) + self.keys.shape[1:], np.float32)
            out[on] = self.keys[start[on] + j[on].astype(np.int64)]
            rest = ~on
            out[rest] = bank.interpolate(clip_ids[rest], u[rest])
            return out
        return bank.interpolate(clip_ids, u, out)
