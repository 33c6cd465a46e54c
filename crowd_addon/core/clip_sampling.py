"""Where a baked clip samples its action: the key times, the events, and whether its
keys are close enough to be interpolated.

A clip has one key every ``step = scene_fps / (crowd_fps * samples_per_frame)``
Blender frames from the start of the action's frame range (:func:`sample_times`);
pose markers become clip events at fractional clip frames (:func:`marker_events`).
The Blender side reads the frame range and markers (``crowd_addon.blender.action_data``).

Between keys the crowd interpolates (lerp, shortest-arc nlerp). Where the action turns
a bone the long way round between two keys (an Euler curve going from 179 to -179
degrees is a full turn in Blender), or fast enough that the arc is not a straight
blend, the in-between poses differ from Blender's: :func:`interpolation_misses`
measures it halfway between keys against the curves' true values and
:func:`interpolation_note` words it for the bake report, with the samples per frame
that would follow the motion.
"""

from __future__ import annotations

import math

import numpy as np

from . import pose as sqt
from .errors import CrowdError

__all__ = ["sample_times", "marker_events", "interpolation_misses", "interpolation_note",
           "MISS_TOLERANCE", "MAX_SAMPLES_PER_FRAME", "ADVICE_INTERVALS"]

#: Radians an interpolated rotation may miss the action's halfway between keys.
MISS_TOLERANCE = 0.05
#: The most keys per crowd frame a bake takes.
MAX_SAMPLES_PER_FRAME = 16
#: How many of the worst key intervals the samples-per-frame advice is checked on.
ADVICE_INTERVALS = 8


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


def interpolation_misses(keys: np.ndarray, halfway: np.ndarray) -> np.ndarray:
    """Angles ``(F - 1, B)`` in radians between the rotation the crowd interpolates
    halfway between consecutive keys (shortest-arc nlerp of ``keys[i]`` and
    ``keys[i + 1]``) and ``halfway[i]``, the action's own rotation there.

    keys : (F, B, 10) local SQT keys; halfway : (F - 1, B, 10) local SQT at the
    midpoints between them.
    """
    a = np.asarray(keys[:-1, :, sqt.ROT], np.float64)
    b = np.asarray(keys[1:, :, sqt.ROT], np.float64)
    mid = a + np.where((a * b).sum(-1, keepdims=True) < 0, -b, b)
    true = np.asarray(halfway[..., sqt.ROT], np.float64)
    dot = np.abs((mid * true).sum(-1))
    dot /= np.linalg.norm(mid, axis=-1) * np.linalg.norm(true, axis=-1)
    return 2 * np.arccos(np.minimum(dot, 1.0))


def interpolation_note(name: str, times: np.ndarray, keys: np.ndarray, evaluate, bone_names,
                       samples_per_frame: int = 1, tolerance: float = MISS_TOLERANCE):
    """A bake report line when the keys of action ``name`` are too far apart to be
    interpolated (:func:`interpolation_misses` above ``tolerance`` anywhere), else None.

    Parameters
    ----------
    times : (F,) Blender frames of the keys (evenly spaced); keys : (F, B, 10).
    evaluate : ``evaluate(frames)`` -> (n, B, 10) the action's local SQT at Blender
        frames (the F-curves evaluated, e.g. ``pose_channels.local_sqt``).
    bone_names : the B bone names; samples_per_frame : keys per crowd frame of the bake.

    The note names the bone and the key frames where the miss is largest, how many key
    intervals and bones miss, and the fewest samples per frame (up to
    :data:`MAX_SAMPLES_PER_FRAME`) whose keys follow the action over the
    :data:`ADVICE_INTERVALS` worst intervals (evaluated at those keys and halfway
    between them).
    """
    times = np.asarray(times, np.float64)
    misses = interpolation_misses(keys, evaluate(0.5 * (times[:-1] + times[1:])))
    bad = misses > tolerance
    if not bad.any():
        return None
    i, b = np.unravel_index(int(np.argmax(misses)), misses.shape)
    worst = float(misses[i, b])
    per_interval = misses.max(1)
    flagged = np.flatnonzero(per_interval > tolerance)
    check = flagged[np.argsort(-per_interval[flagged], kind="stable")[:ADVICE_INTERVALS]]
    frame = (times[1] - times[0]) * samples_per_frame     # Blender frames per crowd frame
    advice, left = None, worst
    for n in range(samples_per_frame + 1, MAX_SAMPLES_PER_FRAME + 1):
        step = frame / n
        grids = []
        for c in check.tolist():                           # their keys over each interval
            j = np.arange(math.floor((times[c] - times[0]) / step + 1e-9),
                          math.ceil((times[c + 1] - times[0]) / step - 1e-9) + 1)
            grids.append(times[0] + j * step)
        at = np.cumsum([0] + [len(g) for g in grids])
        poses = evaluate(np.concatenate(grids + [0.5 * (g[:-1] + g[1:]) for g in grids]))
        half = at[-1] + at - np.arange(len(at))            # where each grid's midpoints start
        left = max(float(interpolation_misses(poses[at[k]:at[k + 1]],
                                              poses[half[k]:half[k + 1]]).max())
                   for k in range(len(grids)))
        if left <= tolerance:
            advice = n
            break
    around = " (the long way round, e.g. an Euler angle crossing +-180 degrees)" \
        if worst > math.pi / 2 else ""
    intervals, bones = int(bad.any(1).sum()), int(bad.any(0).sum())
    text = (f"action {name!r}: bone {bone_names[b]!r} turns too fast between the keys at "
            f"frames {times[i]:g} and {times[i + 1]:g} to be interpolated: halfway, the "
            f"crowd's rotation is {worst:.2f} rad off the action's{around}; {intervals} key "
            f"interval{'s' if intervals != 1 else ''} of {bones} bone"
            f"{'s' if bones != 1 else ''} {'miss' if intervals != 1 else 'misses'} by more "
            f"than {tolerance:g} rad")
    if advice is not None:
        return text + f"; bake with {advice} samples per frame to follow it"
    return text + (f"; {MAX_SAMPLES_PER_FRAME} samples per frame still miss by {left:.2f} "
                   "rad there")
