"""*Import Crowd USD* (File > Import > Crowd (.usd), and the Crowd panel): a crowd
stage brought into Blender so that it plays as the crowd did.

It wraps Blender's own USD importer (``bpy.ops.wm.usd_import``) and adds what that
importer leaves out for a crowd (docs/usd_export.md, "In Blender"):

- **the clock**: the scene's frame rate becomes the stage's ``timeCodesPerSecond``
  (``render.fps`` / ``render.fps_base``) and its frame range the stage's start and
  end time codes, so a 30 fps crowd does not play at Blender's default 24 fps (0.8x);
- **one material per look**: the importer's default makes each agent its own copy
  of every material (a 480-agent crowd: 1,540 materials). Imported with *Reference
  Existing*, all the agents share one material per look, each still in its own
  colours (they are attributes of its meshes). Materials of the file that have a
  look's name are kept out of that sharing: they are renamed for the import and get
  their names back after it, and the imported look takes the next free name
  (``Shirt.001``), so the crowd's template materials are neither worn by the imported
  agents nor renamed.

A stage exported with the ``instanced`` layout imports frozen (Blender's importer
does not animate instanced agents): the operator imports it and says so.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import bpy
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from ..core.base.errors import CrowdError

__all__ = ["CLASSES", "MENUS", "ImportResult", "import_crowd", "scene_rate",
           "CROWD_OT_import_usd", "menu_import"]

#: main layer extensions a crowd stage has (``crowd_addon.usd.files.FORMATS``)
EXTENSIONS = (".usdc", ".usd", ".usda")


@dataclass(frozen=True)
class ImportResult:
    """What :func:`import_crowd` did: the stage's ``fps``, ``frames`` (first, last),
    its ``layout`` (None: not a crowd export), the ``objects`` and ``materials`` it
    made (names), and ``notes`` for the user."""

    fps: float
    frames: tuple
    layout: str | None
    objects: tuple
    materials: tuple
    notes: tuple = ()


def scene_rate(fps: float) -> tuple:
    """Blender's ``(render.fps, render.fps_base)`` for a frame rate: the whole number
    nearest to it over the base that makes it exact (29.97: ``(30, 1.001)``)."""
    whole = max(1, min(32767, round(fps)))
    return whole, whole / fps


def import_crowd(context, path, shared_materials: bool = True,
                 scene_timing: bool = True) -> ImportResult:
    """Import the crowd stage ``path`` into ``context.scene`` with Blender's USD
    importer (the module docstring): ``scene_timing`` sets the scene's frame rate and
    range from the stage, ``shared_materials`` shares one material per look among the
    agents. Raises CrowdError (nothing imported) for a path that is no USD stage."""
    from ..usd.stage_info import stage_timing
    path = os.path.abspath(bpy.path.abspath(os.fspath(path)))
    if os.path.splitext(path)[1].lower() not in EXTENSIONS:
        raise CrowdError(f"{path}: a crowd stage ends in {', '.join(EXTENSIONS)}")
    timing = stage_timing(path)
    scene = context.scene
    objects = set(bpy.data.objects)
    materials = set(bpy.data.materials)
    aside = _set_aside(bpy.data.materials) if shared_materials else []
    try:
        result = bpy.ops.wm.usd_import(
            filepath=path, set_frame_range=scene_timing,
            mtl_name_collision_mode="REFERENCE_EXISTING" if shared_materials
            else "MAKE_UNIQUE")
    except RuntimeError as e:           # the importer's own report of a bad file
        raise CrowdError(f"{path}: Blender's USD importer failed: "
                         f"{str(e).strip() or 'no reason given'}") from None
    finally:
        made = [m for m in bpy.data.materials if m not in materials]
        _put_back(aside, made)
    if "FINISHED" not in result:
        raise CrowdError(f"{path}: Blender's USD importer did not import it ({result})")
    if scene_timing:
        scene.render.fps, scene.render.fps_base = scene_rate(timing.fps)
        scene.frame_start, scene.frame_end = timing.first, timing.last
        scene.frame_set(timing.first)
    notes = []
    if timing.layout == "instanced":
        notes.append("this stage has the instanced layout, which Blender's importer "
                     "brings in without animation: export with Layout: Blender "
                     "(crowd export --layout blender)")
    return ImportResult(fps=timing.fps, frames=(timing.first, timing.last),
                        layout=timing.layout,
                        objects=tuple(sorted(o.name for o in bpy.data.objects
                                             if o not in objects)),
                        materials=tuple(sorted(m.name for m in made)), notes=tuple(notes))


def _set_aside(materials) -> list:
    """Every local material renamed out of the way of the import's looks (the importer
    would otherwise put an existing material of a look's name on every agent):
    ``[(material, its name)]``."""
    aside = []
    for k, mat in enumerate([m for m in materials if m.library is None]):
        aside.append((mat, mat.name))
        mat.name = f"crowd import aside {os.getpid()} {k}"
    return aside


def _put_back(aside, made):
    """The set-aside materials get their names back; an imported material holding one
    of those names moves to the next free ``name.NNN`` first."""
    taken = {m.name: m for m in made}
    for mat, name in aside:
        other = taken.get(name)
        if other is not None:
            other.name = _free_name(name)
        mat.name = name


def _free_name(name: str) -> str:
    k = 1
    while f"{name}.{k:03d}" in bpy.data.materials:
        k += 1
    return f"{name}.{k:03d}"


class CROWD_OT_import_usd(bpy.types.Operator, ImportHelper):
    """Import a crowd USD stage with Blender's USD importer, playing as the crowd did:
    the scene takes the stage's frame rate and frame range, and the agents share one
    material per look, each in its own colours. Export with Layout: Blender for
    agents that move"""

    bl_idname = "crowd.import_usd"
    bl_label = "Import Crowd USD"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".usdc"
    filter_glob: StringProperty(default="*.usd;*.usda;*.usdc", options={"HIDDEN"})
    scene_timing: BoolProperty(
        name="Scene Frame Rate and Range", default=True,
        description="Set the scene's frame rate and frame range to the stage's, so the "
                    "crowd plays at its own speed")
    shared_materials: BoolProperty(
        name="One Material per Look", default=True,
        description="All agents share one material per look, each in its own colours "
                    "(otherwise Blender's importer makes each agent its own copies)")

    def draw(self, _context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "scene_timing")
        layout.prop(self, "shared_materials")

    def execute(self, context):
        try:
            result = import_crowd(context, self.filepath, self.shared_materials,
                                  self.scene_timing)
        except CrowdError as e:
            self.report({"ERROR"}, f"Crowd import: {e}")
            return {"CANCELLED"}
        for note in result.notes:
            self.report({"WARNING"}, f"Crowd import: {note}")
        first, last = result.frames
        self.report({"INFO"}, f"Crowd: imported {len(result.objects):,} objects and "
                              f"{len(result.materials)} materials, frames {first}-{last} "
                              f"at {result.fps:g} fps")
        return {"FINISHED"}


def menu_import(self, _context):
    """File > Import entry."""
    self.layout.operator(CROWD_OT_import_usd.bl_idname, text="Crowd (.usd)")


CLASSES = (CROWD_OT_import_usd,)
#: (menu type name, draw function) pairs appended on register
MENUS = (("TOPBAR_MT_file_import", menu_import),)
