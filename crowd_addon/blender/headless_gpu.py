"""Blender's ``gpu`` module in background mode (``bpy`` as a Python module, or
``blender -b``): it refuses to draw until the GPU has been initialised, which one tiny
render does. Call :func:`init_headless_gpu` before making a ``gpu``-module renderer
headless (``crowd preview --backend blender`` does).

On a headless EGL display (Mesa) Blender tries EGL configurations until one fits and
reports each refusal on stderr (``EGL Error (0x3009): EGL_BAD_MATCH: ...``), though it
then draws. Those lines are kept off the console; any other output goes through.
"""

from __future__ import annotations

import contextlib
import re
import sys
import tempfile

import bpy

from ..core.base.errors import CrowdError
from .c_output import fd_redirected

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
        with _without_egl_mismatches():
            bpy.ops.render.render(scene=scene.name)
    except RuntimeError as e:
        raise CrowdError(f"Blender gpu backend: the initialising render failed ({e})") from None
    finally:
        data = cam.data
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(data)
        bpy.data.scenes.remove(scene)
    _READY["gpu"] = True


#: Blender's report of an EGL configuration it tried and let go (GHOST's EGL context)
_EGL_MISMATCH = re.compile(r"^EGL Error \(0x3009\): EGL_BAD_MATCH\b")


@contextlib.contextmanager
def _without_egl_mismatches():
    """For the ``with`` block, the process's stderr (file descriptor 2, where Blender's
    C code writes) goes to a temporary file; afterwards every line of it but
    :data:`_EGL_MISMATCH` goes on to the real stderr."""
    with tempfile.TemporaryFile() as caught:
        try:
            with fd_redirected(2, caught.fileno()):
                yield
        finally:
            caught.seek(0)
            kept = [line for line in caught.read().decode("utf-8", "replace")
                    .splitlines(keepends=True) if not _EGL_MISMATCH.match(line)]
            if kept:
                sys.stderr.write("".join(kept))
                sys.stderr.flush()

