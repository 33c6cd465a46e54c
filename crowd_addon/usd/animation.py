"""``SkelAnimation`` prims from local SQT poses over time.

One function writes every animation of the export: a stream's timeline, a unique's,
and the blend bank (each in its own layer). A channel that is the same at every frame
(often ``scales``, and ``translations`` of skeletons without root motion) is authored
as samples at its two ends, which readers hold in between; not as a default value,
because value clips (through which agents that change read these layers) contribute
time samples only.

Types follow the UsdSkel schema: ``translations`` ``float3[]``, ``rotations``
``quatf[]``, ``scales`` ``half3[]`` (so non-unit scales keep ~3 significant digits).
"""

from __future__ import annotations

import numpy as np
from pxr import Sdf

from . import convert
from .layers import attribute

__all__ = ["author_animation", "define_animation", "author_samples"]

_T = Sdf.ValueTypeNames
_CHANNELS = (("translations", _T.Float3Array, convert.translations),
             ("rotations", _T.QuatfArray, convert.rotations),
             ("scales", _T.Half3Array, convert.scales))


def author_animation(prim: Sdf.PrimSpec, joints, poses: np.ndarray, times) -> int:
    """Make ``prim`` a SkelAnimation of ``poses`` sampled at ``times``.

    Parameters
    ----------
    prim : a prim spec (its type is set to ``SkelAnimation``).
    joints : Vt.TokenArray of the skeleton's joint paths, B tokens.
    poses : (T, >= B, 10) float32 local SQT; bones beyond B are ignored.
    times : (T,) time codes (frames of this prim's layer).

    Returns
    -------
    int, the number of time samples authored for channels that change (0 for a
    fully constant animation).
    """
    define_animation(prim, joints)
    return author_samples(prim, poses[:, :len(joints)], times)


def define_animation(prim: Sdf.PrimSpec, joints) -> None:
    """``prim`` becomes a SkelAnimation of ``joints`` with its three channels, no values."""
    prim.typeName = "SkelAnimation"
    attribute(prim, "joints", _T.TokenArray, joints, uniform=True)
    for name, type_name, _ in _CHANNELS:
        attribute(prim, name, type_name)


def author_samples(prim: Sdf.PrimSpec, poses: np.ndarray, times) -> int:
    """Time samples of ``poses`` (T, B, 10) at ``times`` (ascending) on the channels of
    ``prim`` (:func:`define_animation`); one stretch of a longer animation may be
    written per call, in time order. A channel the same over the stretch gets samples
    at its two ends only (one if it is one time). Returns the samples authored for
    channels that change."""
    layer = prim.layer
    times = [float(t) for t in times]
    ends = sorted({0, len(times) - 1})
    samples = 0
    for (name, _, to_vt), data in zip(_CHANNELS, convert.sqt_components(poses)):
        path = prim.path.AppendProperty(name)
        if (data == data[:1]).all():
            value = to_vt(data[0])
            for k in ends:
                layer.SetTimeSample(path, times[k], value)      # held in between
            continue
        for k, t in enumerate(times):
            layer.SetTimeSample(path, t, to_vt(data[k]))
        samples += len(times)
    return samples
