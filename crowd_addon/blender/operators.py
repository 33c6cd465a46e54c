"""Operators: bake (modal, with progress and cancel), agents, preview, list editing.

Every operator reports bad input as an ERROR naming what is at fault
(:class:`CrowdError` messages) and then changes nothing: a bake replaces the running
crowd only once the new one is complete.
"""

import time

import bpy
from bpy.props import EnumProperty, IntProperty

from ..core.base.errors import CrowdError
from . import preview, scene_config
from .agents import agents_from_scene
from .show_data import show_from_scene
from .props import NODE_KINDS

__all__ = ["CLASSES", "BakeJob"]


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


class BakeJob:
    """A scene's crowd built one unit at a time (one action, then the mesh, then the
    agents), for a modal operator. Nothing changes in Blender or in the running
    preview until :attr:`config` is used; :meth:`cancel` just drops the work."""

    def __init__(self, scene):
        self.notes = []                 # the bake's remarks, reported as warnings
        self.steps = scene_config.config_steps(scene, notes=self.notes)
        self.done, self.total, self.message = 0, 1, "starting"
        self.config = None

    def step(self) -> bool:
        """Do the next unit; False once :attr:`config` is complete. Raises CrowdError."""
        with preview.suspended():
            try:
                self.done, self.total, self.message = next(self.steps)
            except StopIteration as stop:
                self.config = stop.value
                return False
        return True

    def cancel(self):
        self.steps.close()


class CROWD_OT_bake(bpy.types.Operator):
    """Bake the crowd's actions into clips, place the agents and start the preview
    (Esc cancels; the previous crowd stays until the new one is complete)"""

    bl_idname = "crowd.bake"
    bl_label = "Bake Crowd"
    bl_options = {"REGISTER"}

    _timer = None
    _job = None

    def execute(self, context):
        wm = context.window_manager
        job = BakeJob(context.scene)
        wm.progress_begin(0, 1000)
        try:
            while job.step():
                wm.progress_update(int(1000 * job.done / job.total))
            return self._finish(context, job.config, job.notes)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        finally:
            wm.progress_end()

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        self._job = BakeJob(context.scene)
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        self._timer = wm.event_timer_add(0.001, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel()
            self._end(context)
            self.report({"WARNING"}, "Bake cancelled: the crowd is unchanged")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        job = self._job
        try:
            more = job.step()
            if not more:
                self._end(context)
                return self._finish(context, job.config, job.notes)
        except CrowdError as e:
            self._end(context)
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        context.window_manager.progress_update(int(1000 * job.done / job.total))
        context.workspace.status_text_set(f"Crowd: {job.message} ({job.done + 1}/"
                                          f"{job.total}), Esc to cancel")
        return {"RUNNING_MODAL"}

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)

    def _finish(self, context, config, notes=()):
        from ..core.bake.bake_report import WARNING, report_of
        pv = preview.start(context.scene, config)
        c = pv.crowd
        for note in report_of(config):  # e.g. poses between frames that miss the action's
            self.report({"WARNING" if note.severity == WARNING else "INFO"}, note)
        self.report({"INFO"}, f"Crowd: {len(config.clips)} clips, {c.streams.count} streams, "
                              f"{c.uniques.count} uniques, {c.agents.count} agents")
        return {"FINISHED"}


class CROWD_OT_generate_agents(bpy.types.Operator):
    """Place the agents from the agent sources (the running crowd gets them without a
    new bake)"""

    bl_idname = "crowd.generate_agents"
    bl_label = "Generate Agents"
    bl_options = {"REGISTER"}

    def execute(self, context):
        scene = context.scene
        t0 = time.perf_counter()
        try:
            dg = context.evaluated_depsgraph_get()
            agents, placed = agents_from_scene(scene, dg)
            pv = preview.get(scene)
            if pv is not None:
                cfg = pv.crowd.config.without_agents()
                agents.add_to(cfg)
                cfg.show = show_from_scene(scene, dg, cfg, placed)   # selections: new ids
                preview.start(scene, cfg)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{agents.count} agents in "
                              f"{(time.perf_counter() - t0) * 1e3:.0f} ms")
        return {"FINISHED"}


class CROWD_OT_preview_toggle(bpy.types.Operator):
    """Start (bake first) or stop the viewport preview"""

    bl_idname = "crowd.preview_toggle"
    bl_label = "Toggle Crowd Preview"
    bl_options = {"REGISTER"}

    def execute(self, context):
        if preview.get(context.scene) is not None:
            preview.stop(context.scene)
            return {"FINISHED"}
        return bpy.ops.crowd.bake("EXEC_DEFAULT")

    def invoke(self, context, event):
        if preview.get(context.scene) is not None:
            return self.execute(context)
        return bpy.ops.crowd.bake("INVOKE_DEFAULT")


class _OnPreview:
    """An operator on the running preview (greyed out without one): :meth:`run`; a
    CrowdError is reported and cancels it."""

    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        return preview.get(context.scene) is not None

    def execute(self, context):
        try:
            self.run(context)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class CROWD_OT_measure_repetition(_OnPreview, bpy.types.Operator):
    """Measure how much the previewed crowd repeats itself at this frame: the share of
    screen-space neighbour pairs that play the same stream in step, with the same body
    and colour (docs/variety.md). Seen through the scene camera, or through this
    viewport when the scene has none"""

    bl_idname = "crowd.measure_repetition"
    bl_label = "Measure Repetition"

    def run(self, context):
        preview.measure_repetition(context.scene, context.region_data, context.region)


class CROWD_OT_plan_variety(_OnPreview, bpy.types.Operator):
    """Find the history length M, copies of each stream and offset distribution that
    repeat least through the scene camera (or this viewport), within the Budget and
    Max Streams (docs/variety.md)"""

    bl_idname = "crowd.plan_variety"
    bl_label = "Plan Variety"

    def run(self, context):
        from ..plan_report import metric_text
        wm = context.window_manager
        wm.progress_begin(0, 1)                 # the cursor shows the candidates tried
        try:
            p = preview.plan_variety(context.scene, context.region_data, context.region,
                                     progress=lambda done, total: wm.progress_update(
                                         done / max(total, 1)))
        finally:
            wm.progress_end()
        self.report({"INFO"}, f"Plan: M {p.planned.max_offset}, {p.planned.streams} "
                              f"streams, repetition {metric_text(p.planned.repetition)} "
                              f"(now {metric_text(p.default.repetition)})")


class CROWD_OT_apply_plan(bpy.types.Operator):
    """Set the plan's M, stream copies and Spread offsets in the Crowd settings, then
    bake"""

    bl_idname = "crowd.apply_plan"
    bl_label = "Apply Plan"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        pv = preview.get(context.scene)
        return pv is not None and pv.plan is not None

    def execute(self, context):
        try:
            preview.apply_plan(context.scene)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return bpy.ops.crowd.bake("EXEC_DEFAULT")


# ---------------------------------------------------------------- list editing
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
        owner = _owner(context.scene.crowd, self.collection, self.pool)
        return owner, getattr(owner, self.collection), _INDEX[self.collection]


class CROWD_OT_item_add(_ListOperator, bpy.types.Operator):
    """Add an item to a crowd list"""

    bl_idname = "crowd.item_add"
    bl_label = "Add"
    bl_options = {"REGISTER", "UNDO"}

    kind: EnumProperty(name="Kind", items=NODE_KINDS, default="CLIP")

    def execute(self, context):
        try:
            owner, items, index = self._target(context)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
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
        try:
            owner, items, index = self._target(context)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
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
        try:
            owner, items, index = self._target(context)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        i = getattr(owner, index)
        j = i + self.step
        if not (0 <= i < len(items) and 0 <= j < len(items)):
            return {"CANCELLED"}
        items.move(i, j)
        setattr(owner, index, j)
        return {"FINISHED"}


CLASSES = (CROWD_OT_bake, CROWD_OT_generate_agents, CROWD_OT_preview_toggle,
           CROWD_OT_measure_repetition, CROWD_OT_plan_variety, CROWD_OT_apply_plan,
           CROWD_OT_item_add, CROWD_OT_item_remove, CROWD_OT_item_move)
