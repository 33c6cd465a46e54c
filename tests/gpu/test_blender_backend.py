"""The Blender ``gpu`` module backend against core and against the moderngl backend.

Oracles: core's CPU reference skinning (``Crowd.agent_rows`` + ``skin_vertices``)
for the vertices the backend's vertex stage produces (read back from an RGBA32F
target, one pixel per vertex: Blender's Python API has no transform feedback),
core's pose texture mirror and dirty rows for what each frame uploads, and the
moderngl backend's image of the same frame. Blender runs in a subprocess
(``blender_backend_run.py``): its GPU context and moderngl's must not share this
process's thread.
"""

import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import backend_scenes as scenes  # noqa: E402

RUNNER = os.path.join(HERE, "blender_backend_run.py")
NO_GPU = 3


@pytest.fixture(scope="module")
def blender(tmp_path_factory):
    """``blender(scene)`` -> ``{"gpu/...": ..., "ref/...": ...}`` from the Blender run."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("needs the bpy module (Blender as a Python module)")
    out = tmp_path_factory.mktemp("blender_backend") / "scenes.npz"
    proc = subprocess.run([sys.executable, RUNNER, str(out)], capture_output=True, text=True,
                          timeout=600)
    if proc.returncode == NO_GPU:
        pytest.skip(proc.stderr.strip().splitlines()[-1])
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = np.load(out)
    return lambda scene: {k.split("/", 1)[1]: data[k] for k in data.files
                          if k.startswith(scene + "/")}


def test_streamed_agents_match_cpu_skinning_and_only_dirty_rows_travel(blender, h):
    d = blender("streamed")
    for f in range(3):
        h.assert_close_relative(d[f"gpu/frame{f}"], d[f"ref/frame{f}"])
        np.testing.assert_array_equal(d[f"gpu/texture{f}"], d[f"ref/texture{f}"])
        # the dirty rows and a 4-byte row number each, never the whole texture
        assert d[f"gpu/bytes{f}"] == d[f"ref/rows{f}"] * (d["ref/row_bytes"] + 4)
        assert d[f"gpu/bytes{f}"] < d[f"ref/texture{f}"].nbytes / 4
    # agents 0, 5 and 7 moved or turned before frame 1: their three texels + row number
    assert [int(d[f"gpu/instance_bytes{f}"]) for f in range(3)] == [0, 3 * (48 + 4), 0]


def test_looking_agents_match_cpu_skinning_to_1e5(blender, h):
    """The look stage in Blender's vertex stage (gpu_shaders/look_at.glsl) against
    core's CPU skinning of the looked rows, frame by frame, within 1e-5 m."""
    d = blender("looks")
    for f in range(6):
        assert np.abs(d[f"gpu/frame{f}"] - d[f"ref/frame{f}"]).max() <= 1e-5
    # the looks' texels go up at the first sync and when looks change, not each frame
    sent = [int(d[f"gpu/look_bytes{f}"]) for f in range(6)]
    assert sent[1:4] == [0, 0, 0] and sent[4] > 0 and sent[5] == 0


def test_unique_agents_match_cpu_skinning(blender, h):
    d = blender("unique")
    h.assert_close_relative(d["gpu/unique"], d["ref/unique"])


@pytest.mark.parametrize("where", ["cpu", "gpu"])
def test_agents_mid_transition_match_cpu_skinning(blender, h, where):
    d = blender(f"transitions_{where}")
    for f in range(3):
        h.assert_close_relative(d[f"gpu/frame{f}"], d[f"ref/frame{f}"])
        # with GPU skinning the compute shader wrote the three streams' new rows, the
        # unique's and the four blending slots'
        assert d[f"gpu/skinned_rows{f}"] == (3 + 1 + 4 if where == "gpu" else 0)


def test_every_lod_is_skinned_like_its_mesh_on_the_cpu(blender, h):
    d = blender("lods")
    assert len([k for k in d if k.startswith("gpu/lod")]) == 4          # the card too
    for lod in range(4):
        h.assert_close_relative(d[f"gpu/lod{lod}"], d[f"ref/lod{lod}"])


def test_six_influences_match_cpu_skinning_with_all_six(blender, h):
    d = blender("many_influences")
    h.assert_close_relative(d["gpu/full"], d["ref/full"])
    assert d["gpu/influences"].tolist() == [6, 6, 6, 6]      # the far boxes too
    for lod in range(4):
        h.assert_close_relative(d[f"gpu/lod{lod}"], d[f"ref/lod{lod}"])


def test_wrapped_pose_texture_renders_identically(blender, h):
    flat, wrapped = blender("flat"), blender("wrapped")
    assert flat["gpu/blocks"] == 1 and wrapped["gpu/blocks"] == 3
    h.assert_close_relative(wrapped["gpu/all"], wrapped["ref/all"])
    np.testing.assert_array_equal(wrapped["gpu/all"], flat["gpu/all"])
    np.testing.assert_array_equal(wrapped["gpu/image"], flat["gpu/image"])


def _agreement(a, b, level=2):
    """Fraction of pixels whose channels all differ by at most ``level`` / 255."""
    return float((np.abs(a.astype(int) - b.astype(int)).max(-1) <= level).mean())


def test_same_frame_renders_like_the_moderngl_backend(blender, renderer):
    image = blender("image")["gpu/image"]
    ref = scenes.image(lambda crowd, size: renderer(crowd, size))
    reference = ref["gpu/image"]
    np.testing.assert_array_equal(blender("image")["gpu/lod"], ref["gpu/lod"])
    assert (reference[..., :3] != reference[0, 0, :3]).any(-1).mean() > 0.04  # agents show
    assert _agreement(image, reference) >= 0.995
    wrapped = blender("wrapped")["gpu/image"]
    assert _agreement(wrapped, scenes.wrapped(lambda crowd, size: renderer(crowd, size),
                                              256)["gpu/image"]) >= 0.995


def test_drawing_into_the_bound_framebuffer_like_a_draw_handler(blender):
    """Into the bound sRGB framebuffer of a viewport the renderer writes linear colours
    and the framebuffer encodes them: the image is its own image (which the shader
    encodes), to 8-bit rounding."""
    d = blender("viewport")
    assert not d["gpu/encoding"]
    diff = np.abs(d["gpu/image"].astype(int) - d["ref/image"].astype(int))
    assert diff.max() <= 1, diff.max()
    np.testing.assert_array_equal(d["gpu/lod"], d["ref/lod"])   # LOD from the bound viewport
