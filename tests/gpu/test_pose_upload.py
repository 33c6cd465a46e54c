"""Per-frame uploads: exactly core's dirty rows, never the whole texture, and the GPU
copy stays equal to core's mirror (docs/architecture.md: the new slice, unique rows and
active transition rows)."""

import numpy as np


def test_upload_counter_equals_core_dirty_bytes_and_minimum(h, renderer):
    crowd = h.Crowd(h.make_config(M=8, streams=3, uniques=1, NT=4))
    r = renderer(crowd)
    st = crowd.storage
    row = st.row_bytes
    for i in range(12):
        if i == 3:
            crowd.transition_to_streamed([0, 1], "s2", 5)
        crowd.step()
        expected = st.dirty_bytes()
        active = int(crowd.slots.active.sum())
        stats = r.sync()
        assert stats.pose_bytes == expected
        assert stats.pose_bytes == (crowd.streams.count + crowd.uniques.count + active) * row
        assert stats.pose_bytes < st.nbytes / 4


def test_gpu_texture_equals_core_mirror_with_wrapped_rows(h, renderer):
    cfg = h.make_config(M=24, streams=24, NT=8, max_texture_size=256)
    crowd = h.Crowd(cfg)
    assert crowd.storage.blocks == 3 and crowd.storage.height == 256
    r = renderer(crowd)
    np.testing.assert_array_equal(r.read_pose_texture(), crowd.storage.texture_image())
    for i in range(30):                  # more than M frames: every slice rewritten
        if i == 5:
            crowd.transition_to_unique([3, 4], "u0", 6)
        crowd.step()
        r.sync()
    np.testing.assert_array_equal(r.read_pose_texture(), crowd.storage.texture_image())


def test_gpu_skinning_uploads_local_rows_and_writes_the_pose_texture(h, renderer):
    crowd = h.Crowd(h.make_config(M=24, streams=24, NT=4, max_texture_size=256),
                    skinning="gpu")
    cpu = h.Crowd(h.make_config(M=24, streams=24, NT=4, max_texture_size=256))
    assert crowd.storage.blocks > 1                     # wrapped rows on both textures
    r = renderer(crowd)
    st = crowd.storage
    for i in range(26):                                 # more than M: every slice rewritten
        started = 0
        if i == 2:       # a request's slots send their StartP once (core's rule)
            started = crowd.transition_to_streamed([0, 1, 2], "s1", 4).started.size
            cpu.transition_to_streamed([0, 1, 2], "s1", 4)
        crowd.step()
        cpu.step()
        expected = st.dirty_bytes()
        stats = r.sync()
        assert (stats.pose_bytes, stats.local_bytes) == (0, expected)
        own = crowd.streams.count + crowd.uniques.count
        assert stats.local_bytes == (own + started) * st.row_bytes
        assert stats.skinned_rows == own + crowd.slots.active.sum()
        # the rows the GPU wrote are the CPU crowd's pose texture rows
        gpu_rows = r.read_pose_texture()
        used = np.unique(cpu.agent_rows_index())
        x, y = st.texel_of_row(used)
        for row, x0, y0 in zip(used, x, y):
            np.testing.assert_allclose(gpu_rows[y0, x0:x0 + st.row_texels],
                                       cpu.storage.rows[row].reshape(-1, 4), atol=2e-5)
    hist = np.arange(st.slot_base)                      # every history and unique row
    x, y = st.texel_of_row(hist)
    got = np.stack([r.read_pose_texture()[y0, x0:x0 + st.row_texels] for x0, y0 in zip(x, y)])
    np.testing.assert_allclose(got, cpu.storage.rows[:st.slot_base].reshape(got.shape),
                               atol=2e-5)
