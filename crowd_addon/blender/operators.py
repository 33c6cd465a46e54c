"""Operators: bake (modal, with progress and cancel), agents, preview, variety.

Every operator reports bad input as an ERROR naming what is at fault
(:class:`CrowdError` messages) and then changes nothing: a bake replaces the running
crowd only once the new one is complete.
"""

import time

import bpy

from ..core.base.errors import CrowdError
from . import preview, preview_variety, scene_config
from .agents import agents_from_scene
from .show_data import show_from_scene

__all__ = ["CLASSES", "BakeJob", "bake_now", "event_loop"]


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


def event_loop(context) -> bool:
    """Whether a modal operator gets events here: a window, and not background mode
    (the bpy module has a window but no event loop)."""
    return context.window is not None and not bpy.app.background


def bake_now(op, context) -> set:
    """Bake the context scene's crowd in one go and start the preview with it (Bake
    without an event loop, Preview, Apply Plan): ``{"FINISHED"}``, or ``{"CANCELLED"}``
    with the bake's error reported on ``op`` and nothing changed."""
    wm = context.window_manager
    job = BakeJob(context.scene)
    wm.progress_begin(0, 1000)
    try:
        while job.step():
            wm.progress_update(int(1000 * job.done / job.total))
        return _start_baked(op, context, job.config)
    except CrowdError as e:
        op.report({"ERROR"}, str(e))
        return {"CANCELLED"}
    finally:
        wm.progress_end()


def _start_baked(op, context, config) -> set:
    from ..core.bake.bake_report import WARNING, report_of
    pv = preview.start(context.scene, config)
    c = pv.crowd
    for note in report_of(config):  # e.g. poses between frames that miss the action's
        op.report({"WARNING" if note.severity == WARNING else "INFO"}, note)
    op.report({"INFO"}, f"Crowd: {len(config.clips)} clips, {c.streams.count} streams, "
                        f"{c.uniques.count} uniques, {c.agents.count} agents")
    return {"FINISHED"}


class CROWD_OT_bake(bpy.types.Operator):
    """Bake the crowd's actions into clips, place the agents and start the preview
    (Esc cancels; the previous crowd stays until the new one is complete)"""

    bl_idname = "crowd.bake"
    bl_label = "Bake Crowd"
    bl_options = {"REGISTER"}

    _timer = None
    _job = None

    def execute(self, context):
        return bake_now(self, context)

    def invoke(self, context, event):
        if not event_loop(context):
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
                return _start_baked(self, context, job.config)
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
        return bake_now(self, context)

    def invoke(self, context, event):
        if preview.get(context.scene) is not None or not event_loop(context):
            return self.execute(context)
        return bpy.ops.crowd.bake("INVOKE_DEFAULT")     # modal: reports its own errors


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
        preview_variety.measure_repetition(context.scene, context.region_data, context.region)


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
            p = preview_variety.plan_variety(context.scene, context.region_data,
                                             context.region,
                                             progress=lambda done, total: wm.progress_update(
                                                 done / max(total, 1)))
        finally:
            wm.progress_end()
        self.report({"INFO"}, f"Plan: M {p.planned.max_offset}, {p.planned.streams} "
                              f"streams, repetition {metric_text(p.planned.repetition)} "
                              f"(now {metric_text(p.default.repetition)})")


class CROWD_OT_apply_plan(bpy.types.Operator):
    """Set the plan's M, stream copies and Spread offsets in the Crowd settings, then
    bake (when the bake fails the settings are put back)"""

    bl_idname = "crowd.apply_plan"
    bl_label = "Apply Plan"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        pv = preview.get(context.scene)
        return pv is not None and pv.plan is not None

    def execute(self, context):
        try:
            undo = preview_variety.apply_plan(context.scene)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        done = bake_now(self, context)
        if done != {"FINISHED"}:
            undo()                      # the bake failed: the settings as they were
        return done


CLASSES = (CROWD_OT_bake, CROWD_OT_generate_agents, CROWD_OT_preview_toggle,
           CROWD_OT_measure_repetition, CROWD_OT_plan_variety, CROWD_OT_apply_plan)
