"""Per-frame uploads: exactly core's dirty rows, never the whole texture, and the GPU
copy stays equal to core's mirror (DESIGN.md s.3: the new slice, unique rows and
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
        assert stats.pose_bytes == (crowd.S + crowd.U + active) * row
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


def test_gpu_transition_mode_uploads_local_rows_not_slot_rows(h, renderer):
    crowd = h.Crowd(h.make_config(NT=4), gpu_transitions=True)
    r = renderer(crowd)
    loc = crowd.local_storage
    for i in range(8):
        started = 0
        if i == 2:       # a request fills its slots' rows once, on the CPU (core's rule)
            started = crowd.transition_to_streamed([0, 1, 2], "s1", 4).started.size
        crowd.step()
        pose_expected, local_expected = crowd.storage.dirty_bytes(), loc.dirty_bytes()
        stats = r.sync()
        assert (stats.pose_bytes, stats.local_bytes) == (pose_expected, local_expected)
        assert stats.pose_bytes == (crowd.S + crowd.U + started) * crowd.storage.row_bytes
        assert stats.batch_bytes > 0 if crowd.slots.active.any() else stats.batch_bytes == 0
