"""Blender fixtures: one ``bpy`` per test session, a fresh empty scene per test, and
builders for armatures, slotted actions and F-curves made procedurally.

The oracle everywhere is Blender itself: ``pose.bones[].matrix`` after
``scene.frame_set`` and the depsgraph-evaluated mesh of an Armature modifier.
"""

from types import SimpleNamespace

import numpy as np
import pytest

try:
    import bpy
except ImportError:                 # tests here that need no Blender still run
    bpy = None

# (name, head, tail, roll, parent, connected): rolled bones, a connected chain,
# rest orientations far from the axes, and a second branch
RIG = [
    ("root", (0.0, 0.0, 0.0), (0.0, 0.5, 0.2), 0.3, None, False),
    ("spine", (0.0, 0.5, 0.2), (0.1, 0.9, 1.0), -0.7, "root", True),
    ("arm.L", (0.3, 0.8, 1.0), (0.9, 0.6, 1.2), 1.1, "spine", False),
    ("hand.L", (0.9, 0.6, 1.2), (1.2, 0.5, 1.0), 2.0, "arm.L", True),
    ("leg", (0.1, 0.0, 0.0), (0.2, -0.3, -0.8), 0.0, "root", False),
    ("foot", (0.25, -0.35, -0.85), (0.3, -0.1, -0.9), -2.5, "leg", False),
]


def build_rig(scene, spec=RIG, name="Rig", location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)):
    """An armature object linked to ``scene`` with bones from ``spec``."""
    data = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, data)
    obj.location, obj.rotation_euler = location, rotation
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    for bone, head, tail, roll, _, _ in spec:
        eb = data.edit_bones.new(bone)
        eb.head, eb.tail, eb.roll = head, tail, roll
    for bone, _, _, _, parent, connect in spec:          # children may come first
        if parent:
            data.edit_bones[bone].parent = data.edit_bones[parent]
            data.edit_bones[bone].use_connect = connect
    bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def new_action(name, slot_name="Rig"):
    """An action for F-curves on this Blender: ``(action, slot, owner)`` (a slotted
    action's object slot and channelbag; on 4.2-4.3 ``(action, None, action)``)."""
    from crowd_addon.blender.compat import new_action as make
    return make(name, slot_name)


def add_curve(bag, path, index, frames, values, ipo="BEZIER", handles=None):
    """An F-curve with keys at ``frames``; ``handles`` = ((dx_l, dy_l), (dx_r, dy_r))
    makes every key's handles free at those offsets."""
    fc = bag.fcurves.new(path, index=index)
    kp = fc.keyframe_points
    kp.add(len(frames))
    kp.foreach_set("co", np.stack([frames, values], 1).astype(np.float32).ravel())
    for k in kp:
        k.interpolation = ipo
    fc.update()
    if handles is not None:
        (lx, ly), (rx, ry) = handles
        for k in kp:
            k.handle_left_type = k.handle_right_type = "FREE"
            k.handle_left = (k.co[0] + lx, k.co[1] + ly)
            k.handle_right = (k.co[0] + rx, k.co[1] + ry)
    return fc


def play(obj, action, slot):
    from crowd_addon.blender import compat
    compat.play(obj.animation_data or obj.animation_data_create(), action, slot)


def pose_at(scene, obj, names, frame):
    """Blender's ``pose.bones[name].matrix`` (B, 4, 4) float64 at a (sub)frame."""
    whole = int(np.floor(frame))
    scene.frame_set(whole, subframe=float(frame - whole))
    return np.array([np.array(obj.pose.bones[n].matrix) for n in names])


def rig_action(obj, name="Wave", seed=0, frames=(1, 5, 9, 14, 20)):
    """An action on :data:`RIG` using every channel kind: quaternion (Bezier, with
    long free handles on one channel), Euler YZX (linear), axis-angle (Bezier),
    location (Bezier; also on a connected bone, which Blender ignores), scale
    (constant)."""
    rng = np.random.default_rng(seed)
    fr = np.array(frames, float)
    action, slot, bag = new_action(name)
    obj.pose.bones["arm.L"].rotation_mode = "YZX"
    obj.pose.bones["leg"].rotation_mode = "AXIS_ANGLE"
    obj.pose.bones["foot"].rotation_mode = "ZXY"
    for bone in ("root", "spine", "hand.L"):
        for i in range(4):
            add_curve(bag, f'pose.bones["{bone}"].rotation_quaternion', i, fr,
                      rng.normal(size=fr.size) * 0.4 + (i == 0))
    for i in range(3):
        add_curve(bag, 'pose.bones["arm.L"].rotation_euler', i, fr, rng.normal(size=fr.size),
                  "LINEAR")
        add_curve(bag, 'pose.bones["foot"].rotation_euler', i, fr, rng.normal(size=fr.size))
        add_curve(bag, 'pose.bones["root"].location', i, fr, rng.normal(size=fr.size) * 0.3,
                  handles=((-3.5, 1.0), (4.5, -0.5)) if i == 1 else None)
        add_curve(bag, 'pose.bones["spine"].location', i, fr, rng.normal(size=fr.size) * 0.3)
        add_curve(bag, 'pose.bones["hand.L"].scale', i, fr, 1 + rng.normal(size=fr.size) * 0.2,
                  "CONSTANT")
        add_curve(bag, 'pose.bones["leg"].scale', i, fr, 1 + rng.normal(size=fr.size) * 0.3)
    for i in range(4):
        add_curve(bag, 'pose.bones["leg"].rotation_axis_angle', i, fr, rng.normal(size=fr.size))
    play(obj, action, slot)
    return action, slot, bag


@pytest.fixture
def scene():
    if bpy is None:
        pytest.skip("needs the bpy module")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


@pytest.fixture
def blend():
    """The builders above, for tests (test modules cannot import this conftest)."""
    if bpy is None:
        pytest.skip("needs the bpy module")
    return SimpleNamespace(bpy=bpy, build_rig=build_rig, new_action=new_action,
                           add_curve=add_curve, play=play, pose_at=pose_at,
                           rig_action=rig_action, RIG=RIG)
