"""One GLSL source, two backends: moderngl sources and Blender create-info data
compile in their real compilers (Mesa through moderngl; Blender's gpu module)."""

import importlib.util
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from crowd_addon.core import CrowdError
from crowd_addon.gpu.assembler import GLSL_VERSION, blender_create_info, gl_sources
from crowd_addon.gpu.programs import (CROWD_DRAW, ROW_UPLOAD, SCENE_DRAW, SKIN_ROWS,
                                      WIDE_INPUTS, ProgramSpec, for_influences)

CROWD_DRAW_WIDE = for_influences(CROWD_DRAW, 7)
DEFINES = {CROWD_DRAW.name: {"INFLUENCES": 2, "SHADOWS": 1, "ENCODE_SRGB": 1},
           SKIN_ROWS.name: {"MAX_BONES": 30}, ROW_UPLOAD.name: {},
           CROWD_DRAW_WIDE.name: {"INFLUENCES": 7, "SHADOWS": 1, "ENCODE_SRGB": 1},
           SCENE_DRAW.name: {"SHADOWS": 1, "ENCODE_SRGB": 1}}


def test_programs_for_more_than_four_influences_declare_the_second_pair():
    assert for_influences(CROWD_DRAW, 4) is CROWD_DRAW
    assert CROWD_DRAW_WIDE.vertex_in == CROWD_DRAW.vertex_in + WIDE_INPUTS
    assert CROWD_DRAW_WIDE.name == "crowd_draw_wide" and for_influences(CROWD_DRAW, 8) is \
        CROWD_DRAW_WIDE


@pytest.mark.parametrize("spec", [CROWD_DRAW, CROWD_DRAW_WIDE, SKIN_ROWS, ROW_UPLOAD,
                                  SCENE_DRAW],
                         ids=lambda s: s.name)
def test_gl_sources_compile_and_expose_every_declaration(gl, spec):
    src = gl_sources(spec, DEFINES[spec.name])
    assert all(text.startswith(GLSL_VERSION + "\n") for text in src.values())
    if "compute_shader" in src:
        program = gl.compute_shader(src["compute_shader"])
    else:
        program = gl.program(**src)
    names = set(program)
    declared = [n for _, n in spec.push_constants] + [n for *_, n in spec.samplers]
    declared += [n for *_, n in spec.vertex_in] + [img[3] for img in spec.images]
    assert set(declared) <= names
    program.release()


def test_blender_info_has_no_version_and_one_call_per_declaration():
    info = blender_create_info(CROWD_DRAW, DEFINES[CROWD_DRAW.name])
    methods = [m for m, _, _ in info.calls]
    assert methods.count("push_constant") == len(CROWD_DRAW.push_constants)
    assert methods.count("sampler") == len(CROWD_DRAW.samplers)
    assert methods.count("vertex_in") == len(CROWD_DRAW.vertex_in)
    assert ("define", ("INFLUENCES", "2"), {}) in info.calls
    sources = [args[0] for m, args, _ in info.calls if m.endswith("_source")]
    assert len(sources) == 2 and not any("#version" in s for s in sources)
    # the same files, byte for byte, in both backends
    gl = gl_sources(CROWD_DRAW, DEFINES[CROWD_DRAW.name])
    assert gl["vertex_shader"].endswith(sources[0])
    assert gl["fragment_shader"].endswith(sources[1])


def test_missing_define_and_source_are_named():
    with pytest.raises(CrowdError, match="MAX_BONES"):
        gl_sources(SKIN_ROWS)
    with pytest.raises(CrowdError, match="nope.glsl"):
        gl_sources(ProgramSpec("broken", compute=("nope.glsl",), local_group_size=(1,)))


@pytest.mark.skipif(importlib.util.find_spec("bpy") is None, reason="bpy not installed")
def test_programs_compile_in_blenders_gpu_module():
    """Blender's own GLSL front end (GPUShaderCreateInfo -> create_from_info), in a
    subprocess so its GL context never meets this process's."""
    script = textwrap.dedent("""
        import bpy, gpu
        scene = bpy.context.scene
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x = scene.render.resolution_y = 8
        bpy.ops.render.render()           # initialises the GPU in background mode
        from crowd_addon.gpu.assembler import blender_create_info
        from crowd_addon.gpu.programs import (CROWD_DRAW, ROW_UPLOAD, SCENE_DRAW, SKIN_ROWS,
                                              for_influences)
        for spec, defines in ((CROWD_DRAW, {"INFLUENCES": 4, "SHADOWS": 0, "ENCODE_SRGB": 0}),
                              (CROWD_DRAW, {"INFLUENCES": 4, "SHADOWS": 1, "ENCODE_SRGB": 1}),
                              (for_influences(CROWD_DRAW, 8), {"INFLUENCES": 8, "SHADOWS": 1,
                                                               "ENCODE_SRGB": 1}),
                              (SCENE_DRAW, {"SHADOWS": 1, "ENCODE_SRGB": 0}),
                              (SKIN_ROWS, {"MAX_BONES": 30}), (ROW_UPLOAD, {})):
            gpu.shader.create_from_info(blender_create_info(spec, defines).build(gpu))
            print("compiled", spec.name)
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=240, cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert done.stdout.count("compiled") == 6
