"""Which renderer draws a crowd: :func:`make_renderer`, the one place a backend is
chosen (``crowd preview``, the viewport preview, the benchmarks).

Importing this module imports neither moderngl nor Blender's modules; the chosen
backend is imported when a renderer is made.
"""

from __future__ import annotations

from ..core.base.errors import CrowdError

__all__ = ["BACKENDS", "make_renderer"]

#: Backends that render headless into an image of their own (``crowd preview
#: --backend``); :func:`make_renderer` also takes ``"viewport"``.
BACKENDS = ("moderngl", "blender")


def make_renderer(view, backend: str = "moderngl", size=(640, 360), **kwargs):
    """A renderer (:class:`~.renderer.CrowdRenderer`) of the crowd behind ``view``
    (``crowd.view``).

    ``backend``:

    * ``"moderngl"``: moderngl in a headless EGL context of its own (Mesa llvmpipe
      needs no GPU), drawing into an offscreen image of ``size`` (width, height);
    * ``"blender"``: Blender's ``gpu`` module, with an offscreen image of ``size``, or
      None to draw only into the framebuffer bound at render time; in background mode
      (the ``bpy`` module, ``blender -b``) call
      ``crowd_addon.blender.headless_gpu.init_headless_gpu()`` first;
    * ``"viewport"``: inside the GPU context of Blender's viewport drawing now: the
      moderngl renderer attached to it when Blender draws with OpenGL (draw into
      ``renderer.ctx.detect_framebuffer()``), else the ``gpu``-module renderer
      drawing into the bound framebuffer; ``size`` is not used.

    ``kwargs`` go to the renderer (``light``, ``culling``). A missing package or GPU
    is a CrowdError naming it.
    """
    if backend == "moderngl":
        return _moderngl().standalone(view, size, **kwargs)
    if backend == "blender":
        try:
            import gpu  # noqa: F401  (Blender's module: bpy or a Blender process)
        except ImportError:
            raise CrowdError("backend blender needs Blender's gpu module: run inside "
                             "Blender, or with the bpy module call crowd_addon.blender."
                             "headless_gpu.init_headless_gpu() first") from None
        from .blender_backend import BlenderGPURenderer
        return BlenderGPURenderer(view, size, **kwargs)
    if backend == "viewport":
        import gpu
        kind = gpu.platform.backend_type_get()
        if kind == "OPENGL":
            return _moderngl().attach(view, size=(4, 4), **kwargs)
        from .blender_backend import BlenderGPURenderer
        return BlenderGPURenderer(view, None, **kwargs)
    raise CrowdError(f"unknown backend {backend!r} (choose from "
                     f"{', '.join(BACKENDS + ('viewport',))})")


def _moderngl():
    try:
        import moderngl  # noqa: F401  (the backend imports it when a renderer is made)

        from .moderngl_backend import ModernGLRenderer
    except ImportError as e:
        raise CrowdError(f"backend moderngl needs the moderngl package ({e})") from None
    return ModernGLRenderer
