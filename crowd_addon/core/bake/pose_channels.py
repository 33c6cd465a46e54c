"""Blender pose channels -> local SQT keys, in numpy.

A bone's pose channels are the 17 floats of its pose-bone properties (``location``,
``rotation_quaternion``, ``rotation_euler``, ``rotation_axis_angle``, ``scale``) laid
out as :data:`CHANNELS`. :func:`channel_targets` maps F-curve data paths
(``pose.bones["arm.L"].location``) to a skeleton bone and a channel column;
:func:`local_sqt` evaluates an action's curves (:mod:`.fcurve`) into channels and
composes them with the rest pose as Blender's ``BKE_pchan_to_mat4`` does
(quaternions normalised, Euler orders, axis-angle, connected bones ignore location),
in float32 like Blender's pose evaluation. The Blender side reads the arrays
(``crowd_addon.blender.bake``).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

import numpy as np

from . import fcurve
from ..base import pose as sqt
from ..base.quaternion import multiply_parts

__all__ = ["CHANNELS", "CHANNEL_WIDTH", "channel_targets", "RigChannels", "used_columns",
           "basis_rotation", "local_sqt"]

#: column range ``(first, width)`` of each pose-bone property in a bone's channel block
CHANNELS = {"location": (0, 3), "rotation_quaternion": (3, 4), "rotation_euler": (7, 3),
            "rotation_axis_angle": (10, 4), "scale": (14, 3)}
CHANNEL_WIDTH = 17
_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\](.*)$')
# the rest of a pose-bone data path -> (first column, width) of its channel block
_PROPS = {"." + prop: cols for prop, cols in CHANNELS.items()}
_BLOCK_ELEMENTS = 16384       # frames x bones per block of the rotation composition


@functools.lru_cache(maxsize=4096)
def _bone_path(data_path):
    """(bone name, rest of the path) of a ``pose.bones["..."]`` data path, else Nones
    (cached: a rig's actions share their paths)."""
    m = _PATH.match(data_path)
    if m is None:
        return None, None
    name = m.group(1)
    return (re.sub(r"\\(.)", r"\1", name) if "\\" in name else name), m.group(2)


@functools.lru_cache(maxsize=64)
def channel_targets(paths: tuple, bone_names: tuple):
    """What F-curves with data paths ``paths`` animate on a skeleton of ``bone_names``
    (both tuples of str; cached: an action's paths seldom change between bakes).

    Returns read-only arrays per curve: ``bone`` (C,) int64 bone index (-1: not a
    pose-bone path, or a bone the skeleton lacks), ``first_column`` and ``width``
    (C,) int64 of its channel (width 0: not a bone channel), ``rotation_mode`` (C,)
    bool (a ``rotation_mode`` curve); and the names of the bones the skeleton lacks,
    in curve order (a tuple)."""
    index = {n: i for i, n in enumerate(bone_names)}
    bone = np.full(len(paths), -1, np.int64)
    first_column = np.zeros(len(paths), np.int64)
    width = np.zeros(len(paths), np.int64)
    rotation_mode = np.zeros(len(paths), bool)
    missing = []
    for c, path in enumerate(paths):
        name, rest = _bone_path(path)
        if name is None:
            continue
        b = index.get(name)
        if b is None:
            missing.append(name)
            continue
        bone[c] = b
        rotation_mode[c] = rest == ".rotation_mode"
        prop = _PROPS.get(rest)
        if prop is not None:
            first_column[c], width[c] = prop
    for a in (bone, first_column, width, rotation_mode):
        a.flags.writeable = False
    return bone, first_column, width, rotation_mode, tuple(missing)


@dataclass(frozen=True, eq=False)
class RigChannels:
    """What turning an armature's pose channels into local SQT needs, skeleton order.

    defaults : (B, 17) float32 current channel values (channels no curve animates
        keep them).
    modes : B rotation mode names: ``"QUATERNION"``, ``"AXIS_ANGLE"`` or an Euler
        order (``"XYZ"``, ``"YZX"``...).
    connected : (B,) bool, bones connected to their parent (location ignored).
    rest : (B, 4, 4) float64 rest matrices relative to the parent bone.
    rest_rotation : (B, 4) float64 their rotations (w, x, y, z).
    """

    defaults: np.ndarray
    modes: tuple
    connected: np.ndarray
    rest: np.ndarray
    rest_rotation: np.ndarray

    @functools.cached_property
    def _q0(self) -> np.ndarray:                  # (4, B) float32
        return np.ascontiguousarray(self.rest_rotation.T, np.float32)

    @functools.cached_property
    def _r0(self) -> np.ndarray:                  # (B, 3, 4) float32
        return self.rest[:, :3, :].astype(np.float32)


def used_columns(modes) -> list:
    """Channel columns that bones with rotation ``modes`` read (location, scale and
    the rotation channels of the modes in use)."""
    cols = [0, 1, 2, 14, 15, 16]
    present = set(modes)
    if "QUATERNION" in present:
        cols += [3, 4, 5, 6]
    if "AXIS_ANGLE" in present:
        cols += [10, 11, 12, 13]
    if present - {"QUATERNION", "AXIS_ANGLE"}:
        cols += [7, 8, 9]
    return cols


def basis_rotation(chan: np.ndarray, modes) -> np.ndarray:
    """Unit quaternions ``(4, F, B)`` of pose channels ``(17, F, B)`` (float32 or
    float64, kept) by rotation mode, as ``BKE_pchan_rot_to_mat3``: normalised
    quaternion (a zero one is Blender's ``(0, 1, 0, 0)``), Euler in the bone's axis
    order (first letter applied first), axis-angle with the axis normalised (a zero
    axis is no rotation)."""
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
            half = chan[7:10, :, sel] * chan.dtype.type(0.5)
            c, s = np.cos(half), np.sin(half)
            zero = np.zeros_like(c[0])

            def about(i):                          # rotation about axis i
                parts = [c[i], zero, zero, zero]
                parts[1 + i] = s[i]
                return parts

            a, b, k = ("XYZ".index(ch) for ch in mode)       # q = q_k * q_b * q_a
            for i, part in enumerate(multiply_parts(about(k),
                                                    multiply_parts(about(b), about(a)))):
                q[i][:, sel] = part
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


def local_sqt(rig: RigChannels, curves: fcurve.CurveSet, columns, bones, times,
              fast=None, evaluate=None, component_major: bool = False) -> np.ndarray:
    """Local SQT keys ``(F, B, 10)`` float32 of bone F-curves at Blender frames ``times``.

    Parameters
    ----------
    rig : the armature's channels and rest pose (:class:`RigChannels`).
    curves : the curves' packed keys (C curves).
    columns, bones : (C,) int64 channel column (:data:`CHANNELS`) and skeleton bone
        that each curve drives.
    times : (F,) Blender frames, evaluated in float32.
    fast : (C,) bool, curves :func:`.fcurve.evaluate_frames` reproduces (default all).
    evaluate : ``evaluate(c, times)`` -> (F,) values of curve ``c`` where ``fast`` is
        False (Blender's own evaluation); needed only then.
    component_major : return the ``(F, B, 10)`` keys as a view of a ``(10, F, B)``
        array (each SQT component contiguous, as the composition makes them), for
        consumers that work a component at a time (the bake's between-frame check).

    Works component-major (``(17, F, B)`` channels) so that every quaternion product
    is a few whole-array operations.
    """
    times = np.asarray(times).astype(np.float32)
    columns, bones = np.asarray(columns, np.int64), np.asarray(bones, np.int64)
    fast = np.ones(len(columns), bool) if fast is None else np.asarray(fast, bool)
    modes = rig.modes
    chan = np.empty((CHANNEL_WIDTH, len(times), len(modes)), np.float32)
    cols = used_columns(modes)
    chan[cols] = rig.defaults[:, cols].T[:, None, :]
    which = np.flatnonzero(fast)
    if which.size:
        vals = fcurve.evaluate_frames(curves, times, which)             # (F, C)
        chan[columns[which], :, bones[which]] = vals.T
    slow = np.flatnonzero(~fast).tolist()
    if slow and evaluate is None:
        raise ValueError(f"local_sqt: curves {slow} are not fast and no evaluate callback "
                         "was given")
    for c in slow:
        chan[columns[c], :, bones[c]] = evaluate(c, times)
    moving = np.zeros(len(modes), bool)
    moving[bones[columns < 3]] = True
    return _compose(rig, chan, moving, component_major)


def _compose(rig, chan, moving, component_major=False):
    """Local SQT keys ``(F, B, 10)`` float32 of channels ``(17, F, B)``; ``moving``:
    (B,) bool, bones whose location is animated; ``component_major``: the keys are a
    view of a ``(10, F, B)`` array."""
    modes, r0 = rig.modes, rig._r0
    frames = chan.shape[1]
    loc = chan[0:3]
    loc[:, :, rig.connected] = 0               # BKE_pchan_to_mat4: chains stay closed
    if component_major:
        keys = np.empty((sqt.WIDTH, frames, len(modes)), np.float32).transpose(1, 2, 0)
    else:
        keys = np.empty((frames, len(modes), sqt.WIDTH), np.float32)
    # rotation = rest rotation * basis rotation, a block of frames at a time so that
    # the temporaries stay small (long motion capture clips); the rest rotation is
    # repeated over a block's frames (products of equal shapes run faster than ones
    # broadcasting a (B,) row)
    block = max(1, _BLOCK_ELEMENTS // len(modes))
    rest_rot = np.repeat(rig._q0[:, None, :], min(block, frames), axis=1)
    for f0 in range(0, frames, block):
        f1 = min(frames, f0 + block)
        rot = multiply_parts(rest_rot[:, :f1 - f0], basis_rotation(chan[:, f0:f1], modes))
        for i, comp in enumerate(rot):
            keys[f0:f1, :, 3 + i] = comp
    # translation = rest offset + rest rotation @ location: constant per bone unless
    # the bone's location is animated
    move, still = np.flatnonzero(moving), np.flatnonzero(~moving)
    const = r0[still, :, 3] + np.einsum("bij,bj->bi", r0[still, :, :3], loc[:, 0, still].T)
    lm = loc[:, :, move]                                                 # (3, F, m)
    for i in range(3):
        keys[..., i] = chan[14 + i]
        keys[:, still, 7 + i] = const[:, i]
        keys[:, move, 7 + i] = r0[move, i, 3] + r0[move, i, 0] * lm[0] \
            + r0[move, i, 1] * lm[1] + r0[move, i, 2] * lm[2]
    return keys
