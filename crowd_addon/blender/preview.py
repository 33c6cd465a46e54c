"""Viewport preview: the scene's crowd advanced on frame change and drawn in the 3D view.

One :class:`Preview` per scene holds the core ``Crowd`` built from the scene
(:mod:`.scene_config`) and, once a viewport has drawn, a renderer in Blender's GPU
context (:mod:`.preview_draw`). Previews are kept by the scene's ``session_uid``, which
stays the same across renames and undo: a renamed scene keeps its preview, and its
:mod:`crowd_addon.api` handle goes with it (:func:`follow_renames`); a new scene given
the old name has none.

The crowd follows ``scene.frame_current``; it keeps snapshots every few frames within
the memory cap of the preferences (:mod:`.prefs`), so a jump to any frame (backwards,
or forwards past frames seen before) re-simulates only from the nearest snapshot
(deterministic, ``Crowd.advance_to``), without reporting the replayed frames' events
again. When a character's armature or an action the crowd was built from is
deleted the preview pauses with a message instead of failing; undo that restores
them resumes it. Nothing here keeps Blender data between calls, only names and ids, so
undo and file loads never leave dangling references. After a file load, an undo or
redo, and when the extension is registered, every scene whose flags say its preview
runs (``preview_enabled``, or ``render_crowd``, which follows the preview's crowd) but
has none is restarted, or its flags are turned off with the reason (:func:`restore`).
The previewed crowd's repetition metric and variety plan are :mod:`.preview_variety`'s.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import bpy

from .. import api
from ..core.bake.bake_report import report_of
from ..core.shots.crowd import Crowd
from ..core.base.errors import CrowdError
from . import prefs, scene_config
from .preview_draw import draw, release_renderer
from .props import settings_fingerprint

__all__ = ["Preview", "start", "stop", "stop_all", "get", "running", "check", "last_error",
           "follow_renames", "restore", "draw_scene", "draw_handle", "on_frame_change",
           "on_depsgraph_update", "on_undo", "render_crowd_changed", "on_load_pre",
           "on_load_post"]


@dataclass
class Preview:
    """The running preview of one scene (runtime only, never saved)."""

    scene_name: str                # the scene's name when last seen (it follows renames)
    crowd: Crowd
    armatures: tuple               # (character name, armature name) it was built from
    actions: tuple
    fingerprint: int
    paused: str = ""               # why the crowd stopped advancing ("" = running)
    stale: bool = False            # settings changed since the crowd was built
    step_ms: float = 0.0
    draw_ms: float = 0.0
    renderer: object = None
    draw_error: str = ""
    script_note: str = ""          # why the scene's crowd script did not run
    bake_report: object = None     # core.bake_report.BakeReport of the crowd's bake
    render_frame: int | None = None    # the frame the Render Crowd data shows
    render_stats: object = None        # render_crowd.RenderStats of the last sync
    render_error: str = ""
    repetition: object = None          # core.repetition.Repetition last measured
    repetition_seen: str = ""          # through what it was measured
    plan: object = None                # core.variety_plan.VarietyPlan last proposed

    @property
    def handle(self):
        """The scene's :class:`crowd_addon.api.CrowdHandle`."""
        return api.scene_crowd(self.scene_name)

    def status(self) -> str:
        if self.paused:
            return f"Paused: {self.paused}"
        if self.stale:
            return "Settings changed since the crowd was built: Bake to update"
        if self.bake_report is not None and self.bake_report.warnings:
            first = self.bake_report.warnings[0]
            return (f"Bake: {self.bake_report.summary()} (the first: "
                    f"{first[:120]}{'...' if len(first) > 120 else ''})")
        return ""


_PREVIEWS: dict = {}               # scene.session_uid -> Preview
_ERRORS: dict = {}                 # scene.session_uid -> why its preview stopped
_DRAW = {"handle": None}


def get(scene):
    """The scene's :class:`Preview` or None."""
    pv = _PREVIEWS.get(scene.session_uid)
    if pv is not None and pv.scene_name != scene.name:
        _renamed(pv, scene.name)
    return pv


def running(scene):
    """The scene's :class:`Preview`, or a CrowdError when none runs (what measures
    its crowd needs one)."""
    pv = get(scene)
    if pv is None:
        raise CrowdError("the preview is not running: start it to measure its crowd")
    return pv


def last_error(scene) -> str:
    """Why the scene's preview stopped or could not start ("" if it did not)."""
    return _ERRORS.get(scene.session_uid, "")


def follow_renames() -> None:
    """Bring each preview's scene name, and the :mod:`crowd_addon.api` handle kept under
    it, up to date with its scene's renames (the API runs this before it looks a
    scene's handle up by name)."""
    scenes = {s.session_uid: s for s in bpy.data.scenes}
    for uid, pv in _PREVIEWS.items():
        scene = scenes.get(uid)
        if scene is not None and scene.name != pv.scene_name:
            _renamed(pv, scene.name)


def _renamed(pv, name):
    old, pv.scene_name = pv.scene_name, name
    api.rename_scene(old, name)


def draw_handle():
    """The SpaceView3D draw handler's handle while any preview runs, else None."""
    return _DRAW["handle"]


# ------------------------------------------------------------------ start / stop
def start(scene, config=None) -> Preview:
    """Build the scene's crowd (from ``config`` when given, else from the scene) and
    show it; replaces a running preview only once the new crowd is complete."""
    s = scene.crowd
    if config is None:
        with suspended():
            config = scene_config.config_from_scene(scene)
    for c in s.characters:
        if c.armature is None:
            raise CrowdError(f"character {c.name!r}: no armature chosen")
    crowd, note = scene_config.build_crowd(scene, config)
    crowd.keep_snapshots(*prefs.snapshot_settings())       # scrubbing jumps from them
    pv = Preview(scene.name, crowd, tuple((c.name, c.armature.name) for c in s.characters),
                 tuple(a.name for a in scene_config.scene_actions(s)),
                 settings_fingerprint(s))
    pv.script_note = note
    pv.bake_report = report_of(config)
    if crowd.agents.count and not config.meshes:
        pv.draw_error = "no proxy mesh chosen: agents run but are not drawn"
    old = _PREVIEWS.pop(scene.session_uid, None)
    if old is not None:
        _release(old)
    _PREVIEWS[scene.session_uid] = pv
    _ERRORS.pop(scene.session_uid, None)
    pv.handle.attach(crowd)
    _advance(scene, pv)
    if _DRAW["handle"] is None:
        _DRAW["handle"] = bpy.types.SpaceView3D.draw_handler_add(_draw_callback, (),
                                                                 "WINDOW", "POST_VIEW")
    if not s.preview_enabled:
        s.preview_enabled = True
    return pv


def _release(pv):
    handle = api.scene_crowd(pv.scene_name)
    if handle.crowd is pv.crowd:
        handle.detach()
    release_renderer(pv)


def stop(scene) -> None:
    """Stop the scene's preview and forget its crowd (callbacks registered through
    :mod:`crowd_addon.api` stay for the next one). Render Crowd goes off with it: its
    data would stop following the frame and renders would show a frozen crowd."""
    pv = _PREVIEWS.pop(scene.session_uid, None)
    if pv is not None:
        _release(pv)
    if scene.crowd.preview_enabled:
        scene.crowd.preview_enabled = False
    if scene.crowd.render_crowd:
        scene.crowd.render_crowd = False          # its update removes the render data
    if not _PREVIEWS:
        _remove_draw_handler()


def stop_all() -> None:
    """Stop every preview without touching scene data (unregister, file load)."""
    while _PREVIEWS:
        _release(_PREVIEWS.popitem()[1])
    _remove_draw_handler()


def _remove_draw_handler():
    handle, _DRAW["handle"] = _DRAW["handle"], None
    if handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(handle, "WINDOW")


class suspended:
    """Context manager: frame changes and depsgraph updates are ignored meanwhile
    (the bake plays actions with ``frame_set``, which must not drive the preview)."""

    depth = 0

    def __enter__(self):
        suspended.depth += 1

    def __exit__(self, *exc):
        suspended.depth -= 1


# ---------------------------------------------------------------------- advancing
def _problem(scene, pv) -> str:
    """What the preview's crowd lost in the scene ("" when nothing)."""
    characters = scene.crowd.characters
    for name, armature in pv.armatures:
        c = characters.get(name)
        if c is None:
            return f"character {name!r} was removed; undo or Bake without it"
        if c.armature is None:
            return (f"armature {armature!r} was deleted or unset (character {name!r}); "
                    "choose one and Bake")
        if scene.objects.get(c.armature.name) is None:
            return (f"armature {c.armature.name!r} (character {name!r}) is no longer in "
                    "the scene")
    gone = [a for a in pv.actions if bpy.data.actions.get(a) is None]
    if gone:
        return f"action {gone[0]!r} was deleted; restore it or Bake without it"
    return ""


def check(scene, settings=True):
    """Re-check the scene's preview against the scene and return it (None when none
    runs): what it lost (cheap, every frame) and, with ``settings``, whether the
    settings changed since the build (a walk over ``scene.crowd``, about 0.1 ms per
    stream: the panel does it when it redraws). Read-only."""
    pv = get(scene)
    if pv is not None:
        if settings:
            pv.stale = settings_fingerprint(scene.crowd) != pv.fingerprint
        pv.paused = _problem(scene, pv)
    return pv


def _advance(scene, pv):
    check(scene, settings=False)
    if pv.paused:
        return
    before = pv.crowd.frame
    t0 = time.perf_counter()
    try:
        pv.handle.advance_to(scene.frame_current)
    except Exception as e:  # noqa: BLE001 - a preview never takes Blender down
        pv.paused = f"the crowd stopped at frame {pv.crowd.frame}: {e}"
        return
    if pv.crowd.frame != before:
        pv.step_ms = (time.perf_counter() - t0) * 1e3 / abs(pv.crowd.frame - before)
    _sync_render(scene, pv)


def _sync_render(scene, pv, force=False):
    """Bring the Render Crowd data to the crowd's frame when the switch is on (once a
    frame: its own edits must not make the depsgraph handler sync again)."""
    if not scene.crowd.render_crowd or (pv.render_frame == pv.crowd.frame and not force):
        return
    from . import render_crowd
    with suspended():
        try:
            pv.render_stats = render_crowd.sync(scene, pv.crowd)
            pv.render_error = ""
        except Exception as e:  # noqa: BLE001 - a frame change never takes Blender down
            pv.render_error = f"Render Crowd: {e}"
    pv.render_frame = pv.crowd.frame


def render_crowd_changed(scene) -> None:
    """The Render Crowd switch changed: make the render data now, or remove it."""
    from . import render_crowd
    pv = get(scene)
    if scene.crowd.render_crowd:
        if pv is not None:
            _sync_render(scene, pv, force=True)
            return
        try:                                # the render data follows the preview's crowd
            start(scene)
        except CrowdError as e:             # the switch goes back off: nothing follows it
            _ERRORS[scene.session_uid] = f"Render Crowd needs the preview, which cannot start: {e}"
            scene.crowd.render_crowd = False
    else:
        with suspended():
            render_crowd.remove(scene)
        if pv is not None:
            pv.render_frame, pv.render_stats, pv.render_error = None, None, ""


@bpy.app.handlers.persistent
def on_frame_change(scene, *_):
    pv = get(scene)
    if pv is not None and not suspended.depth:
        _advance(scene, pv)


@bpy.app.handlers.persistent
def on_depsgraph_update(scene, *_):
    pv = get(scene)
    if pv is not None and not suspended.depth:
        _advance(scene, pv)          # pauses, or resumes what an edit restored


def _has_viewport() -> bool:
    """Whether a viewport can show a preview (not in background mode: ``blender -b``,
    the ``bpy`` module)."""
    return not bpy.app.background


def restore(when: str) -> None:
    """Start the preview of every scene whose flags say it runs but that has none, or
    turn its flags off with the reason (:func:`last_error`, "preview stopped ``when``:
    ..."). In background mode only Render Crowd's data (renders, ``blender -b -a``)
    needs the crowd: a scene with only ``preview_enabled`` on is left as it is, flag
    kept, so the file still opens with its preview in Blender's UI."""
    for scene in bpy.data.scenes:
        s = getattr(scene, "crowd", None)
        if s is None or get(scene) is not None:
            continue
        if not (s.render_crowd or (s.preview_enabled and _has_viewport())):
            continue
        try:
            start(scene)
        except CrowdError as e:
            s.preview_enabled = False
            if s.render_crowd:
                s.render_crowd = False            # its update removes the frozen data
            _ERRORS[scene.session_uid] = f"preview stopped {when}: {e}"


@bpy.app.handlers.persistent
def on_undo(*_):
    """Undo/redo: drop previews of scenes that are gone, re-check the others (resume
    when the undo restored what they lost), keep ``preview_enabled`` truthful, let
    Render Crowd skin every pose mesh again (an undo may bring them back as they were),
    and :func:`restore` the previews the undone state's flags ask for."""
    from .render_crowd import forget
    forget()
    scenes = {s.session_uid: s for s in bpy.data.scenes}
    for uid in list(_PREVIEWS):
        scene = scenes.get(uid)
        if scene is None:
            _release(_PREVIEWS.pop(uid))
            continue
        if not scene.crowd.preview_enabled:
            scene.crowd.preview_enabled = True
        pv = check(scene)
        _advance(scene, pv)
    if not _PREVIEWS:
        _remove_draw_handler()
    restore("after the undo")


@bpy.app.handlers.persistent
def on_load_pre(filepath="", *_):
    """Before a file load: stop every preview. Loading another file, or a new one, also
    drops every scene's :mod:`crowd_addon.api` handle (its callbacks were for this
    file's scenes); reloading this file (File > Revert, opening it again) keeps them."""
    from .crowd_script import forget_trusted_scripts
    stop_all()
    _ERRORS.clear()
    if not (bpy.data.filepath and filepath == bpy.data.filepath):
        api.forget_scenes()
    forget_trusted_scripts(unsaved_only=True)     # an unsaved file's trust ends with it


@bpy.app.handlers.persistent
def on_load_post(*_):
    """Rebuild the previews the loaded file had running (or whose crowd renders: Render
    Crowd follows the preview), or stop them with the reason (:func:`restore`)."""
    restore("after loading the file")


# -------------------------------------------------------------------------- drawing
def draw_scene(scene, view_matrix, projection_matrix) -> bool:
    """Draw the scene's crowd into the framebuffer bound now (:func:`.preview_draw.draw`);
    False when no preview runs or nothing was drawn."""
    pv = get(scene)
    return pv is not None and draw(pv, view_matrix, projection_matrix)


def _draw_callback():
    ctx = bpy.context
    rv3d = ctx.region_data
    if ctx.scene is None or rv3d is None:
        return
    draw_scene(ctx.scene, rv3d.view_matrix, rv3d.window_matrix)
