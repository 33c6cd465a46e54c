"""Bake Blender actions into core clips (local SQT keys at the crowd fps, or at a
multiple of it: ``samples_per_frame``).

Two ways, one result:

- **F-curves** (the fast path): every bone F-curve is read in bulk
  (:mod:`.action_data`) and the armature's pose channels and rest pose once; core
  evaluates the curves in numpy at all sample times at once
  (:mod:`crowd_addon.core.bake.fcurve`, Blender's own algorithm) and composes the
  channels into local SQT as Blender's ``BKE_pchan_to_mat4`` does
  (:mod:`crowd_addon.core.bake.pose_channels`).
- **frame_set** (exact by definition, slower): the action is played on the armature,
  ``scene.frame_set`` per key, ``pose.bones[].matrix`` read and made local. Used
  where the fast path cannot be exact: constraints, drivers on the pose, bones that
  do not inherit rotation or full scale, local-location or relative-parent bones,
  animated rotation modes, muted F-curve groups. The result says which actions
  were sampled and why.

Nothing is built until every action has been read and validated; a cancel through
the progress callback returns None and leaves the scene as it was.

Samples per frame: a clip keyed ``samples_per_frame`` times per crowd frame plays at
the same speed (a crowd plays a clip at the clip's own fps) but samples the action
between crowd frames from the action itself, for playback at other speeds and motion
blur. After an F-curve bake the curves are also evaluated halfway between the keys
and the pose the crowd plays there (the keys blended) is compared with them through
the skeleton: where a bone's head misses by more than 1e-3 scene units or its
rotation by more than 1e-3 rad (a fast motion, or a bone turning the long way round,
such as an Euler curve from 179 to -179 degrees, which Blender plays as a full turn)
the notes name the action, bones, frames and sizes and the samples per frame that
follow it (:func:`crowd_addon.core.bake.between_keys.between_keys_note`).

Notes are :class:`crowd_addon.core.bake.bake_report.Note` strings: the between-frame
misses are warnings (kind ``"between_frames"``); frame_set sampling and resampling
remarks are information.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.bake.armature_math import relative_to_parent, sqt_from_matrices
from ..core.anim.clip import Clip
from ..core.bake.bake_report import INFO, WARNING, Note
from ..core.bake.between_keys import between_keys_note
from ..core.bake.clip_sampling import MAX_SAMPLES_PER_FRAME
from ..core.base.errors import CrowdError
from ..core.bake.pose_channels import CHANNEL_WIDTH, CHANNELS, RigChannels, local_sqt
from ..core.base.skeleton import Skeleton
from .action_data import read_action
from .armature import matrices, skeleton_and_rest
from .compat import assigned_slot, play

__all__ = ["BakeResult", "bake_actions", "fast_path_blocker"]

FCURVES, FRAME_SET = "fcurves", "frame_set"


@dataclass(frozen=True, eq=False)
class BakeResult:
    """Baked clips of one armature.

    skeleton : the armature's core skeleton (bone order of every clip).
    clips : one :class:`Clip` per action, in the order given.
    methods : clip name -> ``"fcurves"`` or ``"frame_set"``.
    notes : :class:`~crowd_addon.core.bake.bake_report.Note` strings: why actions were
        sampled with frame_set and resampling remarks (information), and poses
        between keys that miss the action's (warnings, with the samples per frame
        that would follow it).
    """

    skeleton: Skeleton
    clips: tuple
    methods: dict
    notes: tuple


def fast_path_blocker(armature_obj) -> str | None:
    """Why the armature's pose is more than its F-curves (so only frame_set is
    exact), or None."""
    for pb in armature_obj.pose.bones:
        constraints = pb.constraints
        if len(constraints):
            active = [c.name for c in constraints if not c.mute]
            if active:
                return f"bone {pb.name!r} has constraints {active}"
    ad = armature_obj.animation_data
    if ad is not None:
        driven = [d.data_path for d in ad.drivers if d.data_path.startswith("pose.")]
        if driven:
            return f"drivers animate {driven[0]!r}"
    bones = armature_obj.data.bones
    if len(bones) == 0:
        return None
    flags = {}                          # read for all bones at once, checked where odd
    for prop, dtype in (("inherit_scale", np.int32), ("use_inherit_rotation", bool),
                        ("use_local_location", bool), ("use_relative_parent", bool)):
        flags[prop] = np.empty(len(bones), dtype)
        bones.foreach_get(prop, flags[prop])
    full = bones[0].bl_rna.properties["inherit_scale"].enum_items["FULL"].value
    unusual = ((flags["inherit_scale"] != full) | ~flags["use_inherit_rotation"]
               | ~flags["use_local_location"] | flags["use_relative_parent"])
    for i in np.flatnonzero(unusual).tolist():        # in bone order, as before
        b = bones[i]
        if b.parent is None:
            continue
        if b.inherit_scale != "FULL":
            return f"bone {b.name!r} inherits scale {b.inherit_scale!r}"
        if not b.use_inherit_rotation:
            return f"bone {b.name!r} does not inherit rotation"
        if not b.use_local_location or b.use_relative_parent:
            return f"bone {b.name!r} uses parent-space location or relative parenting"
    return None


def bake_actions(armature_obj, actions, fps: float, progress=None, *, loop=None,
                 scene=None, skeleton: Skeleton | None = None,
                 method: str = "auto", samples_per_frame: int = 1) -> BakeResult | None:
    """Bake ``actions`` as played by ``armature_obj`` into clips for a crowd at ``fps``.

    Parameters
    ----------
    actions : iterable of ``bpy.types.Action`` or ``(action, slot)`` pairs (slot: an
        ``ActionSlot`` or its identifier; default :func:`.action_data.resolve_slot`).
    fps : crowd frames per second.
    samples_per_frame : keys per crowd frame, 1..16: the clips are keyed at ``fps *
        samples_per_frame`` (one key per ``scene_fps / (fps * samples_per_frame)``
        Blender frames) and play at the same speed, with in-between poses from the
        action itself.
    progress : optional ``progress(done, total)`` in sampled keys; returning False
        cancels: the result is None and nothing changed.
    loop : None (from each action), a bool, or a dict action name -> bool.
    scene : the scene whose fps (and, for frame_set, evaluation) is used; default
        ``bpy.context.scene``.
    skeleton : bake for this skeleton (must match the armature) instead of a new one.
    method : ``"auto"`` (F-curves where exact, else frame_set) or ``"frame_set"``.
    """
    import bpy

    if method not in ("auto", FRAME_SET):
        raise CrowdError(f"bake method must be 'auto' or 'frame_set', got {method!r}")
    if not (np.isfinite(fps) and fps > 0):
        raise CrowdError(f"bake fps must be positive, got {fps}")
    if isinstance(samples_per_frame, bool) \
            or not isinstance(samples_per_frame, (int, np.integer)) \
            or not 1 <= samples_per_frame <= MAX_SAMPLES_PER_FRAME:
        raise CrowdError(f"bake samples per frame must be a whole number in "
                         f"1..{MAX_SAMPLES_PER_FRAME}, got {samples_per_frame!r}")
    samples = int(samples_per_frame)
    key_fps = fps * samples
    scene = scene or bpy.context.scene
    skeleton, bone_order, rest, rest_rot = skeleton_and_rest(armature_obj, skeleton)
    scene_fps = scene.render.fps / scene.render.fps_base
    pairs = [a if isinstance(a, tuple) else (a, None) for a in actions]
    if not pairs:
        raise CrowdError("no actions given to bake")
    for action, _ in pairs:
        if not isinstance(action, bpy.types.Action):
            raise CrowdError(f"cannot bake {action!r}: not an action")
        try:
            action.name
        except ReferenceError:
            raise CrowdError("an action to bake no longer exists (it was deleted)") from None
    repeated = {a.name for a, _ in pairs if sum(b == a for b, _ in pairs) > 1}
    sources = []
    for action, slot in pairs:
        want = loop.get(getattr(action, "name", None)) if isinstance(loop, dict) else loop
        src = read_action(armature_obj, skeleton, action, key_fps, scene_fps, slot, want)
        if src.name in repeated and src.slot is not None:
            src.name = f"{src.name}[{src.slot.identifier}]"
        sources.append(src)
    rig_reason = fast_path_blocker(armature_obj) if method == "auto" else None
    total = sum(len(s.times) for s in sources)
    done = 0
    clips, methods, notes = [], {}, []
    rig = _rig_state(armature_obj, skeleton, bone_order, rest, rest_rot)
    unit_scale = _unit_scale(armature_obj)
    with _Playback(scene, armature_obj, skeleton) as playback:
        for src in sources:
            reason = "requested" if method == FRAME_SET else rig_reason or src.frame_set_reason
            if reason is None:
                # the curves read for any time (the usual hand-keyed case): the halfway
                # poses of the between-frame check come from the same evaluation
                halves = (0.5 * (src.times[:-1] + src.times[1:])
                          if src.between is None else src.times[:0])
                both = local_sqt(rig, src.keys, src.columns, src.bones,
                                 np.concatenate([src.times, halves]), src.fast,
                                 _evaluator(src))
                keys = both[:len(src.times)]
                methods[src.name] = FCURVES
                done += len(src.times)
                if progress is not None and progress(done, total) is False:
                    return None
                missed = _interpolation_note(src, keys, rig, skeleton, samples, unit_scale,
                                             both[len(src.times):] if len(halves) else None)
            else:
                missed = None               # the curves alone are not the pose here
                keys = playback.bake(src, lambda k: progress is None or progress(
                    done + k + 1, total) is not False)
                if keys is None:
                    return None
                done += len(src.times)
                methods[src.name] = FRAME_SET
                if method != FRAME_SET:
                    notes.append(Note(f"action {src.name!r} sampled with frame_set: "
                                      f"{reason}", "frame_set", INFO))
            notes.extend(Note(n, "sampling", INFO) for n in src.notes)
            if missed is not None:
                notes.append(Note(missed, "between_frames", WARNING))
            clips.append(Clip(src.name, keys, fps=key_fps, loop=src.loop, events=src.events,
                              bone_names=skeleton.bone_names))
    return BakeResult(skeleton, tuple(clips), methods, tuple(notes))


def _unit_scale(armature_obj) -> float:
    """Scene units per armature unit: the armature object's world scale (the cube root
    of its matrix's determinant)."""
    m = np.array(armature_obj.matrix_world, np.float64)[:3, :3]
    return float(abs(np.linalg.det(m)) ** (1.0 / 3.0)) or 1.0


def _interpolation_note(src, keys, rig, skeleton, samples, unit_scale=1.0, halfway=None):
    """The report line when the crowd's poses between the keys of ``src`` miss its
    curves (evaluated halfway between the keys, unless given as ``halfway``), else
    None."""
    try:
        curves, fast = (src.keys, src.fast) if src.between is None else src.between()
    except CrowdError as e:         # e.g. a NaN handle, unused when sampling on the keys
        return f"action {src.name!r}: the interpolation between keys was not checked: {e}"

    def evaluate(times):        # component-major: the check reads a component at a time
        return local_sqt(rig, curves, src.columns, src.bones, times, fast, _evaluator(src),
                         component_major=True)
    return between_keys_note(src.name, src.times, keys, evaluate, skeleton, samples,
                             unit_scale, halfway=halfway)


def _rig_state(armature_obj, skeleton, bone_order, rest, rest_rot) -> RigChannels:
    """What every action's F-curve bake needs of the armature, in skeleton order: the
    current pose channels (unanimated channels keep them), rotation modes, connected
    bones and the rest pose.

    ``bone_order``: Blender index of each skeleton bone; ``rest``, ``rest_rot``: the
    rest pose and its rotations (:func:`.armature.skeleton_and_rest`)."""
    pbs = armature_obj.pose.bones
    position = {n: i for i, n in enumerate(pbs.keys())}
    lacking = [n for n in skeleton.bone_names if n not in position]
    if lacking:
        raise CrowdError(f"armature {armature_obj.name!r} has no pose for bones {lacking}")
    order = [position[n] for n in skeleton.bone_names]
    defaults = np.empty((len(pbs), CHANNEL_WIDTH), np.float32)
    for prop, (col, width) in CHANNELS.items():
        buf = np.empty(len(pbs) * width, np.float32)
        pbs.foreach_get(prop, buf)
        defaults[:, col:col + width] = buf.reshape(-1, width)
    mode = np.empty(len(pbs), np.int32)
    pbs.foreach_get("rotation_mode", mode)
    mode_name = {e.value: e.identifier
                 for e in pbs[0].bl_rna.properties["rotation_mode"].enum_items}
    bones = armature_obj.data.bones
    connect = np.empty(len(bones), bool)
    bones.foreach_get("use_connect", connect)
    return RigChannels(defaults[order], tuple(mode_name[m] for m in mode[order].tolist()),
                       connect[bone_order], rest, rest_rot)


def _evaluator(src):
    """``evaluate(c, times)``: Blender's own evaluation of curve ``c`` of ``src``, for
    the curves the numpy evaluator does not reproduce."""
    def evaluate(c, times):
        fc = src.fcurves[c]
        return [fc.evaluate(float(t)) for t in times]
    return evaluate


class _Playback:
    """Plays actions on the armature with ``scene.frame_set`` and restores the scene
    (frame, action and slot, NLA switch, rest/pose position, pose values) on exit."""

    def __init__(self, scene, armature_obj, skeleton):
        self.scene, self.obj, self.skeleton = scene, armature_obj, skeleton
        self.saved = None

    def __enter__(self):
        return self

    def _save(self):
        obj, pbs = self.obj, self.obj.pose.bones
        if self.scene.objects.get(obj.name) != obj:
            raise CrowdError(f"armature {obj.name!r} is not in scene {self.scene.name!r}; "
                             "it cannot be sampled there")
        ad = obj.animation_data
        if ad is not None and ad.use_tweak_mode:
            raise CrowdError(f"armature {obj.name!r} is in NLA tweak mode; leave it to bake")
        pose = {}
        for prop, (_, width) in CHANNELS.items():
            buf = np.empty(len(pbs) * width, np.float32)
            pbs.foreach_get(prop, buf)
            pose[prop] = buf
        self.saved = dict(
            frame=self.scene.frame_current, subframe=self.scene.frame_subframe,
            had_ad=ad is not None, action=ad.action if ad else None,
            slot=assigned_slot(ad) if ad else None,
            use_nla=ad.use_nla if ad else True, pose=pose,
            pose_position=obj.data.pose_position)

    def bake(self, src, on_frame):
        """Local SQT keys ``(F, B, 10)`` float64 of ``src`` sampled with frame_set, or None when
        ``on_frame(k)`` returns False."""
        if self.saved is None:
            self._save()
        obj = self.obj
        ad = obj.animation_data or obj.animation_data_create()
        ad.use_nla = False
        play(ad, src.action, src.slot)
        obj.data.pose_position = "POSE"
        pbs = obj.pose.bones
        order = [pbs.find(n) for n in self.skeleton.bone_names]
        model = np.empty((len(src.times), len(order), 4, 4))
        for k, t in enumerate(src.times):
            whole = int(np.floor(t))
            self.scene.frame_set(whole, subframe=float(t - whole))
            model[k] = matrices(pbs, "matrix")[order]
            if not on_frame(k):
                return None
        local = relative_to_parent(model, self.skeleton.parents.astype(np.int64))
        return sqt_from_matrices(local, self.skeleton.bone_names, f"action {src.name!r}",
                                 frame_labels=src.times)

    def __exit__(self, *exc):
        s = self.saved
        if s is None:
            return False
        obj = self.obj
        ad = obj.animation_data
        play(ad, s["action"], s["slot"] if s["action"] is not None else None)
        ad.use_nla = s["use_nla"]
        if not s["had_ad"]:
            obj.animation_data_clear()
        obj.data.pose_position = s["pose_position"]
        # back to the frame first: frame_set plays the action over the pose, so the pose
        # values (a posing not keyed yet) are put back after it, as they were
        self.scene.frame_set(s["frame"], subframe=s["subframe"])
        for prop, buf in s["pose"].items():
            obj.pose.bones.foreach_set(prop, buf)
        obj.update_tag()
        # and evaluated, so the bones' matrices show that pose (as frame_set left them)
        import bpy
        layer = bpy.context.view_layer
        (layer if bpy.context.scene == self.scene else self.scene.view_layers[0]).update()
        return False
