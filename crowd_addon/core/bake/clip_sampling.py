"""Where a baked clip samples its action: the key times and the events.

A clip has one key every ``step = scene_fps / (crowd_fps * samples_per_frame)``
Blender frames from the start of the action's frame range (:func:`sample_times`);
pose markers become clip events at fractional clip frames (:func:`marker_events`).
The Blender side reads the frame range and markers (``crowd_addon.blender.action_data``).
Whether the keys are close enough to be interpolated is :mod:`.between_keys`.
"""

from __future__ import annotations

import math

import numpy as np

from ..base.errors import CrowdError

__all__ = ["sample_times", "marker_events", "MAX_SAMPLES_PER_FRAME"]

#: The most keys per crowd frame a bake takes.
MAX_SAMPLES_PER_FRAME = 16


def sample_times(name: str, start: float, end: float, step: float, loop: bool):
    """Blender frames of the clip keys of action ``name``: every ``step`` frames from
    ``start``. A range that is not a whole number of steps is stretched (loops, so
    the period is exact) or extended past ``end`` (clamped clips, so no key is lost).

    Returns ``(times, notes)``: (F,) float64 frames, F >= 2 for ``end > start``, and
    a list of str remarks for the bake report.
    """
    span = end - start
    steps = span / step
    notes = []
    if abs(steps - round(steps)) < 1e-6:
        count = int(round(steps))
    elif loop:
        count = max(1, int(round(steps)))
        notes.append(f"action {name!r}: {span:g} frames is not a whole number of crowd "
                     f"frames; the loop is resampled to {count} steps of "
                     f"{span / count:g} frames so that it still closes")
        step = span / count
    else:
        count = math.ceil(steps)
        notes.append(f"action {name!r}: the last key is sampled at frame "
                     f"{start + count * step:g}, after the end of the action ({end:g})")
    return start + np.arange(count + 1) * step, notes


def marker_events(name: str, markers, times: np.ndarray, begin: float, end: float) -> tuple:
    """Clip events ``((marker name, clip frame), ...)`` of pose ``markers``
    (``(name, Blender frame)`` pairs) on a clip keyed at ``times`` (F,) float64.

    A marker outside the clip's keys (by more than 1e-6 of a clip frame) raises a
    :class:`CrowdError` naming it and the action's frames ``begin..end``.
    """
    step = (times[-1] - times[0]) / (len(times) - 1)
    events = []
    for marker, frame in markers:
        f = (frame - times[0]) / step
        if not -1e-6 <= f <= len(times) - 1 + 1e-6:
            raise CrowdError(f"action {name!r}: pose marker {marker!r} at frame {frame} is "
                             f"outside the action's frames {begin:g}..{end:g}")
        events.append((marker, float(min(max(f, 0.0), len(times) - 1))))
    return tuple(events)
