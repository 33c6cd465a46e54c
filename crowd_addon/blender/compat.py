"""What differs between the Blender releases the extension supports (4.2 LTS to 5.x),
in one place.

Actions: Blender 4.4 made actions *slotted*: an action has ``slots``, its F-curves
live in a channelbag per slot (``action.layers[0].strips[0].channelbag(slot)``) and an
ID plays a slot (``AnimData.action_slot``). Blender 4.2 and 4.3 have *legacy* actions:
``action.fcurves``, no slots. Everything here takes a slot that is None for a legacy
action, so callers need not know which Blender runs.
"""

from __future__ import annotations

import bpy

__all__ = ["SLOTTED_ACTIONS", "action_slots", "fcurve_owner", "first_fcurves",
           "assigned_slot", "play", "new_action", "fcurve_ensure"]

#: Whether this Blender has slotted actions (4.4+).
SLOTTED_ACTIONS = "slots" in bpy.types.Action.bl_rna.properties
#: Whether ``Action.fcurve_ensure_for_datablock`` takes a group name (5.0+).
_GROUP_NAME = SLOTTED_ACTIONS and "group_name" in [
    p.identifier for p in bpy.types.Action.bl_rna.functions[
        "fcurve_ensure_for_datablock"].parameters]


def action_slots(action):
    """The action's slots, or None for a legacy action (Blender 4.2-4.3)."""
    return getattr(action, "slots", None)


def fcurve_owner(action, slot):
    """What holds the F-curves of ``slot`` (``owner.fcurves``, ``owner.groups``): its
    channelbag, the legacy action itself for ``slot`` None, or None when the slot has
    no channelbag."""
    if slot is None:
        return action
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(slot)
            if bag is not None:
                return bag
    return None


def first_fcurves(action):
    """The F-curves of the action's first slot (all of a legacy action's)."""
    slots = action_slots(action)
    owner = fcurve_owner(action, slots[0] if slots else None)
    return [] if owner is None else owner.fcurves


def assigned_slot(anim_data):
    """The slot ``anim_data`` plays (None on legacy Blender or when none is)."""
    return getattr(anim_data, "action_slot", None)


def play(anim_data, action, slot=None):
    """``anim_data`` plays ``action`` (and ``slot``, on Blender with slots)."""
    anim_data.action = action
    if slot is not None:
        anim_data.action_slot = slot


def fcurve_ensure(action, datablock, path: str, index: int, group: str):
    """The F-curve of ``path[index]`` animating ``datablock`` in ``action`` (made, in
    F-curve group ``group``, when missing). On Blender 4.4+ the action's slot for the
    datablock is made and assigned as needed."""
    if _GROUP_NAME:
        return action.fcurve_ensure_for_datablock(datablock, path, index=index,
                                                  group_name=group)
    if SLOTTED_ACTIONS:                                 # 4.4-4.5: no group name
        return action.fcurve_ensure_for_datablock(datablock, path, index=index)
    found = action.fcurves.find(path, index=index)
    return found if found is not None else action.fcurves.new(path, index=index,
                                                              action_group=group)


def new_action(name: str, slot_name: str = "Rig", id_type: str = "OBJECT"):
    """A new action ready for F-curves: ``(action, slot, owner)`` with one ``id_type``
    slot and its channelbag on Blender 4.4+, ``(action, None, action)`` on 4.2-4.3;
    ``owner.fcurves.new(path, index=i)`` adds curves either way."""
    action = bpy.data.actions.new(name)
    if not SLOTTED_ACTIONS:
        return action, None, action
    slot = action.slots.new(id_type, slot_name)
    layer = action.layers.new("Layer")
    strip = layer.strips.new(type="KEYFRAME")
    return action, slot, strip.channelbag(slot, ensure=True)
