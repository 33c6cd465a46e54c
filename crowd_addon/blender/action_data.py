"""An action's F-curves for one armature, read and validated before anything is baked.

Handles slotted actions (Blender 4.4+: ``action.slots``,
``action.layers[0].strips[0].channelbag(slot)``) and legacy actions (4.2-4.3:
``action.fcurves``). :func:`read_action` names the action and the bone at fault for
bones the armature lacks, NaN keys, empty or one-frame actions, and works out the
frames to sample, the pose markers in clip frames and the loop flag.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import CrowdError
from .fcurve_eval import BEZIER, LINEAR, CurveSet

__all__ = ["CHANNELS", "CHANNEL_WIDTH", "BoneCurve", "ActionSource", "resolve_slot",
           "action_fcurves", "read_action"]

# column of each pose-bone property in the per-bone channel block (17 floats)
CHANNELS = {"location": (0, 3), "rotation_quaternion": (3, 4), "rotation_euler": (7, 3),
            "rotation_axis_angle": (10, 4), "scale": (14, 3)}
CHANNEL_WIDTH = 17
_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\](.*)$')


@dataclass(eq=False)
class BoneCurve:
    """One F-curve driving column ``column`` of bone ``bone`` (skeleton index)."""

    fcurve: object
    bone: int
    column: int


@dataclass(eq=False)
class ActionSource:
    """What :mod:`.bake` needs of one action.

    curves : the bone F-curves, in the order of ``keys``.
    keys : their keyframes packed (:class:`CurveSet`).
    fast : (C,) bool, curves the numpy evaluator reproduces; the others (modifiers
        other than Cycles within the key range, easing, sampled points) are
        evaluated with ``FCurve.evaluate``.
    times : (F,) float64 Blender frames of the clip's keys.
    events : ((name, clip frame), ...) from the pose markers.
    frame_set_reason : why only ``scene.frame_set`` sampling is exact, or None.
    notes : resampling remarks for the bake report.
    """

    action: object
    slot: object
    name: str
    curves: list
    keys: CurveSet
    fast: np.ndarray
    times: np.ndarray
    loop: bool
    events: tuple
    frame_set_reason: str | None = None
    notes: list = field(default_factory=list)


def resolve_slot(action, armature_obj, slot=None):
    """The slot of ``action`` that animates the armature (None for legacy actions).

    ``slot``: an ``ActionSlot`` or its identifier. Otherwise the armature's assigned
    slot when it plays this action, else the only object slot with F-curves.
    """
    slots = getattr(action, "slots", None)
    if slots is None:
        if slot is not None:
            raise CrowdError(f"action {action.name!r} has no slots (legacy action); "
                             f"cannot pick slot {slot!r}")
        return None
    if slot is not None:
        for s in slots:
            if s == slot or s.identifier == slot:
                return s
        raise CrowdError(f"action {action.name!r} has no slot {slot!r}; it has "
                         f"{[s.identifier for s in slots]}")
    ad = armature_obj.animation_data
    if ad is not None and ad.action == action and ad.action_slot is not None:
        return ad.action_slot
    usable = [s for s in slots if s.target_id_type in ("OBJECT", "UNSPECIFIED")
              and action_fcurves(action, s)]
    if len(usable) == 1:
        return usable[0]
    if not usable:
        raise CrowdError(f"action {action.name!r} has no slot with F-curves for an object")
    raise CrowdError(f"action {action.name!r} has several object slots "
                     f"{[s.identifier for s in usable]}; choose one")


def action_fcurves(action, slot) -> list:
    """The F-curves of ``slot`` in ``action`` (all F-curves of a legacy action)."""
    if slot is None:
        return list(action.fcurves)
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(slot)
            if bag is not None:
                return list(bag.fcurves)
    return []


@functools.lru_cache(maxsize=4096)
def _bone_path(data_path):
    """(bone name, rest of the path) of a ``pose.bones["..."]`` data path, else Nones
    (cached: a rig's actions share their paths)."""
    m = _PATH.match(data_path)
    if m is None:
        return None, None
    name = m.group(1)
    return (re.sub(r"\\(.)", r"\1", name) if "\\" in name else name), m.group(2)


def _check_finite(arr, start, whats, part, action):
    """Raise naming the curve and key of the first non-finite row of packed ``arr``."""
    if not np.isfinite(arr).all():
        row = int(np.argmax(~np.isfinite(arr).all(1)))
        c = int(np.searchsorted(start, row, side="right") - 1)
        bone, prop, i = whats[c]
        raise CrowdError(f"action {action!r}, bone {bone!r}, {prop}[{i}]: {part} "
                         f"{row - start[c]} is not finite "
                         f"({arr[row].tolist()})")


def _is_cyclic(fc) -> bool:
    """Blender's BKE_fcurve_is_cyclic: a first, unrestricted, infinite Cycles modifier."""
    if len(fc.modifiers) == 0:
        return False
    m = fc.modifiers[0]
    return (m.type == "CYCLES" and not m.mute and not m.use_restricted_range
            and not m.use_influence and m.cycles_before == 0 and m.cycles_after == 0
            and m.mode_before in ("REPEAT", "REPEAT_OFFSET")
            and m.mode_after in ("REPEAT", "REPEAT_OFFSET"))


def read_action(armature_obj, skeleton, action, fps: float, scene_fps: float,
                slot=None, loop=None) -> ActionSource:
    """Read and validate ``action`` for ``armature_obj`` baked at ``fps``.

    Parameters
    ----------
    skeleton : the core skeleton of the armature (bone order of the result).
    fps, scene_fps : crowd and scene frames per second; a clip key is every
        ``scene_fps / fps`` Blender frames from the start of the action's range
        (manual frame range if set, else the span of its bone keys).
    loop : None to take it from the action (manual range "Cyclic Animation", or every
        bone F-curve cycling through a Cycles modifier), else True/False.
    """
    name = action.name
    slot = resolve_slot(action, armature_obj, slot)
    index = {n: i for i, n in enumerate(skeleton.bone_names)}
    curves, whats, counts, missing, reason = [], [], [], [], None
    for fc in action_fcurves(action, slot):
        bone, rest = _bone_path(fc.data_path)
        if bone is None:
            continue
        if bone not in index:
            missing.append(bone)
            continue
        if fc.mute or not fc.is_valid:
            continue
        if rest == ".rotation_mode":
            reason = f"it animates the rotation mode of bone {bone!r}"
        prop = rest[1:] if rest.startswith(".") else None
        if prop not in CHANNELS or not 0 <= fc.array_index < CHANNELS[prop][1]:
            continue
        if fc.group is not None and fc.group.mute:
            reason = f"F-curve group {fc.group.name!r} is muted"
        n = len(fc.keyframe_points)
        if n == 0 and len(fc.sampled_points) == 0 and len(fc.modifiers) == 0:
            continue                              # an empty curve animates nothing
        curves.append(BoneCurve(fc, index[bone], CHANNELS[prop][0] + fc.array_index))
        whats.append((bone, prop, fc.array_index))
        counts.append(n)
    if missing:
        raise CrowdError(f"action {name!r} animates bones that armature "
                         f"{armature_obj.name!r} lacks: {sorted(set(missing))}")
    if not curves:
        raise CrowdError(f"action {name!r} is empty: no F-curves for the bones of armature "
                         f"{armature_obj.name!r}")
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    co = np.zeros((int(start[-1]), 2), np.float32)
    for c, bc in enumerate(curves):
        if counts[c]:
            bc.fcurve.keyframe_points.foreach_get("co", co[start[c]:start[c + 1]].reshape(-1))
    _check_finite(co, start, whats, "key", name)
    keyed = np.flatnonzero(np.array(counts) > 0)
    first, last = co[start[keyed], 0], co[start[keyed + 1] - 1, 0]

    if action.use_frame_range:
        begin, end = float(action.frame_start), float(action.frame_end)
        auto_loop = bool(action.use_cyclic)
    else:
        sampled = [(bc.fcurve.sampled_points[0].co[0], bc.fcurve.sampled_points[-1].co[0])
                   for c, bc in enumerate(curves) if not counts[c]
                   and len(bc.fcurve.sampled_points)]
        lows = list(first) + [a for a, _ in sampled]
        highs = list(last) + [b for _, b in sampled]
        if not lows:
            raise CrowdError(f"action {name!r} has no keyframes and no manual frame range")
        begin, end = float(min(lows)), float(max(highs))
        auto_loop = all(_is_cyclic(bc.fcurve) for bc in curves)
    if not end > begin:
        raise CrowdError(f"action {name!r} is one frame long (frame {begin:g}); a clip needs "
                         "at least two frames")
    loop = auto_loop if loop is None else bool(loop)
    times, notes = _sample_times(name, begin, end, scene_fps / fps, loop)
    keys, fast = _read_interpolation(name, curves, whats, co, start, keyed,
                                     times.astype(np.float32))

    step = (times[-1] - times[0]) / (len(times) - 1)
    events = []
    for m in action.pose_markers:
        f = (m.frame - times[0]) / step
        if not -1e-6 <= f <= len(times) - 1 + 1e-6:
            raise CrowdError(f"action {name!r}: pose marker {m.name!r} at frame {m.frame} is "
                             f"outside the action's frames {begin:g}..{end:g}")
        events.append((m.name, float(min(max(f, 0.0), len(times) - 1))))
    return ActionSource(action, slot, name, curves, keys, fast, times, loop, tuple(events),
                        reason, notes)


def _read_interpolation(name, curves, whats, co, start, keyed, times32):
    """Complete the packed keys with interpolation and handles where they matter,
    and decide which curves the numpy evaluator takes.

    Cycles modifiers change nothing inside a curve's key range, so such curves stay
    fast; other modifiers, easing and sampled points are left to ``FCurve.evaluate``.
    Where every sample time is a key frame of a curve, the value there is the key's
    whatever the interpolation (Blender returns the key itself), so interpolation
    and handles are not read: dense motion capture costs one ``foreach_get`` per
    curve.
    """
    n = len(curves)
    ipo = np.full(len(co), LINEAR, np.int32)
    linear = np.zeros(n, bool)
    keys = CurveSet(co, ipo, None, None, start, linear)
    left = right = None
    inside = np.zeros(n, bool)
    inside[keyed] = ((co[start[keyed], 0] <= times32[0])
                     & (times32[-1] <= co[start[keyed + 1] - 1, 0]))
    eligible = []
    for c in keyed:
        mods = curves[c].fcurve.modifiers
        kinds = {m.type for m in mods if not m.mute} if len(mods) else set()
        if not kinds or (inside[c] and kinds == {"CYCLES"}):
            eligible.append(c)
    fast = np.zeros(n, bool)
    for group in keys.groups(eligible, frames_only=True):
        x = co[start[group[0]]:start[group[0] + 1], 0]
        if not (np.diff(x) > 0).all():
            continue
        fast[group] = True
        at = np.minimum(np.searchsorted(x, times32), len(x) - 1)
        if (x[at] == times32).all():
            continue
        for c in group:
            fc = curves[c].fcurve
            fc.keyframe_points.foreach_get("interpolation", ipo[start[c]:start[c + 1]])
            linear[c] = fc.extrapolation == "LINEAR"
        modes = keys.rows(ipo, group)                                    # (m, K)
        fast[group] = modes.max(1) <= BEZIER                # easing: FCurve.evaluate
        for c in group[(modes == BEZIER).any(1)]:
            if left is None:
                left, right = np.zeros_like(co), np.zeros_like(co)
            kp, span = curves[c].fcurve.keyframe_points, slice(start[c], start[c + 1])
            kp.foreach_get("handle_left", left[span].reshape(-1))
            kp.foreach_get("handle_right", right[span].reshape(-1))
    if left is None:
        return keys, fast
    _check_finite(left, start, whats, "left handle of key", name)
    _check_finite(right, start, whats, "right handle of key", name)
    return CurveSet(co, ipo, left, right, start, linear), fast


def _sample_times(name, start, end, step, loop):
    """Blender frames of the clip keys: every ``step`` frames from ``start``; a range
    that is not a whole number of steps is stretched (loops, so the period is exact)
    or extended past ``end`` (clamped clips, so no key is lost)."""
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
