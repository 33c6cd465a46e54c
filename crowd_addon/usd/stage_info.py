"""What an importer needs to know of a stage before it reads it: its clock and range.

A stage's time codes are crowd frames (docs/usd_export.md, "Time"): the main layer's
``timeCodesPerSecond`` is the crowd's frame rate, ``startTimeCode`` and
``endTimeCode`` its first and last frame (the last plus ``(N - 1) / N`` with ``N``
samples a frame). Blender's USD importer sets the scene's frame range from these but
leaves its frame rate, so a 30 fps crowd played at Blender's default 24 fps
(:mod:`crowd_addon.blender.import_usd` sets both). Only the main layer's metadata is
read, not the stage.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from pxr import Sdf, Tf

from ..core.base.errors import CrowdError

__all__ = ["StageTiming", "stage_timing"]


@dataclass(frozen=True)
class StageTiming:
    """``fps`` (the stage's ``timeCodesPerSecond``), ``first`` and ``last`` whole frames
    of its time range, and of a crowd export's ``customLayerData.crowd``: ``layout``
    (``"instanced"`` / ``"blender"``; None for another stage), ``agents`` and
    ``substeps`` (None when not ours)."""

    fps: float
    first: int
    last: int
    layout: str | None = None
    agents: int | None = None
    substeps: int | None = None


def stage_timing(path) -> StageTiming:
    """The :class:`StageTiming` of the stage whose main layer is ``path``. A stage
    without a time range (a still one) has ``first == last`` at its start. Raises
    CrowdError when ``path`` is no readable USD layer."""
    shown = os.fspath(path)
    if not os.path.isfile(shown):
        raise CrowdError(f"{shown}: no such USD file")
    try:
        layer = Sdf.Layer.OpenAsAnonymous(os.path.abspath(shown), True)   # metadata only
    except Tf.ErrorException as e:
        raise CrowdError(f"{shown}: not a readable USD layer: {e}") from None
    if layer is None:
        raise CrowdError(f"{shown}: not a readable USD layer")
    fps = float(layer.timeCodesPerSecond)
    if not math.isfinite(fps) or fps <= 0:
        raise CrowdError(f"{shown}: timeCodesPerSecond {fps} is not a frame rate")
    start = float(layer.startTimeCode) if layer.HasStartTimeCode() else 1.0
    end = float(layer.endTimeCode) if layer.HasEndTimeCode() else start
    crowd = layer.customLayerData.get("crowd")
    crowd = dict(crowd) if isinstance(crowd, dict) else {}
    first = math.ceil(start - 1e-6)
    last = max(first, math.floor(end + 1e-6))
    layout = crowd.get("layout")
    return StageTiming(fps=fps, first=first, last=last,
                       layout=layout if isinstance(layout, str) else None,
                       agents=_int(crowd.get("agents")), substeps=_int(crowd.get("substeps")))


def _int(value):
    return value if isinstance(value, int) and not isinstance(value, bool) else None
