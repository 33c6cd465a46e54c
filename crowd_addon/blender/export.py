"""A scene's crowd written to USD: the shared bake-record-write steps and the
*Export Crowd USD* operator (Crowd panel button, File > Export > Crowd (.usd)).

:func:`export_steps` is the export, one unit of work per step, all on the caller's
thread: it checks the output and the frame range against the scene, bakes the
scene's Crowd settings (:func:`.scene_config.config_steps`, one action per step),
records the shot once (:class:`crowd_addon.core.shots.recorder.Recorder`, one frame per
step, a crowd that skins nothing) and writes the recording
(:func:`crowd_addon.usd.export_steps`, a layer or a batch of agents per step; all or
nothing: a failure or a cancel leaves no new file and a previous export as it was).
:func:`export_scene` runs it to the end in one call (``crowd export --blend``, the
operator run from a script); the operator run from the UI steps it on a timer and
Esc cancels it. The USD modules (``pxr``) are imported only when an export runs.
"""

import os
import time
from numbers import Integral

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..core.authoring.config import MAX_SUBSTEPS
from ..core.base.errors import CrowdError
from ..core.variety.repetition import RepetitionSettings
from . import preview, scene_config
from .cameras import metric_view

__all__ = ["CLASSES", "MENUS", "ExportJob", "check_export", "export_scene",
           "export_steps", "menu_export", "CROWD_OT_export_usd"]

#: main layer extensions the exporter writes (``crowd_addon.usd.files.FORMATS``)
EXTENSIONS = (".usdc", ".usd", ".usda")


def check_export(scene, path, frames) -> tuple:
    """Validate an export of ``scene`` before any baking; returns ``(first, last)``.

    ``path`` must end in .usdc/.usd/.usda in an existing folder this process can
    write (probed with a temporary folder that is removed again); ``frames`` is
    ``(first, last)``, whole numbers, ``scene.frame_start <= first <= last`` (the
    crowd starts at the scene's start frame). Raises CrowdError naming the fault.
    """
    from ..usd.files import ExportFiles

    try:
        first, last = frames
    except (TypeError, ValueError):
        raise CrowdError(f"export: frames must be (first, last), got {frames!r}") from None
    if any(isinstance(f, bool) or not isinstance(f, Integral) for f in (first, last)):
        raise CrowdError(f"export: frames must be whole numbers, got {frames!r}")
    if last < first:
        raise CrowdError(f"export: frame range {first}-{last} is empty (last < first)")
    if first < scene.frame_start:
        raise CrowdError(f"export: frame range {first}-{last} starts before scene "
                         f"{scene.name!r}'s start frame {scene.frame_start}, where the "
                         "crowd starts")
    with ExportFiles(path):             # extension, folder, and a writable folder
        pass
    return int(first), int(last)


def export_scene(scene, path, frames, agents=None, progress=None, on_bake=None,
                 depsgraph=None, layout="instanced", substeps=1, snapshots=None,
                 repetition=RepetitionSettings(), trust_script=False,
                 ignore_script=False, strict=False):
    """Bake ``scene``'s Crowd settings and export the shot to ``path`` in one call
    (:func:`export_steps` run to the end).

    Parameters
    ----------
    scene : a scene with Crowd settings (``scene.crowd``, the extension registered).
    path, agents, layout : as :func:`crowd_addon.usd.export_crowd`; frames : ``(first, last)``
        (:func:`check_export`).
    substeps : samples written per frame (1..16; more than 1 adds sub-frame samples
        for motion blur: ``Crowd(..., substeps=N)``).
    snapshots : optional snapshot folder (``crowd export --snapshots``): the crowd
        starts from its latest snapshot there before ``first`` and leaves one at
        ``last`` (:class:`crowd_addon.core.shots.snapshot.ShotSnapshots`).
    progress : optional ``progress(stage, done, total)`` after each recorded frame
        (``"simulate"``) and each step of the writing.
    on_bake : optional ``on_bake(done, total, message)`` before each bake step
        (:func:`.scene_config.config_steps`), then with each note of the bake report
        (``config.bake_report``) as ``warning: ...`` or ``note: ...``.
    strict : the bake report's warnings stop the export before anything is written
        (:class:`~crowd_addon.core.bake.bake_report.BakeWarnings`, ``--strict``).
    depsgraph : evaluated depsgraph for the agent sources (default: the scene's).
    repetition : the repetition metric's settings (None: not measured), measured
        through the scene camera at the scene's render size when it has one
        (:func:`.cameras.metric_view`).
    trust_script : run the scene's crowd script in this export even where it is not
        trusted (``crowd export --trust-scripts``); it trusts nothing after the call.
    ignore_script : leave the scene's crowd script out of this export, trusted or not
        (``crowd export --ignore-scripts``).

    Returns
    -------
    ``(config, result)``: the baked :class:`~crowd_addon.core.authoring.config.CrowdConfig` and
    the :class:`~crowd_addon.usd.export.ExportResult`. Raises CrowdError (nothing
    written then); the scene is not changed. An exception raised by a callback stops
    the export the same way.
    """
    steps = export_steps(scene, path, frames, agents, depsgraph, layout, substeps, snapshots,
                         repetition, trust_script, ignore_script, strict)
    try:
        while True:
            try:
                stage, done, total, message = next(steps)
            except StopIteration as stop:
                return stop.value
            if stage == "bake":
                if on_bake is not None:
                    on_bake(done, total, message)
            elif progress is not None:
                progress(stage, done, total)
    finally:
        steps.close()                   # a raising callback: the export is dropped


def export_steps(scene, path, frames, agents=None, depsgraph=None, layout="instanced",
                 substeps=1, snapshots=None, repetition=RepetitionSettings(),
                 trust_script=False, ignore_script=False, strict=False):
    """The export of :func:`export_scene` as a generator, one unit of work per
    ``next()``: returns ``(config, result)`` (``StopIteration.value``).

    Yields ``(stage, done, total, message)``: stage ``"bake"`` before each bake step
    (``message`` as :func:`.scene_config.config_steps`), ``"simulate"`` after each
    recorded frame, then each step of :func:`crowd_addon.usd.export_steps`; after the
    bake, stage ``"bake"`` once per note of its report (``message``: the note's
    ``line``; ``strict``: then a report with warnings stops it, nothing written)
    (``message`` is the stage). The output and the frame range are checked when it is
    called (CrowdError); a fault found later (the agent count, a missing proxy mesh:
    checked once baked, before recording) is raised by ``next()``.

    Closing the generator before it is done (``close()``, or dropping it) cancels the
    export: close returns once its temporary files are removed; nothing is written, a
    previous export at ``path`` is left as it was, the scene is unchanged.
    """
    from ..core.shots.crowd import check_substeps
    from ..usd.export import check_layout
    frames = check_export(scene, path, frames)
    check_layout(layout)
    return _export_steps(scene, path, frames, agents, depsgraph, layout,
                         check_substeps(substeps), snapshots, repetition, trust_script,
                         ignore_script, strict)


def _export_steps(scene, path, frames, agents, depsgraph, layout, substeps, snapshots,
                  repetition, trust_script, ignore_script=False, strict=False):
    import dataclasses

    from ..core.bake.bake_report import report_of
    from ..core.shots.snapshot import ShotSnapshots
    from ..core.shots.crowd import Crowd
    from ..core.shots.recorder import Recorder
    from ..usd.export import check_export as check_output
    from ..usd.export import export_steps as write_steps

    bake = scene_config.config_steps(scene, depsgraph)
    try:
        while True:
            with preview.suspended():   # the bake's frame_set must not drive a preview
                try:
                    done, total, message = next(bake)
                except StopIteration as stop:
                    config = stop.value
                    break
            yield "bake", done, total, message
    finally:
        bake.close()
    report = report_of(config)          # the bake's, meshes' and LOD levels' notes
    for note in report:
        yield "bake", 1, 1, note.line
    report.check_strict(strict)
    check_output(config, path, agents, layout)
    crowd, note = scene_config.build_crowd(scene, config, substeps=substeps,
                                           trust_script=trust_script,
                                           ignore_script=ignore_script)
    if note:
        yield "bake", 1, 1, note
    snaps = ShotSnapshots(snapshots, crowd, frames[0]) if snapshots else None
    recorder = Recorder(crowd, *frames)
    while not recorder.finished:
        recorder.step()
        yield "simulate", recorder.done, recorder.total, "simulate"
    if snaps is not None:
        snaps.recorded()
    camera, repetition = metric_view(scene, repetition)
    writing = write_steps(recorder.finish(), path, agents, layout, camera, repetition)
    try:
        while True:
            try:
                stage, done, total = next(writing)
            except StopIteration as stop:
                if snaps is None:
                    return config, stop.value
                return config, dataclasses.replace(stop.value, started_from=snaps.started_from,
                                                   snapshot=snaps.keep())
            yield stage, done, total, stage
    finally:
        writing.close()                 # a cancel: its temporary files are removed


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


def _event_loop(context) -> bool:
    """Whether a modal operator gets events here: a window, and not background mode
    (the bpy module has a window but no event loop)."""
    return context.window is not None and not bpy.app.background


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
    from ..gpu.preview_render import writable_dir
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
