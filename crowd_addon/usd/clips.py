"""Agents that change what they play: value clips over shared layers, not baked copies.

An agent that is not static plays a sequence of pieces (:class:`~.shot.Pieces`): a
stream at an offset, a unique, or a blend. Its ``SkelAnimation`` holds no poses; a
``clips`` set (UsdClipsAPI) picks, piece by piece, the layer that has them:

- a stream piece reads the stream's layer (the same one the shared offset animations
  reference) at ``F - O``;
- a unique piece reads the unique's layer at ``F``;
- a blend piece reads its frames from a *blend bank* of its skeleton, a layer in
  which each blend has its own stretch of time (a skeleton's blends fill as many
  banks as :data:`BANK_FRAMES` needs, so each is written and freed in turn).

So a transition costs its blending frames once, and the agent's steady stretches
stay shared. Frames an agent looks at something (*aim* pieces, :data:`~.shot.AIM`:
its own poses with the look's turn in the chain joints) go to the same banks, read
the same way. Every clip layer holds its animation at :data:`PRIM` and authors every
channel as time samples (clips contribute time samples only; a constant channel is
one sample). Pieces switch between samples, half a sample before their first frame
(``start - 0.5 / N`` with ``N`` samples a frame, ``start - 0.5`` without sub-frame
samples): every sample time lies inside one piece, so readers that sample whole frames
(Blender's importer) and UsdSkel agree exactly there, and a sub-frame sample just
before a switch still reads the piece the crowd showed then.
"""

from __future__ import annotations

import numpy as np
from pxr import Sdf, Vt

from .animation import author_samples, define_animation
from .layers import attribute, define, new_layer
from .shot import AIM, STREAM, TRANSITION

__all__ = ["PRIM", "BANK_FRAMES", "BankLayout", "bank_layout", "bank_layer", "manifest_layer",
           "clip_sets"]

#: the animation prim of every layer a clip reads (streams, uniques, blend banks)
PRIM = "Animation"
#: empty frames between two blends in a bank (no sample is shared across blends)
GAP = 1
#: blends whose poses are rebuilt and written at a time
_BANK_CHUNK = 2048
#: samples (frames, or frames x substeps) a bank layer holds at most (~110 MB of 82-bone
#: poses); more go to the next
BANK_FRAMES = 65536
_T = Sdf.ValueTypeNames


class BankLayout:
    """One bank layer: blends of skeleton ``skeleton`` (``pieces``, indices into the
    shot's pieces), numbered ``part`` among that skeleton's banks, each at bank time
    ``base`` (its first frame); ``times`` every sample's bank time (``substeps`` a
    frame), blend after blend; ``frames`` the blends' frames."""

    def __init__(self, skeleton: int, part: int, pieces: np.ndarray, lengths: np.ndarray,
                 substeps: int = 1):
        self.skeleton, self.part, self.pieces = skeleton, part, pieces
        self.lengths, self.substeps = lengths, substeps
        self.base = np.cumsum(lengths + GAP) - (lengths + GAP)
        frames = np.repeat(self.base - np.cumsum(lengths) + lengths, lengths) + \
            np.arange(int(lengths.sum()))
        self.times = (frames[:, None] + np.arange(substeps) / substeps).reshape(-1)
        self.frames = int(lengths.sum())

    @property
    def key(self) -> tuple:
        return ("blend", self.skeleton, self.part)


def bank_layout(shot, frames_per_bank: int | None = None) -> list:
    """The shot's blend pieces laid out in banks: per skeleton, consecutive blends go
    to one bank layer until it holds ``frames_per_bank`` (default :data:`BANK_FRAMES`)
    frames, so a layer is written and freed before the next is built. Returns the
    :class:`BankLayout` list."""
    frames_per_bank = frames_per_bank or BANK_FRAMES
    p, n = shot.pieces, shot.substeps
    blend = np.flatnonzero((p.kind == TRANSITION) | (p.kind == AIM))
    skel = shot.agent_skeleton[p.agent[blend]]
    out = []
    for k in np.unique(skel).tolist():
        mine = blend[skel == k]
        lengths = (p.end - p.start)[mine]
        part = (np.cumsum(lengths) - lengths) * n // frames_per_bank
        for j, q in enumerate(np.unique(part).tolist()):
            out.append(BankLayout(int(k), j, mine[part == q], lengths[part == q], n))
    return out


def bank_layer(shot, layout: BankLayout, joints, fmt, name: str):
    """One bank: its blends' frames at their bank times. A generator yielding the
    blends written so far after each batch (their poses are rebuilt a batch at a time)
    and returning the layer."""
    times = layout.times
    layer = new_layer(fmt, shot.fps, float(times[0]), float(times[-1]), default_prim=PRIM,
                      comment=f"crowd blends of {name!r} (bank {layout.part}): each blend's "
                              "frames in a stretch of its own; agents read them through "
                              "value clips")
    with Sdf.ChangeBlock():
        prim = define(layer, PRIM, "SkelAnimation")
        define_animation(prim, joints)
    n = len(joints)
    first = np.r_[0, np.cumsum(layout.lengths)] * layout.substeps
    for a in range(0, layout.pieces.size, _BANK_CHUNK):
        b = min(a + _BANK_CHUNK, layout.pieces.size)
        with Sdf.ChangeBlock():
            author_samples(prim, shot.piece_poses(layout.pieces[a:b])[:, :n],
                           times[first[a]:first[b]])
        yield b
    return layer


def manifest_layer(fmt, fps: float):
    """The clips' manifest: which attributes the clips provide (values in the clips)."""
    layer = new_layer(fmt, fps, 0.0, 0.0, default_prim=PRIM,
                      comment="value clip manifest of the crowd's animations")
    prim = define(layer, PRIM, "SkelAnimation")
    for name, type_name in (("translations", _T.Float3Array), ("rotations", _T.QuatfArray),
                            ("scales", _T.Half3Array)):
        attribute(prim, name, type_name)
    return layer


def clip_sets(shot, assets, banks):
    """One ``clips`` dictionary per non-static agent, in agent order (a generator, so
    the work is spread over the export's steps).

    ``assets``: ``{("stream", s) | ("unique", u) | BankLayout.key | "manifest": asset
    path}`` relative to the layer the dictionaries are authored in; ``banks``:
    :func:`bank_layout`'s result.
    """
    p = shot.pieces
    clip_time = np.where(p.kind == STREAM, p.start - p.offset, p.start).astype(np.float64)
    key = [("stream" if k == STREAM else "unique", int(r))
           for k, r in zip(p.kind.tolist(), p.ref.tolist())]
    for bank in banks:
        clip_time[bank.pieces] = bank.base
        for j in bank.pieces.tolist():
            key[j] = bank.key
    manifest = Sdf.AssetPath(assets["manifest"])
    bounds = np.flatnonzero(np.r_[True, p.agent[1:] != p.agent[:-1], True])
    half = 0.5 / shot.substeps                  # half a sample: switches lie between samples
    start, end = p.start.astype(np.float64) - half, p.end.astype(np.float64) - half
    for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
        used = list(dict.fromkeys(key[a:b]))
        index = [used.index(k) for k in key[a:b]]
        times, active = [], []
        for j in range(a, b):
            c = clip_time[j]
            times += [(start[j], c - half), (end[j], c + (end[j] - start[j]) - half)]
            active.append((start[j], float(index[j - a])))
        yield {"default": {
            "assetPaths": Sdf.AssetPathArray([assets[k] for k in used]),
            "primPath": f"/{PRIM}",
            "active": Vt.Vec2dArray(active),
            "times": Vt.Vec2dArray(times),
            "manifestAssetPath": manifest}}
