"""An action's F-curves for one armature, read and validated before anything is baked.

Handles slotted actions (Blender 4.4+: ``action.slots``,
``action.layers[0].strips[0].channelbag(slot)``) and legacy actions (4.2-4.3:
``action.fcurves``). :func:`read_action` names the action and the bone at fault for
bones the armature lacks, NaN keys, empty or one-frame actions, and works out the
frames to sample, the pose markers in clip frames and the loop flag. What it reads
is handed to core as arrays: keys packed into a :class:`~crowd_addon.core.bake.fcurve.CurveSet`,
data paths mapped by :func:`~crowd_addon.core.bake.pose_channels.channel_targets`, key
times and events from :mod:`crowd_addon.core.bake.clip_sampling`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from ..core.bake.clip_sampling import marker_events, sample_times
from ..core.base.errors import CrowdError
from ..core.bake.fcurve import BEZIER, LINEAR, CurveSet, check_finite
from ..core.bake.pose_channels import CHANNELS, channel_targets
from .compat import action_slots, assigned_slot, fcurve_owner

__all__ = ["BoneCurve", "ActionSource", "resolve_slot", "action_fcurves", "read_action"]


@dataclass(eq=False)
class BoneCurve:
    """One F-curve driving column ``column`` of bone ``bone`` (skeleton index)."""

    fcurve: object
    bone: int
    column: int


@dataclass(eq=False)
class ActionSource:
    """What :mod:`.bake` needs of one action.

    fcurves : the bone F-curves, in the order of ``keys``.
    bones, columns : (C,) int64 skeleton bone and channel column of each curve.
    keys : their keyframes packed (:class:`CurveSet`).
    fast : (C,) bool, curves the numpy evaluator reproduces; the others (modifiers
        other than Cycles within the key range, easing, sampled points) are
        evaluated with ``FCurve.evaluate``.
    times : (F,) float64 Blender frames of the clip's keys.
    events : ((name, clip frame), ...) from the pose markers.
    frame_set_reason : why only ``scene.frame_set`` sampling is exact, or None.
    notes : resampling remarks for the bake report.
    between : None when ``keys`` and ``fast`` hold for any time in the sampled range,
        else ``between()`` -> ``(keys, fast)`` that do (``keys`` then lacks the
        interpolation of curves sampled only on their keys, where it does not matter).
    """

    action: object
    slot: object
    name: str
    fcurves: list
    bones: np.ndarray
    columns: np.ndarray
    keys: CurveSet
    fast: np.ndarray
    times: np.ndarray
    loop: bool
    events: tuple
    frame_set_reason: str | None = None
    notes: list = field(default_factory=list)
    between: object = None

    @property
    def curves(self) -> list:
        """The curves as :class:`BoneCurve` (F-curve, bone, column), in ``keys`` order."""
        return [BoneCurve(fc, int(b), int(c))
                for fc, b, c in zip(self.fcurves, self.bones, self.columns)]


def resolve_slot(action, armature_obj, slot=None):
    """The slot of ``action`` that animates the armature (None for legacy actions).

    ``slot``: an ``ActionSlot`` or its identifier. Otherwise the armature's assigned
    slot when it plays this action, else the only object slot with F-curves.
    """
    slots = action_slots(action)
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
    if ad is not None and ad.action == action and assigned_slot(ad) is not None:
        return assigned_slot(ad)
    usable = [s for s in slots if s.target_id_type in ("OBJECT", "UNSPECIFIED")
              and _has_fcurves(fcurve_owner(action, s))]
    if len(usable) == 1:
        return usable[0]
    if not usable:
        raise CrowdError(f"action {action.name!r} has no slot with F-curves for an object")
    raise CrowdError(f"action {action.name!r} has several object slots "
                     f"{[s.identifier for s in usable]}; choose one")


def action_fcurves(action, slot) -> list:
    """The F-curves of ``slot`` in ``action`` (all F-curves of a legacy action)."""
    owner = fcurve_owner(action, slot)
    return [] if owner is None else list(owner.fcurves)


def _has_fcurves(owner) -> bool:
    return owner is not None and len(owner.fcurves) > 0


def _is_cyclic(fc) -> bool:
    """Blender's BKE_fcurve_is_cyclic: a first, unrestricted, infinite Cycles modifier."""
    if len(fc.modifiers) == 0:
        return False
    m = fc.modifiers[0]
    return (m.type == "CYCLES" and not m.mute and not m.use_restricted_range
            and not m.use_influence and m.cycles_before == 0 and m.cycles_after == 0
            and m.mode_before in ("REPEAT", "REPEAT_OFFSET")
            and m.mode_after in ("REPEAT", "REPEAT_OFFSET"))


def _bulk(collection, prop, dtype):
    """``prop`` of every item of ``collection`` with one ``foreach_get``."""
    buf = np.empty(len(collection), dtype)
    collection.foreach_get(prop, buf)
    return buf


def _read_keys(fields, kps, start, which=None):
    """Keyframe properties into packed arrays, one ``foreach_get`` per curve and
    field: ``fields`` is ``((prop, packed), ...)``, arrays ``(N, ...)`` alike whose
    rows ``start[c]:start[c+1]`` (``start``: a list) are curve ``c``'s keys; curves
    ``which`` (default all)."""
    width = fields[0][1][:1].size
    views = []
    for prop, packed in fields:
        view = packed.reshape(-1)
        if view.dtype == np.float32:    # a buffer: slices of a memoryview cost less
            view = memoryview(view)     # (enums are read as sequences: numpy only)
        views.append((prop, view))
    edges = start if width == 1 else [i * width for i in start]
    get = type(kps[0]).foreach_get      # unbound: skips the RNA attribute lookup per call
    spans = zip(kps, edges, edges[1:]) if which is None else \
        ((kps[c], edges[c], edges[c + 1]) for c in which)
    if len(views) == 1:
        (prop, view), = views
        for kp, a, b in spans:
            if a != b:
                get(kp, prop, view[a:b])
        return
    for kp, a, b in spans:
        if a != b:
            for prop, view in views:
                get(kp, prop, view[a:b])


@functools.cache
def _interpolation_fits_bytes() -> bool:
    """Whether every ``Keyframe.interpolation`` value fits a byte."""
    import bpy
    values = [e.value for e in bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items]
    return min(values) >= 0 and max(values) < 256


def _read_interpolation_enum(ipo, keys, kps, group):
    """``Keyframe.interpolation`` of curves ``group`` (equal key counts) into ``ipo``.

    ``foreach_get`` hands an enum over item by item whatever the buffer, and a
    ``bytearray`` takes the items fastest (the values are below 256)."""
    members = group.tolist()
    if not _interpolation_fits_bytes():
        bounds = keys.start.tolist()
        _read_keys((("interpolation", ipo),), kps, bounds, members)
        return
    index, k = keys.key_index(group)
    parts = []
    get = type(kps[0]).foreach_get
    for c in members:
        part = bytearray(k)
        get(kps[c], "interpolation", part)
        parts.append(part)
    values = np.frombuffer(b"".join(parts), np.uint8)
    ipo[index] = values if isinstance(index, slice) else values.reshape(len(members), k)


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

    Per-curve flags (mute, validity, array index, extrapolation) are read for all
    F-curves at once; the keyframes with one ``foreach_get`` per curve and field.
    """
    name = action.name
    slot = resolve_slot(action, armature_obj, slot)
    owner = fcurve_owner(action, slot)
    fcs = [] if owner is None else list(owner.fcurves)
    selected, reason = [], None
    if fcs:
        coll = owner.fcurves
        bone, first_column, width, rotation_mode, missing = channel_targets(
            tuple([fc.data_path for fc in fcs]), skeleton.bone_names)
        if missing:
            raise CrowdError(f"action {name!r} animates bones that armature "
                             f"{armature_obj.name!r} lacks: {sorted(set(missing))}")
        live = (bone >= 0) & ~_bulk(coll, "mute", bool) & _bulk(coll, "is_valid", bool)
        array_index = _bulk(coll, "array_index", np.int32)
        extrapolation = _bulk(coll, "extrapolation", np.int32)
        channel = live & (0 <= array_index) & (array_index < width)
        column = (first_column + array_index).tolist()
        groups = getattr(owner, "groups", None)
        muted_groups = groups is None or any(g.mute for g in groups)
        # the reason is the one given by the last curve that gives one
        moded = np.flatnonzero(live & rotation_mode)
        reason_at = int(moded[-1]) if moded.size else -1
        if moded.size:
            reason = ("it animates the rotation mode of bone "
                      f"{skeleton.bone_names[bone[reason_at]]!r}")
        bone = bone.tolist()
        for c in np.flatnonzero(channel).tolist():
            fc = fcs[c]
            if muted_groups and c > reason_at and fc.group is not None and fc.group.mute:
                reason = f"F-curve group {fc.group.name!r} is muted"
            kp = fc.keyframe_points
            n = len(kp)
            mods = fc.modifiers
            modded = len(mods) > 0
            if n == 0 and not modded and len(fc.sampled_points) == 0:
                continue                              # an empty curve animates nothing
            selected.append((c, kp, n, bone[c], column[c], mods if modded else None))
    if not selected:
        raise CrowdError(f"action {name!r} is empty: no F-curves for the bones of armature "
                         f"{armature_obj.name!r}")
    which, kps, counts, bones, columns, mods = (list(v) for v in zip(*selected))
    fcurves = [fcs[c] for c in which]
    linear_value = fcurves[0].bl_rna.properties["extrapolation"].enum_items["LINEAR"].value
    extrapolation = extrapolation[which]

    def what(c):
        """Curve ``c`` in messages: the action, bone, property and array index."""
        prop = next(p for p, (col, w) in CHANNELS.items() if col <= columns[c] < col + w)
        return (f"action {name!r}, bone {skeleton.bone_names[bones[c]]!r}, "
                f"{prop}[{columns[c] - CHANNELS[prop][0]}]")

    start = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=start[1:])
    bounds = start.tolist()
    co = np.empty((bounds[-1], 2), np.float32)
    _read_keys((("co", co),), kps, bounds)
    check_finite(co, start, what, "key")
    keyed = np.flatnonzero(np.array(counts) > 0)
    first, last = co[start[keyed], 0], co[start[keyed + 1] - 1, 0]

    if action.use_frame_range:
        begin, end = float(action.frame_start), float(action.frame_end)
        auto_loop = bool(action.use_cyclic)
    else:
        sampled = [(fc.sampled_points[0].co[0], fc.sampled_points[-1].co[0])
                   for fc, n in zip(fcurves, counts) if not n and len(fc.sampled_points)]
        lows = first.tolist() + [a for a, _ in sampled]
        highs = last.tolist() + [b for _, b in sampled]
        if not lows:
            raise CrowdError(f"action {name!r} has no keyframes and no manual frame range")
        begin, end = float(min(lows)), float(max(highs))
        auto_loop = all(m is not None and _is_cyclic(fc) for fc, m in zip(fcurves, mods))
    if not end > begin:
        raise CrowdError(f"action {name!r} is one frame long (frame {begin:g}); a clip needs "
                         "at least two frames")
    loop = auto_loop if loop is None else bool(loop)
    times, notes = sample_times(name, begin, end, scene_fps / fps, loop)
    times32, extrap_linear = times.astype(np.float32), extrapolation == linear_value
    keys, fast, on_keys = _read_interpolation(mods, kps, what, co, start, keyed, times32,
                                              extrap_linear)

    def between():
        """The curves read for evaluation anywhere in the sampled range."""
        return _read_interpolation(mods, kps, what, co, start, keyed, times32,
                                   extrap_linear, force=True)[:2]

    events = marker_events(name, [(m.name, m.frame) for m in action.pose_markers], times,
                           begin, end)
    return ActionSource(action, slot, name, fcurves, np.array(bones, np.int64),
                        np.array(columns, np.int64), keys, fast, times, loop, events,
                        reason, notes, between if on_keys else None)


def _modifiers_allow(mods, inside) -> bool:
    """Whether a curve with modifiers ``mods`` is still its keys (no active modifier,
    or only Cycles while the samples stay ``inside`` its keys)."""
    kinds = {m.type for m in mods if not m.mute}
    return not kinds or (inside and kinds == {"CYCLES"})


def _read_interpolation(mods, kps, what, co, start, keyed, times32, extrap_linear,
                        force=False):
    """Complete the packed keys with interpolation and handles where they matter at
    the (sorted) frames ``times32`` (everywhere in their range when ``force``), and
    decide which curves the numpy evaluator takes. Returns ``(keys, fast, on_keys)``,
    ``on_keys`` telling whether some curves were left unread because every time is
    one of their keys.

    Cycles modifiers change nothing inside a curve's key range, so such curves stay
    fast; other modifiers, easing and sampled points are left to ``FCurve.evaluate``.
    Where every sample time is a key frame of a curve, the value there is the key's
    whatever the interpolation (Blender returns the key itself), so interpolation
    and handles are not read: dense motion capture costs one ``foreach_get`` per
    curve (until the bake's interpolation check evaluates between the keys).
    """
    n = len(mods)
    ipo = np.full(len(co), LINEAR, np.int32)
    linear = np.zeros(n, bool)
    keys = CurveSet(co, ipo, None, None, start, linear)
    left = right = None
    bounds = start.tolist()
    inside = np.zeros(n, bool)
    inside[keyed] = ((co[start[keyed], 0] <= times32[0])
                     & (times32[-1] <= co[start[keyed + 1] - 1, 0]))
    inside = inside.tolist()
    eligible = [c for c in keyed.tolist()
                if mods[c] is None or _modifiers_allow(mods[c], inside[c])]
    fast = np.zeros(n, bool)
    on_keys = False
    for group in keys.groups(eligible, frames_only=True):
        x = co[bounds[group[0]]:bounds[group[0] + 1], 0]
        if not (np.diff(x) > 0).all():
            continue
        fast[group] = True
        at = np.minimum(np.searchsorted(x, times32), len(x) - 1)
        if not force and (x[at] == times32).all():
            on_keys = True
            continue
        _read_interpolation_enum(ipo, keys, kps, group)
        linear[group] = extrap_linear[group]
        modes = keys.rows(ipo, group)                                    # (m, K)
        fast[group] = modes.max(1) <= BEZIER                # easing: FCurve.evaluate
        bezier = group[(modes == BEZIER).any(1)].tolist()
        if bezier:
            if left is None:
                left, right = np.zeros_like(co), np.zeros_like(co)
            if len(bezier) == n:
                bezier = None                             # all curves: no index lists
            _read_keys((("handle_left", left), ("handle_right", right)), kps, bounds,
                       bezier)
    if left is None:
        return keys, fast, on_keys
    check_finite(left, start, what, "left handle of key")
    check_finite(right, start, what, "right handle of key")
    return CurveSet(co, ipo, left, right, start, linear), fast, on_keys
