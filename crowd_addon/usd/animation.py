"""``SkelAnimation`` prims from local SQT poses over time.

One function writes every animation of the export: a stream's timeline, a unique's,
and the blend bank (each in its own layer). A channel that is the same at every frame
(often ``scales``, and ``translations`` of skeletons without root motion) is authored
as one time sample, which readers hold at every time; not as a default value, because
value clips (through which agents that change read these layers) contribute time
samples only.

Types follow the UsdSkel schema: ``translations`` ``float3[]``, ``rotations``
``quatf[]``, ``scales`` ``half3[]`` (so non-unit scales keep ~3 significant digits).
"""

from __future__ import annotations

import numpy as np
from pxr import Sdf

from . import convert
from .layers import attribute

__all__ = ["author_animation"]

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
    prim.typeName = "SkelAnimation"
    attribute(prim, "joints", _T.TokenArray, joints, uniform=True)
    layer = prim.layer
    times = [float(t) for t in times]
    samples = 0
    for (name, type_name, to_vt), data in zip(
            _CHANNELS, convert.sqt_components(poses[:, :len(joints)])):
        path = attribute(prim, name, type_name).path
        if (data == data[:1]).all():
            layer.SetTimeSample(path, times[0], to_vt(data[0]))     # held at every time
            continue
        for k, t in enumerate(times):
            layer.SetTimeSample(path, t, to_vt(data[k]))
        samples += len(times)
    return samples
