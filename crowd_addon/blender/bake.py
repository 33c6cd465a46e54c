"""Bake Blender actions into core clips (local SQT keys at the crowd fps).

Two ways, one result:

- **F-curves** (the fast path): every bone F-curve is read in bulk and evaluated in
  numpy at all sample times at once (:mod:`.fcurve_eval`, Blender's own algorithm),
  channels are composed into ``matrix_basis`` per bone as Blender's
  ``BKE_pchan_to_mat4`` does (quaternions normalised, Euler orders, axis-angle,
  connected bones ignore location), then into local SQT with the rest pose.
- **frame_set** (exact by definition, slower): the action is played on the armature,
  ``scene.frame_set`` per key, ``pose.bones[].matrix`` read and made local. Used
  where the fast path cannot be exact: constraints, drivers on the pose, bones that
  do not inherit rotation or full scale, local-location or relative-parent bones,
  animated rotation modes, muted F-curve groups. The result says which actions
  were sampled and why.

Nothing is built until every action has been read and validated; a cancel through
the progress callback returns None and leaves the scene as it was.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import pose as sqt
from ..core.clip import Clip
from ..core.errors import CrowdError
from ..core.skeleton import Skeleton
from . import fcurve_eval
from .action_data import CHANNEL_WIDTH, read_action
from .armature import matrices, relative_to_parent, skeleton_and_rest, sqt_from_matrices

__all__ = ["BakeResult", "bake_actions", "fast_path_blocker"]

FCURVES, FRAME_SET = "fcurves", "frame_set"
_BLOCK_ELEMENTS = 16384       # frames x bones per block of the rotation composition


@dataclass(frozen=True, eq=False)
class BakeResult:
    """Baked clips of one armature.

    skeleton : the armature's core skeleton (bone order of every clip).
    clips : one :class:`Clip` per action, in the order given.
    methods : clip name -> ``"fcurves"`` or ``"frame_set"``.
    notes : why actions were sampled with frame_set, and resampling remarks.
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
                 method: str = "auto") -> BakeResult | None:
    """Bake ``actions`` as played by ``armature_obj`` into clips at ``fps``.

    Parameters
    ----------
    actions : iterable of ``bpy.types.Action`` or ``(action, slot)`` pairs (slot: an
        ``ActionSlot`` or its identifier; default :func:`.action_data.resolve_slot`).
    fps : crowd frames per second; one clip key per ``scene_fps / fps`` Blender frames.
    progress : optional ``progress(done, total)`` in sampled frames; returning False
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
        src = read_action(armature_obj, skeleton, action, fps, scene_fps, slot, want)
        if src.name in repeated and src.slot is not None:
            src.name = f"{src.name}[{src.slot.identifier}]"
        sources.append(src)
    rig_reason = fast_path_blocker(armature_obj) if method == "auto" else None
    total = sum(len(s.times) for s in sources)
    done = 0
    clips, methods, notes = [], {}, []
    rig = _rig_state(armature_obj, skeleton, bone_order, rest, rest_rot)
    with _Playback(scene, armature_obj, skeleton) as playback:
        for src in sources:
            reason = "requested" if method == FRAME_SET else rig_reason or src.frame_set_reason
            if reason is None:
                keys = _bake_fcurves(rig, src)
                methods[src.name] = FCURVES
                done += len(src.times)
                if progress is not None and progress(done, total) is False:
                    return None
            else:
                keys = playback.bake(src, lambda k: progress is None or progress(
                    done + k + 1, total) is not False)
                if keys is None:
                    return None
                done += len(src.times)
                methods[src.name] = FRAME_SET
                if method != FRAME_SET:
                    notes.append(f"action {src.name!r} sampled with frame_set: {reason}")
            notes.extend(src.notes)
            clips.append(Clip(src.name, keys, fps=fps, loop=src.loop, events=src.events,
                              bone_names=skeleton.bone_names))
    return BakeResult(skeleton, tuple(clips), methods, tuple(notes))


def _rig_state(armature_obj, skeleton, bone_order, rest, rest_rot) -> dict:
    """What every action's F-curve bake needs of the armature, in skeleton order:
    current pose channels ``defaults`` (B, 17) float32 (unanimated channels keep
    them), ``modes`` (rotation modes), ``connected`` (B,) bool, and the rest pose
    relative to the parent as quaternions ``q0`` (4, B) and matrices ``r0`` (B, 3, 4).

    ``bone_order``: Blender index of each skeleton bone; ``rest``, ``rest_rot``: the
    rest pose and its rotations (:func:`.armature.skeleton_and_rest`)."""
    pbs = armature_obj.pose.bones
    position = {n: i for i, n in enumerate(pbs.keys())}
    lacking = [n for n in skeleton.bone_names if n not in position]
    if lacking:
        raise CrowdError(f"armature {armature_obj.name!r} has no pose for bones {lacking}")
    order = [position[n] for n in skeleton.bone_names]
    defaults = np.empty((len(pbs), CHANNEL_WIDTH), np.float32)
    for prop, (col, width) in (("location", (0, 3)), ("rotation_quaternion", (3, 4)),
                               ("rotation_euler", (7, 3)), ("rotation_axis_angle", (10, 4)),
                               ("scale", (14, 3))):
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
    return dict(defaults=defaults[order], modes=[mode_name[m] for m in mode[order].tolist()],
                connected=connect[bone_order],
                q0=rest_rot.T.astype(np.float32), r0=rest[:, :3, :].astype(np.float32))


def _bake_fcurves(rig, src):
    """Local SQT keys ``(F, B, 10)`` float32 from the action's F-curves.

    Works component-major (``(17, F, B)`` channels) so that every quaternion product
    is a few whole-array operations, in float32 like Blender's pose evaluation.
    """
    times = src.times.astype(np.float32)
    defaults, modes, r0 = rig["defaults"], rig["modes"], rig["r0"]
    chan = np.empty((CHANNEL_WIDTH, len(times), len(modes)), np.float32)
    cols = _used_columns(modes)
    chan[cols] = defaults[:, cols].T[:, None, :]
    fast = np.flatnonzero(src.fast)
    if fast.size:
        vals = fcurve_eval.evaluate_frames(src.keys, times, fast)         # (F, C)
        chan[src.columns[fast], :, src.bones[fast]] = vals.T
    for c in np.flatnonzero(~src.fast):
        fc = src.fcurves[c]
        chan[src.columns[c], :, src.bones[c]] = [fc.evaluate(float(t)) for t in times]
    loc = chan[0:3]
    loc[:, :, rig["connected"]] = 0                # BKE_pchan_to_mat4: chains stay closed
    keys = np.empty((len(times), len(modes), sqt.WIDTH), np.float32)
    # rotation = rest rotation * basis rotation, a block of frames at a time so that
    # the temporaries stay small (long motion capture clips); the rest rotation is
    # repeated over a block's frames (products of equal shapes run faster than ones
    # broadcasting a (B,) row)
    block = max(1, _BLOCK_ELEMENTS // len(modes))
    rest_rot = np.repeat(rig["q0"][:, None, :], min(block, len(times)), axis=1)
    for f0 in range(0, len(times), block):
        f1 = min(len(times), f0 + block)
        rot = _qmul(rest_rot[:, :f1 - f0], basis_rotation(chan[:, f0:f1], modes))
        for i, comp in enumerate(rot):
            keys[f0:f1, :, 3 + i] = comp
    # translation = rest offset + rest rotation @ location: constant per bone unless
    # the bone's location is animated
    moving = np.zeros(len(modes), bool)
    moving[src.bones[src.columns < 3]] = True
    move, still = np.flatnonzero(moving), np.flatnonzero(~moving)
    const = r0[still, :, 3] + np.einsum("bij,bj->bi", r0[still, :, :3], loc[:, 0, still].T)
    lm = loc[:, :, move]                                                 # (3, F, m)
    for i in range(3):
        keys[..., i] = chan[14 + i]
        keys[:, still, 7 + i] = const[:, i]
        keys[:, move, 7 + i] = r0[move, i, 3] + r0[move, i, 0] * lm[0] \
            + r0[move, i, 1] * lm[1] + r0[move, i, 2] * lm[2]
    return keys


def _used_columns(modes):
    """Channel columns that the bones' rotation modes read (location, scale and the
    rotation channels of the modes in use)."""
    cols = [0, 1, 2, 14, 15, 16]
    present = set(modes)
    if "QUATERNION" in present:
        cols += [3, 4, 5, 6]
    if "AXIS_ANGLE" in present:
        cols += [10, 11, 12, 13]
    if present - {"QUATERNION", "AXIS_ANGLE"}:
        cols += [7, 8, 9]
    return cols


def _qmul(a, b):
    """Hamilton product ``a * b`` of quaternions given as 4 component arrays."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def _eps(i, j, k):
    """Levi-Civita symbol of three distinct axes."""
    return 1 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1


def basis_rotation(chan: np.ndarray, modes) -> np.ndarray:
    """Unit quaternions ``(4, F, B)`` of pose channels ``(17, F, B)`` by rotation mode,
    as ``BKE_pchan_rot_to_mat3``: normalised quaternion (a zero one is Blender's
    ``(0, 1, 0, 0)``), Euler in the bone's axis order (first letter applied first),
    axis-angle with the axis normalised (a zero axis is no rotation)."""
    kinds = set(modes)
    if kinds == {"QUATERNION"}:                    # the usual case: no gathers, no copy
        return _unit_quaternions(chan[3:7])
    q = np.empty((4,) + chan.shape[1:], chan.dtype)
    modes = np.array(modes)
    for mode in kinds:
        sel = np.flatnonzero(modes == mode)
        if sel.size == modes.size:
            sel = slice(None)                      # all bones: views, no gathers
        if mode == "QUATERNION":
            q[:, :, sel] = _unit_quaternions(chan[3:7, :, sel])
        elif mode == "AXIS_ANGLE":
            angle, axis = chan[10][:, sel], chan[11:14, :, sel]
            n = np.sqrt((axis * axis).sum(0))
            half = np.where(n > 0, angle / 2, 0)
            k = np.sin(half) / np.where(n > 0, n, 1)
            q[:, :, sel] = np.stack([np.cos(half), axis[0] * k, axis[1] * k, axis[2] * k])
        else:
            half = chan[7:10, :, sel] * np.float32(0.5)
            c, s = np.cos(half), np.sin(half)
            a, b, k = ("XYZ".index(ch) for ch in mode)       # q = q_k * q_b * q_a
            v = [None] * 3                                   # q_b * q_a
            w = c[b] * c[a]
            v[a], v[b], v[k] = c[b] * s[a], s[b] * c[a], _eps(b, a, k) * s[b] * s[a]
            q[0][:, sel] = c[k] * w - s[k] * v[k]
            q[1 + k][:, sel] = c[k] * v[k] + s[k] * w        # then q_k * (q_b * q_a)
            for i in (a, b):
                j = 3 - i - k
                q[1 + i][:, sel] = c[k] * v[i] + _eps(i, k, j) * s[k] * v[j]
    return q


def _unit_quaternions(raw):
    """``raw`` (4, ...) normalised; a zero quaternion is Blender's ``(0, 1, 0, 0)``.
    (The squares are summed in order, as ``(raw * raw).sum(0)`` would, without the
    (4, ...) temporary.)"""
    n = np.sqrt(raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2] + raw[3] * raw[3])
    if (n > 0).all():
        return raw / n
    unit = raw / np.where(n > 0, n, 1)
    unit[1] = np.where(n > 0, unit[1], 1)
    return unit


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
        for prop, width in (("location", 3), ("rotation_quaternion", 4),
                            ("rotation_euler", 3), ("rotation_axis_angle", 4), ("scale", 3)):
            buf = np.empty(len(pbs) * width, np.float32)
            pbs.foreach_get(prop, buf)
            pose[prop] = buf
        self.saved = dict(
            frame=self.scene.frame_current, subframe=self.scene.frame_subframe,
            had_ad=ad is not None, action=ad.action if ad else None,
            slot=getattr(ad, "action_slot", None) if ad else None,
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
        ad.action = src.action
        if src.slot is not None:
            ad.action_slot = src.slot
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
        ad.action = s["action"]
        if s["action"] is not None and s["slot"] is not None:
            ad.action_slot = s["slot"]
        ad.use_nla = s["use_nla"]
        if not s["had_ad"]:
            obj.animation_data_clear()
        for prop, buf in s["pose"].items():
            obj.pose.bones.foreach_set(prop, buf)
        obj.data.pose_position = s["pose_position"]
        self.scene.frame_set(s["frame"], subframe=s["subframe"])
        return False
