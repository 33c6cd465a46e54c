"""Operators that edit the Crowd settings' lists: add, remove and move an item.

One operator of each kind serves every list (``collection``: the characters, their
LODs, streams, uniques, nodes and their inputs and transitions, the agent sources,
the show's cues, reactions, parameters and look targets, the palettes, mesh variants
and props); the list's owner is the settings, the active character or its active
stream or unique (``pool``) or that animation's active node. A new item gets a name
of its own and what the selection suggests (the active object as a character's
armature or body, as an agent source, a mesh variant, a prop or a look target). Bad
input is reported as an ERROR naming what is at fault, and nothing changes.
"""

import bpy
from bpy.props import EnumProperty, IntProperty

from ..core.base.errors import CrowdError
from .props import NODE_KINDS

__all__ = ["CLASSES"]


def _all_animations(settings):
    """Every stream and unique of every character (their names share one space)."""
    return [a for c in settings.characters for pool in (c.streams, c.uniques) for a in pool]


def _unique_name(existing, base):
    names = {item.name for item in existing}
    if base not in names:
        return base
    i = 1
    while f"{base}.{i:03d}" in names:
        i += 1
    return f"{base}.{i:03d}"


_COLLECTIONS = (
    ("characters", "Characters", ""), ("lods", "LODs", ""), ("streams", "Streams", ""),
    ("uniques", "Uniques", ""), ("nodes", "Nodes", ""), ("inputs", "Inputs", ""),
    ("transitions", "Transitions", ""), ("agent_sources", "Agent Sources", ""),
    ("cues", "Cues", ""), ("reactions", "Reactions", ""), ("parameters", "Parameters", ""),
    ("palettes", "Palettes", ""), ("variants", "Mesh Variants", ""), ("props", "Props", ""),
    ("look_targets", "Look Targets", ""),
)
_INDEX = {"characters": "active_character_index", "lods": "active_lod_index",
          "streams": "active_stream_index", "uniques": "active_unique_index",
          "nodes": "active_node_index", "inputs": "active_input_index",
          "transitions": "active_transition_index", "agent_sources": "active_source_index",
          "cues": "active_cue_index", "reactions": "active_reaction_index",
          "parameters": "active_parameter_index", "palettes": "active_palette_index",
          "variants": "active_variant_index", "props": "active_prop_index",
          "look_targets": "active_look_target_index"}
#: lists held by ``scene.crowd`` (or a struct of it): collection -> its owner
_SETTINGS_LISTS = {"characters": lambda s: s, "agent_sources": lambda s: s,
                   "cues": lambda s: s.show, "reactions": lambda s: s.show,
                   "parameters": lambda s: s.show, "look_targets": lambda s: s.show}
#: lists held by the active character
_CHARACTER_LISTS = ("lods", "streams", "uniques", "palettes", "variants", "props")


def _active(items, index, what):
    if not 0 <= index < len(items):
        raise CrowdError(f"no active {what}")
    return items[index]


def _owner(settings, collection, pool):
    """The struct holding ``collection``: the settings, the active character, its
    active stream/unique (pool ``STREAMS``/``UNIQUES``) or that animation's active
    node."""
    if collection in _SETTINGS_LISTS:
        return _SETTINGS_LISTS[collection](settings)
    char = _active(settings.characters, settings.active_character_index, "character")
    if collection in _CHARACTER_LISTS:
        return char
    noun = pool.lower()[:-1]
    anims = char.streams if pool == "STREAMS" else char.uniques
    index = char.active_stream_index if pool == "STREAMS" else char.active_unique_index
    anim = _active(anims, index, f"{noun} of character {char.name!r}")
    if collection == "nodes":
        return anim
    if not 0 <= anim.active_node_index < len(anim.nodes):
        raise CrowdError(f"{noun} {anim.name!r} has no active node")
    return anim.nodes[anim.active_node_index]


def _armature_of(obj):
    """The armature deforming mesh ``obj`` (its first Armature modifier's), or None."""
    for mod in obj.modifiers:
        if mod.type == "ARMATURE" and mod.object is not None:
            return mod.object
    return None


def _new_character(item, obj):
    """A new character from the active object: an armature, or a mesh skinned to one
    (then the body)."""
    if obj is None:
        return
    if obj.type == "ARMATURE":
        item.armature = obj
    elif obj.type == "MESH":
        item.body = obj
        item.armature = _armature_of(obj)


class _ListOperator:
    collection: EnumProperty(items=_COLLECTIONS)
    pool: EnumProperty(items=(("STREAMS", "Streams", ""), ("UNIQUES", "Uniques", "")))

    def _target(self, context):
        """``(owner, items, index property)``, or None after reporting why not."""
        try:
            owner = _owner(context.scene.crowd, self.collection, self.pool)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return None
        return owner, getattr(owner, self.collection), _INDEX[self.collection]


class CROWD_OT_item_add(_ListOperator, bpy.types.Operator):
    """Add an item to a crowd list"""

    bl_idname = "crowd.item_add"
    bl_label = "Add"
    bl_options = {"REGISTER", "UNDO"}

    kind: EnumProperty(name="Kind", items=NODE_KINDS, default="CLIP")

    def execute(self, context):
        target = self._target(context)
        if target is None:
            return {"CANCELLED"}
        owner, items, index = target
        s = context.scene.crowd
        item = items.add()
        if self.collection == "characters":
            item.name = _unique_name(items, "Character")
            _new_character(item, context.active_object)
        elif self.collection == "lods":
            item.name = f"LOD {len(items)}"
        elif self.collection in ("streams", "uniques"):
            item.name = _unique_name(_all_animations(s), "Stream"
                                     if self.collection == "streams" else "Unique")
            node = item.nodes.add()
            node.name = "Action"
            arm = owner.armature
            ad = arm.animation_data if arm is not None else None
            node.action = ad.action if ad is not None else None
        elif self.collection == "nodes":
            item.kind = self.kind
            item.name = _unique_name(items, self.kind.title().replace("_", " "))
        elif self.collection == "inputs":
            item.name = _unique_name(items, "State" if owner.kind == "STATE_MACHINE"
                                     else "Input")
        elif self.collection == "agent_sources":
            item.name = _unique_name(items, "Agents")
            obj = context.active_object
            rigs = {c.armature for c in s.characters}
            item.object = obj if obj is not None and obj not in rigs else None
        elif self.collection in ("variants", "props"):
            item.name = _unique_name(items, self.collection[:-1].title())
            obj = context.active_object         # the selected mesh, when not the body
            if obj is not None and obj.type == "MESH" and obj != owner.body:
                item.object = obj
        elif self.collection == "look_targets":    # the selected object, by its name
            obj = context.active_object
            item.name = _unique_name(items, obj.name if obj is not None else "Target")
            item.object = obj
        elif self.collection in ("cues", "reactions", "parameters"):
            item.name = _unique_name(items, self.collection[:-1].title())
            if self.collection == "cues":       # a cue starts after the first frame
                item.frame = max(context.scene.frame_current, context.scene.frame_start + 1)
        setattr(owner, index, len(items) - 1)
        return {"FINISHED"}


class CROWD_OT_item_remove(_ListOperator, bpy.types.Operator):
    """Remove the active item of a crowd list"""

    bl_idname = "crowd.item_remove"
    bl_label = "Remove"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        target = self._target(context)
        if target is None:
            return {"CANCELLED"}
        owner, items, index = target
        i = getattr(owner, index)
        if not 0 <= i < len(items):
            self.report({"ERROR"}, f"nothing selected in {self.collection}")
            return {"CANCELLED"}
        items.remove(i)
        setattr(owner, index, min(i, len(items) - 1) if len(items) else 0)
        return {"FINISHED"}


class CROWD_OT_item_move(_ListOperator, bpy.types.Operator):
    """Move the active item of a crowd list up or down"""

    bl_idname = "crowd.item_move"
    bl_label = "Move"
    bl_options = {"REGISTER", "UNDO"}

    step: IntProperty(default=-1)

    def execute(self, context):
        target = self._target(context)
        if target is None:
            return {"CANCELLED"}
        owner, items, index = target
        i = getattr(owner, index)
        j = i + self.step
        if not (0 <= i < len(items) and 0 <= j < len(items)):
            return {"CANCELLED"}
        items.move(i, j)
        setattr(owner, index, j)
        return {"FINISHED"}


CLASSES = (CROWD_OT_item_add, CROWD_OT_item_remove, CROWD_OT_item_move)
