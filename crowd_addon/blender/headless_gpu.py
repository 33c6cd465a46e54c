"""Blender's ``gpu`` module in background mode (``bpy`` as a Python module, or
``blender -b``): it refuses to draw until the GPU has been initialised, which one tiny
render does. Call :func:`init_headless_gpu` before making a ``gpu``-module renderer
headless (``crowd preview --backend blender`` does)."""

from __future__ import annotations

import bpy

from ..core.errors import CrowdError

__all__ = ["init_headless_gpu"]

_READY = {"gpu": False}


def init_headless_gpu() -> None:
    """Make Blender's ``gpu`` module usable in background mode: one
    8 x 8 Workbench render of a temporary scene, removed afterwards. Does nothing in
    a Blender with a UI, or when already done in this process."""
    if _READY["gpu"] or not bpy.app.background:
        return
    scene = bpy.data.scenes.new("crowd_gpu_init")
    cam = bpy.data.objects.new("crowd_gpu_init", bpy.data.cameras.new("crowd_gpu_init"))
    try:
        scene.collection.objects.link(cam)
        scene.camera = cam
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x = scene.render.resolution_y = 8
        bpy.ops.render.render(scene=scene.name)
    except RuntimeError as e:
        raise CrowdError(f"Blender gpu backend: the initialising render failed ({e})") from None
    finally:
        data = cam.data
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(data)
        bpy.data.scenes.remove(scene)
    _READY["gpu"] = True
