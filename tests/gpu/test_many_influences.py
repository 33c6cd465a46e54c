"""A proxy with six bone influences a vertex skinned by the moderngl backend's vertex
stage (read back by transform feedback) against core's CPU skinning with all six
(``backend_scenes.many_influences``; the Blender ``gpu`` backend runs the same scene in
test_blender_backend.py)."""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import backend_scenes as scenes  # noqa: E402


def test_six_influences_match_cpu_skinning_with_all_six(h, renderer):
    d = scenes.many_influences(lambda crowd, size: renderer(crowd))
    h.assert_close_relative(d["gpu/full"], d["ref/full"])
    # the full mesh, its two LODs and the far boxes (their corners skinned like the
    # part's nearest vertex) use six bones a vertex
    assert d["gpu/influences"].tolist() == [6, 6, 6, 6]
    for lod in range(4):
        h.assert_close_relative(d[f"gpu/lod{lod}"], d[f"ref/lod{lod}"])


def test_vertex_format_grows_only_past_four_influences(h):
    from crowd_addon.gpu.proxies import proxy_buffers
    four = proxy_buffers(h.make_config().meshes["fan"][0])
    six = proxy_buffers(h.make_config(influences=6).meshes["fan"][0])
    assert sorted(four.attributes) == ["bone_idx", "bone_w", "col", "look_depth", "nor", "pos"]
    assert four.interleaved().itemsize == 56 and four.influences == 2
    assert sorted(six.attributes) == ["bone_idx", "bone_idx2", "bone_w", "bone_w2", "col",
                                      "look_depth", "nor", "pos"]
    assert six.interleaved().itemsize == 80 and six.influences == 6
    np.testing.assert_array_equal(six.batched(3).attributes["bone_w2"][: six.vertex_count],
                                  six.attributes["bone_w2"])


def test_look_depths_pack_each_influences_chain_depth_in_four_bits():
    from crowd_addon.gpu.proxies import look_depths
    depth = np.array([0, 0, 1, 2, 2, 0])          # bones 2-4 on or below a two-bone chain
    idx = np.array([[0, 1, 0, 0], [2, 0, 0, 0], [4, 3, 1, 0], [5, 5, 5, 5]])
    got = look_depths(idx, depth)
    assert got.dtype == np.uint32
    assert got.tolist() == [0, 1, 2 | (2 << 4), 0]
    assert look_depths(idx, None).tolist() == [0, 0, 0, 0]
    wide = np.array([[0, 0, 0, 0, 0, 0, 0, 3]])
    assert look_depths(wide, depth).tolist() == [2 << 28]
