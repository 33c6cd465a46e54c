"""Register and unregister everything the extension adds to Blender.

:func:`register` adds the property groups (``Scene.crowd``), operators, UI lists and
panels, the File > Export and File > Import menu entries, the ``crowd`` command of
Blender's ``-c`` option (:mod:`.cli_commands`), and the app handlers the preview needs (file load, frame
change, depsgraph update, undo/redo; all persistent so they survive file loads). The
viewport draw handler exists only while a preview runs; the bake's modal timer only
while it bakes. Once registered it restarts the previews the open file's flags ask for
(``preview.restore``, as opening the file does): disabling the extension leaves each
scene's ``preview_enabled`` and ``render_crowd`` and any Render Crowd data in the file as
they are, and enabling it again brings their crowds back to life instead of leaving the
render data frozen. :func:`unregister` stops every preview (removing the draw handler)
and takes all of it away again, so register/unregister can alternate any number of times.
:func:`leftovers` lists anything of ours still registered (tests use it).
"""

from __future__ import annotations

import bpy

from .. import api
from . import (cli_commands, export, import_usd, list_operators, operators, panels, prefs,
               preview, props, seats_operator, show_panels)

__all__ = ["CLASSES", "HANDLERS", "MENUS", "register", "unregister", "leftovers"]

CLASSES = (props.CLASSES + operators.CLASSES + list_operators.CLASSES + seats_operator.CLASSES
           + export.CLASSES + import_usd.CLASSES + panels.CLASSES + show_panels.CLASSES
           + prefs.CLASSES)
MENUS = export.MENUS + import_usd.MENUS    # (menu type name, draw function)
HANDLERS = (("load_pre", preview.on_load_pre), ("load_post", preview.on_load_post),
            ("frame_change_post", preview.on_frame_change),
            ("depsgraph_update_post", preview.on_depsgraph_update),
            ("undo_post", preview.on_undo), ("redo_post", preview.on_undo))


def _ours(fn, wanted) -> bool:
    """Same function, or the same function of an earlier import of this module (an
    extension reload brings new function objects)."""
    return fn is wanted or (getattr(fn, "__module__", None) == wanted.__module__
                            and getattr(fn, "__qualname__", None) == wanted.__qualname__)


def register(restore: bool = True):
    """Register everything (the module docstring). ``restore`` False: the open file's
    previews are not restarted (a ``crowd`` command that opened a .blend and builds
    its crowd itself: starting them would bake it a second time)."""
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.crowd = bpy.props.PointerProperty(type=props.CROWD_PG_settings)
    for name, fn in HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        for old in [h for h in handlers if _ours(h, fn)]:
            handlers.remove(old)
        handlers.append(fn)
    for menu, fn in MENUS:
        _remove_menu_entries(menu, fn)
        getattr(bpy.types, menu).append(fn)
    cli_commands.register_command()
    api.set_context_scene(_context_scene_name, preview.follow_renames)
    if restore and isinstance(bpy.data, bpy.types.BlendData):   # at start: load_post does
        preview.restore("when the extension was enabled")


def unregister():
    cli_commands.unregister_command()
    preview.stop_all()
    api.detach_all()
    api.set_context_scene(None)
    for menu, fn in MENUS:
        _remove_menu_entries(menu, fn)
    for name, fn in HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        for old in [h for h in handlers if _ours(h, fn)]:
            handlers.remove(old)
    if hasattr(bpy.types.Scene, "crowd"):
        del bpy.types.Scene.crowd
    for cls in reversed(CLASSES):
        if cls.is_registered:
            bpy.utils.unregister_class(cls)


def _context_scene_name():
    """The context scene's name (for :mod:`crowd_addon.api` calls that name none)."""
    scene = bpy.context.scene
    return None if scene is None else scene.name


def _menu_entries(menu, fn) -> list:
    """Our draw functions (this import's or an earlier one's) in a menu."""
    cls = getattr(bpy.types, menu)
    if not cls.is_extended():
        return []
    return [f for f in cls._dyn_ui_initialize() if _ours(f, fn)]


def _remove_menu_entries(menu, fn):
    for old in _menu_entries(menu, fn):
        getattr(bpy.types, menu).remove(old)


def leftovers() -> list:
    """Descriptions of anything of ours still registered: classes, ``Scene.crowd``,
    app handlers, menu entries, the draw handler, the ``crowd`` CLI command."""
    out = [f"class {c.__name__}" for c in CLASSES if c.is_registered]
    out += [f"bpy.types.{c.__name__}" for c in CLASSES if hasattr(bpy.types, c.__name__)]
    if hasattr(bpy.types.Scene, "crowd"):
        out.append("Scene.crowd")
    for name, fn in HANDLERS:
        out += [f"handler {name}: {h.__qualname__}" for h in getattr(bpy.app.handlers, name)
                if _ours(h, fn)]
    for menu, fn in MENUS:
        out += [f"menu {menu}: {f.__qualname__}" for f in _menu_entries(menu, fn)]
    if preview.draw_handle() is not None:
        out.append("SpaceView3D draw handler")
    if cli_commands.command_registered():
        out.append("CLI command crowd")
    return out
