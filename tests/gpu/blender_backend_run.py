"""Runs ``backend_scenes`` with the Blender ``gpu`` backend, in its own process.

    python tests/gpu/blender_backend_run.py OUT.npz

Blender's GPU context and moderngl's standalone context do not share a thread
well (each makes its own context current), so the tests run this in a
subprocess: ``bpy`` is imported, the GPU initialised by one tiny Workbench
render (blender.headless_gpu), every scene run, and the arrays saved as
``<scene>/<gpu|ref>/<name>``. Also draws one scene the way a viewport draw
handler does (into a bound ``GPUOffScreen``, no clear of its own).
"""

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE, os.path.dirname(os.path.dirname(HERE))]

import backend_scenes as scenes  # noqa: E402
from crowd_addon.core.base.camera import frame_crowd  # noqa: E402

#: Exit status when Blender cannot get a GPU context here (the tests skip).
NO_GPU = 3


def viewport(make):
    """The image scene drawn into a bound framebuffer by a renderer without an image
    of its own (what a SpaceView3D draw handler does), against its own image. The
    framebuffer is sRGB (``SRGB8_A8``), as the viewport's overlay buffer that draw
    handlers draw into: it encodes on write what the renderer writes linear."""
    import gpu
    own = scenes.image(make)
    crowd = scenes.c.Crowd(scenes.c.make_config(M=8, agents=16, spacing=0.9))
    r = make(crowd, None)
    for _ in range(5):
        crowd.step()
        r.sync()
    w, h = scenes.SIZE
    colour = gpu.types.GPUTexture((w, h), format="SRGB8_A8")
    depth = gpu.types.GPUTexture((w, h), format="DEPTH_COMPONENT32F")
    framebuffer = gpu.types.GPUFrameBuffer(color_slots=(colour,), depth_slot=depth)
    with framebuffer.bind():
        gpu.state.viewport_set(0, 0, w, h)
        background = [((c + 0.055) / 1.055) ** 2.4 for c in (0.62, 0.66, 0.72)]  # linear
        framebuffer.clear(color=(*background, 1.0), depth=1.0)
        r.render(frame_crowd(crowd, aspect=w / h), clear=None)
    buf = colour.read()
    buf.dimensions = w * h * 4
    image = np.asarray(buf, np.float64).reshape(h, w, 4)[::-1]
    if image.max() <= 1.0:                        # read back as floats (decoded or not)
        image = image * 255.0
    return {"gpu/image": np.rint(image).astype(np.uint8), "ref/image": own["gpu/image"],
            "gpu/lod": r.plan.lists.lod, "ref/lod": own["gpu/lod"],
            "gpu/encoding": np.array(r.encoding_srgb)}


def main(path):
    import bpy  # noqa: F401  (Blender as a module; its gpu module comes with it)
    from crowd_addon.core import CrowdError
    from crowd_addon.gpu.blender_backend import BlenderGPURenderer
    from crowd_addon.blender.headless_gpu import init_headless_gpu
    try:
        init_headless_gpu()
    except CrowdError as e:
        print(f"no GPU for Blender here: {e}", file=sys.stderr)
        sys.exit(NO_GPU)

    def make(crowd, size):
        return BlenderGPURenderer(crowd.view, size=size)

    runs = {"streamed": lambda: scenes.streamed(make),
            "unique": lambda: scenes.unique(make),
            "transitions_cpu": lambda: scenes.transitions(make, "cpu"),
            "transitions_gpu": lambda: scenes.transitions(make, "gpu"),
            "lods": lambda: scenes.lods(make),
            "looks": lambda: scenes.looks(make),
            "many_influences": lambda: scenes.many_influences(make),
            "flat": lambda: scenes.wrapped(make, 16384),
            "wrapped": lambda: scenes.wrapped(make, 256),
            "image": lambda: scenes.image(make),
            "viewport": lambda: viewport(make)}
    out = {}
    for name, run in runs.items():
        out.update({f"{name}/{k}": v for k, v in run().items()})
    np.savez(path, **out)


if __name__ == "__main__":
    main(sys.argv[1])
