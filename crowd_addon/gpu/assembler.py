"""Shader sources for each backend, assembled from one description.

:func:`gl_sources` gives complete GLSL 4.30 stages for moderngl (``#version``,
defines, then ``layout``-qualified declarations of everything in the
:class:`~.programs.ProgramSpec`, then the ``gpu_shaders/`` files).
:func:`blender_create_info` gives the same program as plain data: the ordered
``GPUShaderCreateInfo`` calls Blender's ``gpu`` module needs (no ``#version``,
declarations by calls) and :meth:`BlenderShaderInfo.build` replays them on a
``gpu`` module passed in, so this module never imports ``bpy`` or ``gpu``.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.base.errors import CrowdError
from .programs import SHADER_DIR, ProgramSpec

__all__ = ["GLSL_VERSION", "read_sources", "gl_sources", "BlenderShaderInfo",
           "blender_create_info"]

GLSL_VERSION = "#version 430 core"

_TYPES = {"FLOAT": "float", "VEC2": "vec2", "VEC3": "vec3", "VEC4": "vec4",
          "MAT3": "mat3", "MAT4": "mat4", "UINT": "uint", "UVEC2": "uvec2",
          "UVEC3": "uvec3", "UVEC4": "uvec4", "INT": "int", "IVEC2": "ivec2",
          "IVEC3": "ivec3", "IVEC4": "ivec4", "BOOL": "bool"}
_SAMPLERS = {"FLOAT_2D": "sampler2D", "INT_2D": "isampler2D", "UINT_2D": "usampler2D",
             "FLOAT_BUFFER": "samplerBuffer", "INT_BUFFER": "isamplerBuffer"}
_IMAGES = {"FLOAT_2D": "image2D", "INT_2D": "iimage2D", "UINT_2D": "uimage2D"}
_QUALIFIERS = {("WRITE",): "writeonly ", ("READ",): "readonly ", ("READ", "WRITE"): "",
               ("NO_RESTRICT",): ""}
_INTERP = {"smooth": "smooth", "flat": "flat", "no_perspective": "noperspective"}


def _glsl(table, key, what):
    try:
        return table[key]
    except KeyError:
        raise CrowdError(f"shader assembler: unsupported {what} {key!r}") from None


def read_sources(files) -> str:
    """The ``gpu_shaders/`` files concatenated, each introduced by its name."""
    parts = []
    for name in files:
        path = SHADER_DIR / name
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as e:
            raise CrowdError(f"shader source {path}: cannot read it ({e.strerror})") from None
        parts.append(f"/* ---- {name} ---- */\n{text}")
    return "\n".join(parts)


def _check_defines(spec: ProgramSpec, defines: dict) -> dict:
    missing = [d for d in spec.defines if d not in defines]
    if missing:
        raise CrowdError(f"shader program {spec.name!r}: needs values for {missing}")
    return {str(k): str(v) for k, v in defines.items()}


def gl_sources(spec: ProgramSpec, defines: dict | None = None) -> dict:
    """``{"vertex_shader"|"fragment_shader"|"compute_shader": GLSL text}`` for moderngl."""
    defs = _check_defines(spec, defines or {})
    head = [GLSL_VERSION] + [f"#define {k} {v}" for k, v in defs.items()]
    common = [f"uniform {_glsl(_TYPES, t, 'type')} {n};" for t, n in spec.push_constants]
    common += [f"layout(binding = {s}) uniform {_glsl(_SAMPLERS, t, 'sampler type')} {n};"
               for s, t, n in spec.samplers]
    common += [f"layout(std430, binding = {s}) "
               f"{_glsl(_QUALIFIERS, tuple(sorted(q)), 'buffer qualifiers')}buffer "
               f"{n}_block {{ {_glsl(_TYPES, t, 'type')} {n}[]; }};"
               for s, t, n, q in spec.storage_buffers]
    out = {}
    for stage, files in spec.stages().items():
        decl = list(common)
        if stage == "vertex":
            decl += [f"layout(location = {s}) in {_glsl(_TYPES, t, 'type')} {n};"
                     for s, t, n in spec.vertex_in]
            decl += [f"{_INTERP[q]} out {_glsl(_TYPES, t, 'type')} {n};"
                     for iface in spec.interfaces for q, t, n in iface.members]
        elif stage == "fragment":
            decl += [f"{_INTERP[q]} in {_glsl(_TYPES, t, 'type')} {n};"
                     for iface in spec.interfaces for q, t, n in iface.members]
            decl += [f"layout(location = {s}) out {_glsl(_TYPES, t, 'type')} {n};"
                     for s, t, n in spec.fragment_out]
        else:
            size = (tuple(spec.local_group_size) + (1, 1))[:3]
            decl.insert(0, "layout(local_size_x = {}, local_size_y = {}, local_size_z = {}) "
                        "in;".format(*size))
            decl += [f"layout(binding = {s}, {fmt.lower()}) uniform "
                     f"{_glsl(_QUALIFIERS, tuple(sorted(q)), 'image qualifiers')}"
                     f"{_glsl(_IMAGES, t, 'image type')} {n};"
                     for s, fmt, t, n, q in spec.images]
        out[f"{stage}_shader"] = "\n".join(head + decl) + "\n" + read_sources(files)
    return out


@dataclass(frozen=True)
class BlenderShaderInfo:
    """A ``GPUShaderCreateInfo`` as data.

    ``interfaces``: ``(name, ((qualifier, type, name), ...))`` per
    ``GPUStageInterfaceInfo``; ``calls``: ``(method, args, kwargs)`` in order, where
    a ``vertex_out`` call names its interface.
    """

    name: str
    interfaces: tuple
    calls: tuple

    def build(self, gpu):
        """The ``gpu.types.GPUShaderCreateInfo`` (``gpu`` is Blender's module); pass
        it to ``gpu.shader.create_from_info``."""
        blocks = {}
        for name, members in self.interfaces:
            block = gpu.types.GPUStageInterfaceInfo(name)
            for qualifier, type_, member in members:
                getattr(block, qualifier)(type_, member)
            blocks[name] = block
        info = gpu.types.GPUShaderCreateInfo()
        for method, args, kwargs in self.calls:
            if method == "vertex_out":
                args = (blocks[args[0]],)
            getattr(info, method)(*args, **kwargs)
        return info


def blender_create_info(spec: ProgramSpec, defines: dict | None = None) -> BlenderShaderInfo:
    """The create-info calls for Blender's ``gpu`` module (sources without ``#version``)."""
    if spec.storage_buffers:
        raise CrowdError(f"shader program {spec.name!r}: Blender's gpu module declares no "
                         f"storage buffers; it is a moderngl program")
    defs = _check_defines(spec, defines or {})
    calls = [("define", (k, v), {}) for k, v in defs.items()]
    calls += [("push_constant", (t, n), {}) for t, n in spec.push_constants]
    calls += [("sampler", (s, t, n), {}) for s, t, n in spec.samplers]
    calls += [("image", (s, fmt, t, n), {"qualifiers": set(q)})
              for s, fmt, t, n, q in spec.images]
    calls += [("vertex_in", (s, t, n), {}) for s, t, n in spec.vertex_in]
    calls += [("vertex_out", (iface.name,), {}) for iface in spec.interfaces]
    calls += [("fragment_out", (s, t, n), {}) for s, t, n in spec.fragment_out]
    if spec.local_group_size:
        calls.append(("local_group_size", tuple(spec.local_group_size), {}))
    for stage, files in spec.stages().items():
        calls.append((f"{stage}_source", (read_sources(files),), {}))
    interfaces = tuple((i.name, tuple(i.members)) for i in spec.interfaces)
    return BlenderShaderInfo(spec.name, interfaces, tuple(calls))
