"""The Show panels (3D view > sidebar > Crowd > Show): cues, reactions, parameters.

Each list has add, remove and move buttons (the crowd list operators). A cue's row
shows its frame, what it does and, while the preview runs, how many agents it selects
(from the running crowd: selections are resolved when the crowd is built).
"""

import bpy

from . import crowd_script, preview
from .panels import _list, _Panel

__all__ = ["CLASSES"]


def _counts(context) -> dict:
    pv = preview.get(context.scene)
    runner = getattr(pv.crowd, "show", None) if pv is not None else None
    return {} if runner is None else {d["name"]: d for d in runner.describe()}


def _cost(d) -> str:
    """What a cue costs: its agents, and how many of them need a transition slot."""
    if not d["switched"]:
        return f" ({d['agents']:,})"
    return f" ({d['agents']:,}: {d['slots']:,} by slot)"


class CROWD_UL_cues(bpy.types.UIList):
    def draw_item(self, context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "mute", text="", emboss=False,
                 icon="HIDE_ON" if item.mute else "HIDE_OFF")
        row.prop(item, "name", text="", emboss=False)
        row.label(text=str(item.frame) if item.timeline else "reaction")
        d = _counts(context).get(item.name)
        row.label(text=f"{item.action.title()} {item.target}"
                  + ("" if d is None or item.action in ("TRIGGER", "PARAMETER")
                     else _cost(d)))


class CROWD_UL_reactions(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "mute", text="", emboss=False,
                 icon="HIDE_ON" if item.mute else "HIDE_OFF")
        row.prop(item, "name", text="", emboss=False)
        row.label(text=f"{item.event or '?'} -> {item.cue or '?'}")


class CROWD_UL_look_targets(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False)
        row.label(text=item.object.name if item.object is not None else "?",
                  icon="OBJECT_DATA")


class CROWD_UL_parameters(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=f"{item.target or '?'}")
        row.prop(item, "name", text="", emboss=False)
        row.prop(item, "value", text="")


class CROWD_OT_trust_script(bpy.types.Operator):
    """Let this scene's crowd script run in this file until Blender quits (not saved):
    only this text of this file as it reads now; another file, or the text edited, asks
    again. Rebuilds the preview so the script runs"""

    bl_idname = "crowd.trust_script"
    bl_label = "Trust Script"

    def execute(self, context):
        text = context.scene.crowd.show.script
        if text is None:
            self.report({"ERROR"}, "the scene has no crowd script (Crowd > Show > Script)")
            return {"CANCELLED"}
        crowd_script.trust_script(text)
        if preview.get(context.scene) is not None:
            try:
                preview.start(context.scene)
            except Exception as e:  # noqa: BLE001 - reported, never raised in the UI
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
        return {"FINISHED"}


class CROWD_PT_show(_Panel, bpy.types.Panel):
    bl_label = "Show"
    bl_parent_id = "CROWD_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        show = context.scene.crowd.show
        layout = self.layout
        layout.label(text="Cues")
        _list(layout, "CROWD_UL_cues", show, "cues", "active_cue_index", rows=4)
        if 0 <= show.active_cue_index < len(show.cues):
            _draw_cue(layout, context.scene, show.cues[show.active_cue_index])
        layout.separator()
        layout.label(text="Reactions")
        _list(layout, "CROWD_UL_reactions", show, "reactions", "active_reaction_index")
        if 0 <= show.active_reaction_index < len(show.reactions):
            r = show.reactions[show.active_reaction_index]
            col = layout.column()
            col.use_property_split = True
            col.prop(r, "event")
            col.prop(r, "source")
            col.prop_search(r, "cue", show, "cues")
            col.prop(r, "radius")
        layout.separator()
        layout.label(text="Look Targets (what Look At cues turn heads toward)")
        _list(layout, "CROWD_UL_look_targets", show, "look_targets",
              "active_look_target_index", rows=2)
        col = layout.column()
        col.use_property_split = True
        if 0 <= show.active_look_target_index < len(show.look_targets):
            t = show.look_targets[show.active_look_target_index]
            col.prop(t, "object")
            col.prop(t, "smoothing")
        col.prop(show, "look_lag")
        if show.look_lag == "SEEDED":
            col.prop(show, "look_max_lag")
        layout.separator()
        layout.label(text="Animated Parameters")
        _list(layout, "CROWD_UL_parameters", show, "parameters", "active_parameter_index")
        if 0 <= show.active_parameter_index < len(show.parameters):
            p = show.parameters[show.active_parameter_index]
            col = layout.column()
            col.use_property_split = True
            col.prop(p, "target")
            col.prop(p, "kind")
            col.prop(p, "value")
        layout.separator()
        layout.prop(show, "script")
        pv = preview.get(context.scene)
        if pv is not None and pv.script_note:
            box = layout.box()
            box.label(text=pv.script_note, icon="ERROR")
            box.operator("crowd.trust_script", icon="CHECKMARK")


def _draw_cue(layout, scene, c):
    col = layout.column()
    col.use_property_split = True
    col.prop(c, "timeline")
    if c.timeline:
        col.prop(c, "frame")
    col.prop(c, "action")
    if c.action == "LOOK":
        col.prop_search(c, "target", scene.crowd.show, "look_targets")
        col.prop(c, "duration")
        col.prop(c, "hold")
    else:
        col.prop(c, "target")
    if c.action in ("TRIGGER", "PARAMETER"):
        col.prop(c, "parameter")
        if c.action == "PARAMETER":
            col.prop(c, "set_value")
        return
    if c.action != "LOOK":          # a look is a layer: no slots, offsets or triggers
        _draw_move(col, c)
    box = layout.box().column()
    box.use_property_split = True
    box.prop_search(c, "source", scene.crowd, "agent_sources")
    box.prop(c, "select")
    for key in {"ATTRIBUTE": ("attribute", "op", "compare"), "GROUP": ("vertex_group",),
                "INSIDE": ("bounds",)}.get(c.select, ()):
        box.prop(c, key)
    box.prop(c, "fraction")
    box.prop(c, "seed")
    box = layout.box().column()
    box.use_property_split = True
    box.prop(c, "timing")
    if c.timing == "SPREAD":
        box.prop(c, "spread")
    elif c.timing == "SWEEP":
        for key in ("sweep_mode", "sweep_centre", "sweep_speed", "sweep_start", "sweep_laps"):
            box.prop(c, key)


def _draw_move(col, c):
    """A stream or unique cue's blend, offset, slots, hold and switch trigger."""
    col.prop(c, "duration")
    if c.action == "STREAM":
        col.prop(c, "offset_mode")
        if c.offset_mode == "GIVEN":
            col.prop(c, "offset")
    col.prop(c, "when_full")
    col.prop(c, "hold")
    col.prop(c, "interrupt")
    col.prop(c, "switch_trigger")
    if c.switch_trigger:
        col.prop(c, "release_trigger")
        d = _counts(bpy.context).get(c.name)
        if d is not None:
            col.label(text=f"{d['switched']:,} agents follow {d['streams']} streams, "
                           f"{d['slots']:,} by slot", icon="INFO")


CLASSES = (CROWD_UL_cues, CROWD_UL_reactions, CROWD_UL_look_targets, CROWD_UL_parameters,
           CROWD_OT_trust_script, CROWD_PT_show)
