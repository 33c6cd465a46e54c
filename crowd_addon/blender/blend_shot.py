"""A .blend's shot opened for a command (:meth:`crowd_addon.shot_source.ShotSource.open`
and ``blender -c crowd``): the file opened and the extension registered when needed
(:func:`open_scene`), the scene's crowd script checked before anything runs, the
frames (given, or the scene's frame range), the Crowd settings baked as the panel
bakes them when first needed (the bake report's notes to ``on_bake``; ``strict``:
warnings stop it), the crowd built with the script, and the scene camera the
repetition metric is measured through. Blender's own log lines go to stderr
(:func:`blender_output_to_stderr`) so a command's stdout holds only its summary.
"""

from __future__ import annotations

import os
from functools import cached_property

from ..core.base.errors import CrowdError
from .c_output import fd_redirected

__all__ = ["BlendShot", "open_scene", "blender_output_to_stderr", "preview_view",
           "preview_scene"]


def open_scene(blend: str | None = None, scene: str | None = None):
    """The Blender scene of a command: the active (or ``scene``-named) scene of the
    .blend ``blend`` opened here, or of the file already open (inside Blender).
    Registers the extension when the scene has no Crowd settings yet. Raises
    CrowdError."""
    try:
        import bpy
    except ImportError:
        raise CrowdError("give --config CROWD_JSON, or --blend with the bpy module "
                         "installed (pip install bpy)") from None
    if blend:
        if not os.path.isfile(blend):
            raise CrowdError(f"{blend}: no such .blend file")
        try:
            bpy.ops.wm.open_mainfile(filepath=os.path.abspath(blend))
        except RuntimeError as e:            # not a .blend, damaged, from a newer Blender
            reason = str(e).strip().splitlines()[-1] if str(e).strip() else "unreadable"
            raise CrowdError(f"{blend}: Blender cannot open it as a .blend file "
                             f"({reason})") from None
    elif not bpy.data.filepath:
        raise CrowdError("give --config CROWD_JSON or --blend SCENE_BLEND (no .blend is "
                         "open)")
    found = bpy.context.scene if scene is None else bpy.data.scenes.get(scene)
    if found is None:
        raise CrowdError(f"no scene {scene!r} in {bpy.data.filepath} (scenes: "
                         f"{[s.name for s in bpy.data.scenes]})")
    if not hasattr(found, "crowd"):             # outside an installed extension
        from .registration import register
        register(restore=False)             # the command builds the crowd: one bake
    return found


class BlendShot:
    """The shot of a .blend's scene (``source``: a ShotSource, or anything with its
    ``blend``, ``scene``, ``trust_scripts``, ``ignore_scripts``, ``strict`` and
    ``substeps``): ``scene``, ``frames`` ((first, last): given, or the scene's range),
    ``config`` (baked on first use), :meth:`crowd` and :meth:`metric_view`.
    ``crowd_needed`` False (``crowd plan``: no crowd is built, so no script runs):
    the script is not checked."""

    def __init__(self, source, frames=None, on_bake=None, crowd_needed: bool = True,
                 reuse_bake=None, keep_bake=None):
        from .crowd_script import check_script
        self.source, self.on_bake = source, on_bake
        self.reuse_bake, self.keep_bake = reuse_bake, keep_bake
        self.scene = open_scene(source.blend, source.scene)
        if crowd_needed:   # a script that would not run stops the command here
            check_script(self.scene, source.trust_scripts, source.ignore_scripts)
        self.frames = (self.scene.frame_start, self.scene.frame_end) if frames is None \
            else tuple(int(f) for f in frames)
        if self.frames[0] < self.scene.frame_start:     # before the bake: the crowd's start
            raise CrowdError(f"frame range {self.frames[0]}-{self.frames[1]} starts before "
                             f"scene {self.scene.name!r}'s start frame "
                             f"{self.scene.frame_start}, where the crowd starts")

    @cached_property
    def config(self):
        """The scene's CrowdConfig, baked as the panel bakes it; each note of its bake
        report goes to ``on_bake`` (``warning: ...`` / ``note: ...``), and with
        ``strict`` warnings raise BakeWarnings (exit code 2). ``reuse_bake``: a
        snapshot folder whose kept bake of this .blend is read instead of baking;
        ``keep_bake``: one the bake is kept in (:mod:`.bake_cache`)."""
        from ..core.bake.bake_report import report_of
        from .bake_cache import bake_key, bake_of, load_baked, save_baked
        from .scene_config import config_from_scene
        key = bake_key(self.scene) if self.source.blend and (
            self.reuse_bake or self.keep_bake) else None      # opened from its file
        config = load_baked(self.reuse_bake, key) if self.reuse_bake and key else None
        if config is not None and self.on_bake is not None:
            self.on_bake(1, 1, f"the bake kept in {self.reuse_bake} by its snapshot pass "
                               f"(the .blend is unchanged): not baked again")
        if config is None:
            config = config_from_scene(self.scene, self.on_bake)
            if self.keep_bake and key:
                save_baked(self.keep_bake, key, config, bake_of(self.scene))
        report = report_of(config)
        if self.on_bake is not None:
            for note in report:
                self.on_bake(1, 1, note.line)
        report.check_strict(self.source.strict)
        return config

    def crowd(self, substeps: int | None = None):
        """The shot's crowd with the scene's crowd script run on it (why it did not run,
        if so, goes to ``on_bake``)."""
        from .scene_config import build_crowd
        crowd, note = build_crowd(
            self.scene, self.config,
            substeps=self.source.substeps if substeps is None else substeps,
            trust_script=self.source.trust_scripts, ignore_script=self.source.ignore_scripts)
        if note and self.on_bake is not None:
            self.on_bake(1, 1, note)
        return crowd

    def metric_view(self, settings):
        """The scene camera at its render size, and ``settings`` sized to it
        (:func:`.cameras.metric_view`)."""
        from .cameras import metric_view
        return metric_view(self.scene, settings)


def preview_view(shot, start=None, frames=None, size=(None, None), camera=None) -> tuple:
    """``(first, frames, size, view, camera name)`` of ``crowd preview --blend``: the
    first frame (``start`` or the scene's), the frame count (``frames`` or to the
    scene's end), the size (the scene's render size where None), the camera object
    (``camera`` by name or the scene camera) and its view (None: the renderer frames
    the crowd). Checked before the bake."""
    from .cameras import camera_from_object, find_camera, scene_size
    scene = shot.scene
    first = scene.frame_start if start is None else int(start)
    if frames is None:
        frames = scene.frame_end - first + 1
        if frames < 1:
            raise CrowdError(f"--start {first} is after scene {scene.name!r}'s last "
                             f"frame {scene.frame_end}; give --frames")
    size = scene_size(scene, size)
    obj = find_camera(scene, camera)
    view = None if obj is None else camera_from_object(obj, size[0] / size[1])
    return first, frames, size, view, None if obj is None else obj.name


def preview_scene(shot) -> dict:
    """The scene drawn around the crowd and its sun (``render_preview``'s ``scene`` and
    ``light``)."""
    from .scene_geometry import scene_geometry, scene_light
    return {"scene": scene_geometry(shot.scene), "light": scene_light(shot.scene)}


def blender_output_to_stderr():
    """A context: whatever is written to the process's standard output (Blender's own
    log lines such as ``Read blend: ...``, which its C code writes there) goes to
    standard error, so a command's stdout holds only its summary (``--json``: one JSON
    object)."""
    return fd_redirected(1, 2)
