"""The *Export Crowd USD* operator (Crowd panel button, File > Export > Crowd (.usd)).

Run from the UI it steps the export (:func:`.scene_export.export_steps`, an
:class:`ExportJob`) on a timer with a progress bar, and Esc cancels it; run from a
script it exports in one call (:func:`.scene_export.export_scene`). A missing output
folder is made, and removed again when the export fails or is cancelled.
"""

import os
import time

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..core.authoring.config import MAX_SUBSTEPS
from ..core.base.errors import CrowdError
from .operators import event_loop as _event_loop
from .scene_export import export_scene, export_steps

__all__ = ["CLASSES", "MENUS", "ExportJob", "menu_export", "CROWD_OT_export_usd"]

#: main layer extensions the exporter writes (``crowd_addon.usd.files.FORMATS``)
EXTENSIONS = (".usdc", ".usd", ".usda")


class ExportJob:
    """A scene's export (:func:`export_steps`) run a slice of time at a time, for the
    modal operator; :meth:`cancel` drops it and nothing is written."""

    def __init__(self, scene, path, frames, agents=None, depsgraph=None, layout="instanced",
                 substeps=1):
        self.steps = export_steps(scene, path, frames, agents, depsgraph, layout, substeps)
        self.stage, self.done, self.total, self.message = "bake", 0, 1, "starting"
        self.config = self.result = None

    def step(self, seconds=0.0) -> bool:
        """Do units of work for about ``seconds`` (at least one); False once
        :attr:`result` is set. Raises CrowdError (the job is then over, nothing
        written)."""
        end = time.perf_counter() + seconds
        while True:
            try:
                self.stage, self.done, self.total, self.message = next(self.steps)
            except StopIteration as stop:
                self.config, self.result = stop.value
                return False
            if time.perf_counter() >= end:
                return True

    @property
    def progress(self) -> int | None:
        """Progress bar position, 0..1000 (see ``_SPANS``); None for a stage without one."""
        return _progress(self.stage, self.done, self.total)

    @property
    def status(self) -> str:
        if self.stage == "bake":
            return f"{self.message} ({self.done + 1}/{self.total})"
        return f"{self.stage} {self.done}/{self.total}"

    def cancel(self):
        """Stop the export; returns once its temporary files are removed."""
        self.steps.close()


def _size(n: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:,} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return ""


#: progress bar share (out of 1000) of the bake and of each export stage
_SPANS = {"bake": (0, 300), "simulate": (300, 700), "characters": (700, 720),
          "streams": (720, 800), "uniques": (800, 810), "blends": (810, 860),
          "agent animations": (860, 980),
          "layout": (980, 1000)}


def _progress(stage, done, total):
    """Progress bar position (0..1000) of ``done`` out of ``total`` in ``stage``, or
    None for a stage without a share."""
    lo, hi = _SPANS.get(stage, (None, None))
    if lo is None or total <= 0:
        return None
    return lo + (hi - lo) * min(done, total) // total


class CROWD_OT_export_usd(bpy.types.Operator, ExportHelper):
    """Bake the scene's crowd settings and write the crowd shot as UsdSkel (a main
    layer and a folder of layers beside it); Esc cancels; nothing is written if
    anything fails or the export is cancelled"""

    bl_idname = "crowd.export_usd"
    bl_label = "Export Crowd USD"
    bl_options = {"REGISTER"}

    filename_ext = ".usdc"
    check_extension = None              # .usd/.usda/.usdc are kept: see check()
    filter_glob: StringProperty(default="*.usd;*.usda;*.usdc", options={"HIDDEN"})
    use_scene_range: BoolProperty(
        name="Scene Frame Range", default=True,
        description="Export the scene's frame range (otherwise Start and End)")
    frame_start: IntProperty(name="Start", default=1, options={"SKIP_SAVE"},
                             description="First frame (not before the scene's start "
                                         "frame, where the crowd starts)")
    frame_end: IntProperty(name="End", default=250, options={"SKIP_SAVE"},
                           description="Last frame, inclusive")
    agents: IntProperty(name="Agents", default=0, min=0,
                        description="Export only the first N agents (0: all)")
    usd_layout: EnumProperty(
        name="Layout", default="instanced",
        items=[("instanced", "Instanced", "Agents are instanceable: renderers share each "
                "character (usdview, Houdini, Omniverse, render delegates)"),
               ("blender", "Blender", "Agents are not instanceable, so Blender's own USD "
                "import plays their animation, and their colours are on their meshes, "
                "where it reads them (Blender 4.5 and later)")],
        description="How the agents are laid out in the stage")
    substeps: IntProperty(
        name="Samples per Frame", default=1, min=1, max=MAX_SUBSTEPS,
        description="Poses written per frame: more than 1 adds samples between frames "
                    "(the crowd evaluated there) for renderers' motion blur, at that many "
                    "times the animation data")
    interactive: BoolProperty(
        default=False, options={"HIDDEN", "SKIP_SAVE"},
        description="Run step by step on a timer after the file browser (Esc cancels); "
                    "set by invoke. Otherwise the export runs to the end in one call")

    #: seconds of work per timer event of the modal export
    step_seconds = 0.05
    _timer = None
    _job = None
    _made = ()                          # folders made for this export, deepest first

    def check(self, _context):
        """.usdc, .usd and .usda stay as typed; any other name gets .usdc."""
        if not os.path.basename(self.filepath):
            return False
        if os.path.splitext(self.filepath)[1].lower() in EXTENSIONS:
            return False
        self.filepath = bpy.path.ensure_ext(os.path.splitext(self.filepath)[0],
                                            self.filename_ext)
        return True

    def invoke(self, context, event):
        scene = context.scene
        if not self.properties.is_property_set("frame_start"):
            self.frame_start = scene.frame_start
        if not self.properties.is_property_set("frame_end"):
            self.frame_end = scene.frame_end
        self.interactive = _event_loop(context)
        return ExportHelper.invoke(self, context, event)

    def draw(self, _context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "use_scene_range")
        col = layout.column(align=True)
        col.enabled = not self.use_scene_range
        col.prop(self, "frame_start")
        col.prop(self, "frame_end")
        layout.prop(self, "agents")
        layout.prop(self, "usd_layout")
        layout.prop(self, "substeps")

    def execute(self, context):
        """From the file browser (after invoke): start the modal export. From a script:
        export in one call."""
        scene = context.scene
        frames = ((scene.frame_start, scene.frame_end) if self.use_scene_range
                  else (self.frame_start, self.frame_end))
        path = bpy.path.abspath(self.filepath)
        wm = context.window_manager
        try:            # a missing folder is made, as crowd export makes it
            self._made = _make_folder(os.path.dirname(os.path.abspath(path)))
        except CrowdError as e:
            return self._fail(e)
        if self.interactive and _event_loop(context):
            try:
                # the depsgraph is looked up when the agents are placed, as the bake does
                self._job = ExportJob(scene, path, frames, agents=self.agents or None,
                                      layout=self.usd_layout, substeps=self.substeps)
            except CrowdError as e:
                return self._fail(e)
            wm.progress_begin(0, 1000)
            self._timer = wm.event_timer_add(0.001, window=context.window)
            wm.modal_handler_add(self)
            return {"RUNNING_MODAL"}

        def update(stage, done, total):
            value = _progress(stage, done, total)
            if value is not None:
                wm.progress_update(value)

        wm.progress_begin(0, 1000)
        try:
            config, result = export_scene(
                scene, path, frames, agents=self.agents or None, progress=update,
                on_bake=lambda done, total, _what: update("bake", done, total),
                depsgraph=context.evaluated_depsgraph_get(), layout=self.usd_layout,
                substeps=self.substeps)
        except CrowdError as e:
            return self._fail(e)
        except BaseException:
            self._unmake()
            raise
        finally:
            wm.progress_end()
        return self._finish(result, config)

    def modal(self, context, event):
        job = self._job
        if event.type in {"ESC", "RIGHTMOUSE"} and event.value == "PRESS":
            job.cancel()                # returns once the temporary files are gone
            self._end(context)
            self._unmake()
            self.report({"WARNING"}, "Export cancelled: nothing was written")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            more = job.step(self.step_seconds)
        except CrowdError as e:
            self._end(context)
            return self._fail(e)
        except BaseException:
            job.cancel()
            self._end(context)
            self._unmake()
            raise
        if not more:
            self._end(context)
            return self._finish(job.result, job.config)
        value = job.progress
        if value is not None:
            context.window_manager.progress_update(value)
        context.workspace.status_text_set(f"Crowd export: {job.status}, Esc to cancel")
        return {"RUNNING_MODAL"}

    def cancel(self, context):
        """Blender ends the operator (file browser closed, file loaded, window closed):
        a running export is dropped, nothing is written."""
        if self._job is not None:
            self._job.cancel()
            self._end(context)
            self._unmake()

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        if self._job is not None:
            self._job = None
            wm.progress_end()
            context.workspace.status_text_set(None)

    def _fail(self, error):
        self._unmake()
        self.report({"ERROR"}, f"Crowd export: {str(error).removeprefix('export: ')}")
        return {"CANCELLED"}

    def _unmake(self):
        """The folders this export made, removed again (it failed or was cancelled)."""
        _remove_folders(self._made)
        self._made = ()

    def _finish(self, result, config=None):
        from ..core.bake.bake_report import report_of
        self._made = ()
        if config is not None:          # the bake's notes, as the Bake operator reports them
            for note in report_of(config):
                self.report({"WARNING" if note.severity == "warning" else "INFO"}, note)
        first, last = result.frames
        self.report({"INFO"}, f"Crowd: wrote {result.agents:,} agents, frames {first}-"
                              f"{last} to {result.path} and {len(result.files) - 1} "
                              f"layers ({_size(result.bytes)})")
        return {"FINISHED"}


def _make_folder(folder) -> tuple:
    """Create ``folder`` and its missing parents (checked first to be creatable and
    writable: CrowdError naming it); returns the folders made, deepest first."""
    from ..core.base.files import writable_dir
    writable_dir(folder)
    made, probe = [], folder
    while not os.path.exists(probe) and os.path.dirname(probe) != probe:
        made.append(probe)
        probe = os.path.dirname(probe)
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        _remove_folders(made)
        raise CrowdError(f"output folder {folder}: cannot create it "
                         f"({e.strerror or e})") from None
    return tuple(made)


def _remove_folders(made):
    """Remove the folders :func:`_make_folder` made, deepest first, each only while
    empty."""
    for folder in made:
        try:
            os.rmdir(folder)
        except OSError:
            break


def menu_export(self, _context):
    """File > Export entry."""
    self.layout.operator(CROWD_OT_export_usd.bl_idname, text="Crowd (.usd)")


CLASSES = (CROWD_OT_export_usd,)
#: (menu type name, draw function) pairs appended on register
MENUS = (("TOPBAR_MT_file_export", menu_export),)
