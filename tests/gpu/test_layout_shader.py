"""gpu_shaders/block_layout.glsl and pose_layout.glsl, run in compute shaders,
against core's layout (PoseStorage.texel_of_row, texture_image) and exact integer
arithmetic; the row upload shader Blender's backend writes dirty rows with."""

import moderngl
import numpy as np
import pytest

from crowd_addon.core import PoseStorage
from crowd_addon.gpu.assembler import gl_sources
from crowd_addon.gpu.instances import InstanceData
from crowd_addon.gpu.programs import ROW_UPLOAD, UPLOAD_GROUP, ProgramSpec
from crowd_addon.gpu.texture_region import stage_rows

PROBE = """
layout(std430, binding = 0) buffer Result { ivec4 result[]; };
layout(std430, binding = 1) buffer Input { ivec2 operands[]; };
uniform int u_count;
void main()
{
  int i = int(gl_GlobalInvocationID.x);
  if (i < u_count) {
    result[i] = ivec4(pose_texel(operands[i].x, 3), divmod(operands[i].x, operands[i].y));
  }
}
"""


def run_probe(gl, storage, operands):
    spec = ProgramSpec("layout_probe", compute=("block_layout.glsl", "pose_layout.glsl"),
                       push_constants=(("IVEC4", "u_pose_layout"),),
                       local_group_size=(64,))
    program = gl.compute_shader(gl_sources(spec)["compute_shader"] + PROBE)
    program["u_pose_layout"].value = (storage.height, storage.row_texels, storage.M, storage.S)
    program["u_count"].value = len(operands)
    out = gl.buffer(reserve=len(operands) * 16)
    inp = gl.buffer(np.ascontiguousarray(operands, np.int32).tobytes())
    out.bind_to_storage_buffer(0)
    inp.bind_to_storage_buffer(1)
    program.run(-(-len(operands) // 64))
    result = np.frombuffer(out.read(), np.int32).reshape(-1, 4)
    for obj in (program, out, inp):
        obj.release()
    return result


@pytest.mark.parametrize("max_size", [256, 16384])
def test_pose_texel_mirrors_texel_of_row(gl, max_size):
    storage = PoseStorage(streams=24, max_offset=30, uniques=5, slots=17, bones=24,
                          max_texture_size=max_size)
    rows = np.arange(storage.row_count)
    result = run_probe(gl, storage, np.c_[rows, np.ones_like(rows)])
    x, y = storage.texel_of_row(rows)
    np.testing.assert_array_equal(result[:, 0], x + 3)
    np.testing.assert_array_equal(result[:, 1], y)


def test_divmod_is_exact_up_to_2_pow_24(gl):
    rng = np.random.default_rng(0)
    b = np.concatenate([[1, 2, 3, 7, 72, 256, 16383, 16384], rng.integers(1, 20000, 4000)])
    a = np.concatenate([rng.integers(0, 2 ** 24, b.size),
                        (rng.integers(0, 1000, b.size) * b - 1).clip(0)])   # just below b * q
    b = np.concatenate([b, b])
    storage = PoseStorage(1, 1, 0, 0, 1)
    result = run_probe(gl, storage, np.c_[a, b])
    np.testing.assert_array_equal(result[:, 2], a // b)
    np.testing.assert_array_equal(result[:, 3], a % b)


def upload_rows(gl, program, texture, block_rows, regions):
    """What a backend without partial texture writes does: stage, then scatter."""
    staging, rows = stage_rows(regions)
    if rows.size == 0:
        return 0
    stage = gl.texture((staging.shape[1], staging.shape[0]), 4, staging.tobytes(), dtype="f4")
    index = gl.texture((rows.size, 1), 1, rows.tobytes(), dtype="i4")
    for tex in (stage, index):
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    stage.use(0)
    index.use(1)
    texture.bind_to_image(0, read=False, write=True)
    program["u_upload"].value = (block_rows, staging.shape[1], rows.size, 0)
    program.run(-(-staging.shape[1] // UPLOAD_GROUP), rows.size)
    gl.memory_barrier()
    stage.release()
    index.release()
    return staging.nbytes


def test_row_upload_shader_keeps_pose_and_agent_textures_equal_to_core(gl, h):
    crowd = h.Crowd(h.make_config(M=24, streams=24, NT=8, agents=40, max_texture_size=256))
    st = crowd.storage
    assert st.blocks == 3
    program = gl.compute_shader(gl_sources(ROW_UPLOAD)["compute_shader"])
    pose = gl.texture((st.width, st.height), 4, dtype="f4")
    agents = InstanceData(crowd.view, max_texture_size=16)
    agent_tex = gl.texture((agents.width, agents.height), 4, agents.texture_image().tobytes(),
                           dtype="f4")                      # created whole, updated by rows
    upload_rows(gl, program, pose, st.height, crowd.view.take_upload_regions())    # all rows
    for i in range(5):
        if i == 2:
            crowd.transition_to_unique([3, 30], "u0", 4)
        crowd.step()
        sent = upload_rows(gl, program, pose, st.height, crowd.view.take_upload_regions())
        rows = crowd.streams.count + crowd.uniques.count + int(crowd.slots.active.sum())
        assert sent == rows * st.row_bytes
        sent = upload_rows(gl, program, agent_tex, agents.block_rows, agents.update(crowd.view))
        assert sent == (2 * 48 if i == 2 else 0)        # the two agents that changed
    np.testing.assert_array_equal(np.frombuffer(pose.read(), np.float32).reshape(
        st.height, st.width, 4), st.texture_image())
    np.testing.assert_array_equal(np.frombuffer(agent_tex.read(), np.float32).reshape(
        agents.height, agents.width, 4), agents.texture_image())
    for obj in (program, pose, agent_tex):
        obj.release()
