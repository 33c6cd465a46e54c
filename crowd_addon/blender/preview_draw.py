"""The viewport preview's drawing: a running :class:`.preview.Preview`'s crowd drawn
into the framebuffer the 3D view has bound, through the view's matrices.

The renderer is made on the first draw (``crowd_addon.gpu.backends.make_renderer(view,
"viewport")`` chooses): the moderngl renderer in Blender's OpenGL context, the
``gpu``-module renderer on Metal or Vulkan. When it cannot be made or draw,
``Preview.draw_error`` says why (the panel shows it) and drawing stops.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from . import shared_gl

log = logging.getLogger("crowd_addon.preview")

__all__ = ["draw", "release_renderer"]


@dataclass(frozen=True)
class _ViewCamera:
    """What a renderer needs of a camera: ``view_projection`` (4, 4) world -> clip, kept
    as tuples so that equal views compare equal (renderers redo per-view work only
    when the view changes)."""

    matrix: tuple

    @property
    def view_projection(self) -> np.ndarray:
        return np.array(self.matrix, np.float64)


def draw(pv, view_matrix, projection_matrix) -> bool:
    """Draw the preview's crowd into the framebuffer bound now, seen through the 4x4
    world->view and view->clip matrices; returns whether anything was drawn. Errors
    are kept in ``pv.draw_error`` and stop further drawing (never raised)."""
    if pv.draw_error or pv.crowd.agents.count == 0:
        return False
    t0 = time.perf_counter()
    try:
        if pv.renderer is None:
            from ..gpu.backends import make_renderer
            pv.renderer = make_renderer(pv.crowd.view, "viewport")
        view = np.array(view_matrix, np.float64)
        cam = _ViewCamera(tuple(map(tuple, (np.array(projection_matrix, np.float64)
                                            @ view).tolist())))
        pv.renderer.sync()
        mgl = getattr(pv.renderer, "ctx", None)
        if mgl is None:
            pv.renderer.render(cam, target=None, clear=None)
        else:
            shared = shared_gl.shared_context()
            shared.before(mgl)
            pv.renderer.render(cam, target=mgl.detect_framebuffer(), clear=None)
            shared.after()
    except Exception as e:  # noqa: BLE001 - a draw callback must never raise
        pv.draw_error = f"cannot draw: {e}"
        release_renderer(pv)
        return False
    pv.draw_ms = (time.perf_counter() - t0) * 1e3
    return True


def release_renderer(pv) -> None:
    """Free the preview's renderer (a new one is made on the next draw)."""
    if pv.renderer is not None:
        renderer, pv.renderer = pv.renderer, None
        try:
            renderer.release()
        except Exception as e:  # noqa: BLE001 - the GPU context may be gone already
            log.warning("crowd preview of %r: renderer release failed: %s", pv.scene_name, e)
