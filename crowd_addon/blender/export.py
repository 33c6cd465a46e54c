"""A scene's crowd written to USD: the shared bake-and-export step and the
*Export Crowd USD* operator (Crowd panel button, File > Export > Crowd (.usd)).

:func:`export_scene` checks the output and the frame range against the scene, bakes
the scene's Crowd settings (:func:`.scene_config.config_steps`) and writes the shot
with :func:`crowd_addon.usd.export_crowd` (all or nothing: a failure leaves no new
file and a previous export as it was). ``crowd export --blend`` and the operator both
call it. The USD modules (``pxr``) are imported only when an export runs.
"""

import os
from numbers import Integral

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..core.errors import CrowdError
from . import preview, scene_config

__all__ = ["CLASSES", "MENUS", "check_export", "export_scene", "menu_export",
           "CROWD_OT_export_usd"]

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
                 depsgraph=None):
    """Bake ``scene``'s Crowd settings and export the shot to ``path``.

    Parameters
    ----------
    scene : a scene with Crowd settings (``scene.crowd``, the extension registered).
    path, frames, agents, progress : as :func:`crowd_addon.usd.export_crowd`
        (``progress(stage, done, total)`` during the export).
    on_bake : optional ``on_bake(done, total, message)`` before each bake step
        (:func:`.scene_config.config_from_scene`).
    depsgraph : evaluated depsgraph for the agent sources (default: the scene's).

    Returns
    -------
    ``(config, result)``: the baked :class:`~crowd_addon.core.config.CrowdConfig` and
    the :class:`~crowd_addon.usd.export.ExportResult`. Raises CrowdError (nothing
    written then); the scene is not changed.
    """
    from ..usd import export_crowd

    frames = check_export(scene, path, frames)
    with preview.suspended():           # the bake's frame_set must not drive a preview
        config = scene_config.config_from_scene(scene, on_bake, depsgraph)
    return config, export_crowd(config, path, frames, agents=agents, progress=progress)


def _size(n: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:,} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return ""


#: progress bar share (out of 1000) of the bake and of each export stage
_SPANS = {"bake": (0, 300), "simulate": (300, 700), "characters": (700, 720),
          "streams": (720, 820), "agent animations": (820, 980), "layout": (980, 1000)}


class CROWD_OT_export_usd(bpy.types.Operator, ExportHelper):
    """Bake the scene's crowd settings and write the crowd shot as UsdSkel (a main
    layer and a folder of layers beside it); nothing is written if anything fails"""

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

    def execute(self, context):
        scene = context.scene
        frames = ((scene.frame_start, scene.frame_end) if self.use_scene_range
                  else (self.frame_start, self.frame_end))
        path = bpy.path.abspath(self.filepath)
        wm = context.window_manager
        wm.progress_begin(0, 1000)

        def update(stage, done, total):
            lo, hi = _SPANS.get(stage, (None, None))
            if lo is not None and total > 0:
                wm.progress_update(lo + (hi - lo) * min(done, total) // total)

        try:
            _config, result = export_scene(
                scene, path, frames, agents=self.agents or None, progress=update,
                on_bake=lambda done, total, _what: update("bake", done, total),
                depsgraph=context.evaluated_depsgraph_get())
        except CrowdError as e:
            self.report({"ERROR"}, f"Crowd export: {str(e).removeprefix('export: ')}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        first, last = result.frames
        self.report({"INFO"}, f"Crowd: wrote {result.agents:,} agents, frames {first}-"
                              f"{last} to {result.path} and {len(result.files) - 1} "
                              f"layers ({_size(result.bytes)})")
        return {"FINISHED"}


def menu_export(self, _context):
    """File > Export entry."""
    self.layout.operator(CROWD_OT_export_usd.bl_idname, text="Crowd (.usd)")


CLASSES = (CROWD_OT_export_usd,)
#: (menu type name, draw function) pairs appended on register
MENUS = (("TOPBAR_MT_file_export", menu_export),)
