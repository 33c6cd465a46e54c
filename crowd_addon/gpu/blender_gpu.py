"""Plumbing of the Blender ``gpu`` backend (:mod:`.blender_backend`): headless start,
its extra shader programs, a program cache, float textures from numpy.

Blender's Python ``gpu`` module creates textures only from float data and has no
transform feedback, so that backend needs two small programs the moderngl backend
does not, declared here like :mod:`.programs` and assembled from ``gpu_shaders/`` by
:func:`.assembler.blender_create_info`: :data:`UPLOAD_INTS` (an R32F block copied
into an R32I texture: draw lists, row numbers for :data:`~.programs.ROW_UPLOAD`)
and :data:`CROWD_CAPTURE` (the crowd's vertex computed by the same library calls as
``crowd_vert.glsl``, drawn as a point on its own pixel of an RGBA32F target).

Nothing here imports ``bpy`` or ``gpu`` at import time; functions take Blender's
``gpu`` module as an argument or import it when called.
"""

from __future__ import annotations

import numpy as np

from .assembler import blender_create_info
from .programs import CROWD_DRAW, UPLOAD_GROUP, ProgramSpec

__all__ = ["UPLOAD_INTS", "CROWD_CAPTURE", "program", "use_program",
           "float_texture", "read_buffer", "set_if_used"]

#: An R32F block (exact integers below 2**24) written into an R32I texture at
#: ``u_offset``.
UPLOAD_INTS = ProgramSpec(
    name="upload_ints",
    compute=("upload_ints_comp.glsl",),
    push_constants=(("IVEC2", "u_offset"),),
    samplers=((0, "FLOAT_2D", "source_tex"),),
    images=((0, "R32I", "INT_2D", "target_img", ("WRITE",)),),
    local_group_size=(UPLOAD_GROUP, 1),
)

#: The crowd's vertex moved to pixel (vertex, instance); no light (push constants
#: stay within the 128 bytes every backend guarantees).
CROWD_CAPTURE = ProgramSpec(
    name="crowd_capture",
    vertex=CROWD_DRAW.vertex[:-1] + ("capture_vert.glsl",),
    fragment=("capture_frag.glsl",),
    vertex_in=CROWD_DRAW.vertex_in,
    interfaces=CROWD_DRAW.interfaces,
    push_constants=tuple(p for p in CROWD_DRAW.push_constants if p[1] != "u_light")
    + (("IVEC2", "u_capture_size"),),
    samplers=CROWD_DRAW.samplers,
    fragment_out=CROWD_DRAW.fragment_out,
    defines=CROWD_DRAW.defines,
)

_PROGRAMS = {}          # (program, defines) -> GPUShader, compiled once a process


def program(gpu, spec: ProgramSpec, defines: dict | None = None):
    """``spec`` compiled with ``defines`` into a ``gpu.types.GPUShader``, shared by
    every renderer of the process (compiled once, never freed: see
    :func:`use_program`)."""
    key = (spec.name, tuple(sorted((defines or {}).items())))
    if key not in _PROGRAMS:
        info = blender_create_info(spec, defines).build(gpu)
        _PROGRAMS[key] = gpu.shader.create_from_info(info)
    return _PROGRAMS[key]


def use_program(gpu, shader) -> None:
    """Make ``shader`` current. Blender skips a bind when its context's current shader
    has the same address, and a freed shader's address can be reused by a new one,
    which would leave the old GL program in use: unbinding first makes the bind real."""
    gpu.shader.unbind()
    shader.bind()


def float_texture(gpu, image, fmt: str = "RGBA32F"):
    """A ``GPUTexture`` holding ``image`` ``(H, W, C)`` (converted to float32)."""
    flat = np.ascontiguousarray(image, np.float32).reshape(-1)
    return gpu.types.GPUTexture((image.shape[1], image.shape[0]), format=fmt,
                                data=gpu.types.Buffer("FLOAT", flat.size, flat))


def read_buffer(buffer, dtype) -> np.ndarray:
    """A ``gpu.types.Buffer`` as a flat numpy array (its exported strides are not C
    order, so it is flattened first)."""
    buffer.dimensions = int(np.prod(buffer.dimensions))
    return np.frombuffer(buffer, dtype).copy()


def set_if_used(setter, name: str, value) -> None:
    """``setter(name, value)`` unless the GLSL compiler dropped ``name`` (unused in
    that program, e.g. the capture program has no view matrix)."""
    try:
        setter(name, value)
    except ValueError:
        pass
