"""Pose texture layout, per-frame dirty rows and column-block wrapping (docs/architecture.md."""

import numpy as np
import pytest

from crowd_addon.core import (ClipPlayer, Crowd, CrowdConfig, CrowdError, PoseStorage,
                              Skeleton, skinning_matrices)
from crowd_addon.core.base import pose as sqt
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

M = 8


def build(NT=5, max_texture_size=16384, skeleton=None, streams=3, uniques=2):
    small = skeleton or humanoid("fan", bones=24)
    big = humanoid("big", bones=30)
    cfg = CrowdConfig(max_offset=M, transition_slots=NT, max_texture_size=max_texture_size)
    cfg.add_skeleton(small)
    if skeleton is None:
        cfg.add_skeleton(big)
    for i in range(streams + uniques):
        cfg.add_clip(periodic_clip(small, f"c{i}", frames=13 + 2 * i, seed=i))
    if skeleton is None:
        cfg.add_clip(periodic_clip(big, "cbig", frames=19, seed=9))
    for s in range(streams):
        cfg.add_stream(f"s{s}", small.name, ClipPlayer(f"c{s}"))
    if skeleton is None:
        cfg.add_stream("sbig", "big", ClipPlayer("cbig"))
    for u in range(uniques):
        cfg.add_unique(f"u{u}", small.name, ClipPlayer(f"c{streams + u}"))
    cfg.add_agents(20, streams=np.arange(20) % streams)
    return Crowd(cfg), cfg


def tiny_skeleton():
    bind = sqt.identity_pose(2)
    bind[1, sqt.TRANS] = (0, 0, 1)
    return Skeleton("tiny", ["a", "b"], [-1, 0], bind)


def region_rows(regions):
    out = []
    for r in regions:
        out.extend(range(*r.rows))
    return out


# --------------------------------------------------------------------- layout


def test_layout_rows_and_row_width():
    crowd, _ = build()
    st = crowd.storage
    S, U, NT = 4, 2, 5
    assert (crowd.streams.count, crowd.uniques.count, crowd.slots.count,
            crowd.bones) == (S, U, NT, 30)
    assert st.row_count == M * S + U + NT
    assert st.row_texels == 3 * 30
    assert st.row_bytes == 3 * 30 * 16
    assert st.rows.shape == (M * S + U + NT, 30, 3, 4)
    assert st.unique_base == M * S and st.slot_base == M * S + U
    assert st.height == st.row_count and st.width == 3 * 30 and st.blocks == 1


def test_row_texels_hold_bone_major_matrix_rows():
    crowd, cfg = build()
    for _ in range(3):
        crowd.step()
    st, F = crowd.storage, crowd.frame
    img = st.texture_image()
    for s, (clip, sk) in enumerate([("c0", cfg.skeletons["fan"]),
                                    ("cbig", cfg.skeletons["big"])]):
        stream = 0 if s == 0 else 3
        ref = skinning_matrices(cfg.clips[clip].sample(float(F))[None].astype(np.float64),
                                sk)[0]
        x, y = st.texel_of_row((F % M) * crowd.streams.count + stream)
        for b in range(sk.bone_count):
            for r in range(3):
                np.testing.assert_allclose(img[y, x + 3 * b + r], ref[b, r], rtol=1e-5,
                                           atol=1e-5)
        # bones beyond a smaller skeleton stay identity rows
        for b in range(sk.bone_count, crowd.bones):
            np.testing.assert_array_equal(img[y, x + 3 * b:x + 3 * b + 3],
                                          np.eye(4, dtype=np.float32)[:3])


# ---------------------------------------------------------------- dirty rows


def test_upload_bytes_per_step_is_exact():
    crowd, _ = build(NT=3)
    rb = crowd.storage.row_bytes
    S, U = crowd.streams.count, crowd.uniques.count
    assert crowd.step().upload_bytes == (S + U) * rb
    crowd.transition_to_streamed([0, 3], 0, 3)
    rep = crowd.step()
    assert rep.transitions_active == 2
    assert rep.upload_bytes == (S + U + 2) * rb
    crowd.transition_to_streamed([1, 4, 7], 1, 2)     # 1 slot free, 2 queued
    rep = crowd.step()
    assert rep.upload_bytes == (S + U + 3) * rb
    rep = crowd.step()                                # 0, 3 and 1 finish
    assert rep.transitions_finished == 3 and rep.transitions_active == 0
    assert rep.upload_bytes == (S + U) * rb
    rep = crowd.step()                                # queue served: 4, 7
    assert rep.transitions_started == 2 and rep.transitions_active == 2
    assert rep.upload_bytes == (S + U + 2) * rb
    for _ in range(4):
        rep = crowd.step()
        assert rep.upload_bytes == (S + U + rep.transitions_active) * rb
    assert rep.transitions_active == 0 and rep.upload_bytes == (S + U) * rb


def test_take_dirty_regions_returns_exactly_changed_rows():
    crowd, _ = build(NT=4)
    st, S, U = crowd.storage, crowd.streams.count, crowd.uniques.count
    full = crowd.view.take_upload_regions()                # after reset: everything
    assert region_rows(full) == list(range(st.row_count))
    assert crowd.view.take_upload_regions() == []
    crowd.step()
    F = crowd.frame
    want = list(range((F % M) * S, (F % M) * S + S)) + list(range(M * S, M * S + U))
    assert sorted(region_rows(crowd.view.take_upload_regions())) == want
    res = crowd.transition_to_streamed([2, 9], 1, 4)
    between = crowd.view.take_upload_regions()             # the slots' start rows
    assert sorted(region_rows(between)) == sorted((st.slot_base + res.slots).tolist())
    crowd.step()
    F = crowd.frame
    want = sorted(list(range((F % M) * S, (F % M) * S + S)) + list(range(M * S, M * S + U))
                  + (st.slot_base + res.slots).tolist())
    regions = crowd.view.take_upload_regions()
    rows = region_rows(regions)
    assert sorted(rows) == want and len(rows) == len(set(rows))
    for r in regions:
        np.testing.assert_array_equal(r.data, st.rows[r.rows[0]:r.rows[1]].reshape(
            r.height, st.row_texels, 4))
        assert r.nbytes == r.height * st.row_bytes


# ------------------------------------------------------------------- wrapping


def fill_random(st, seed=0):
    st.rows[:] = np.random.default_rng(seed).normal(size=st.rows.shape)


def test_wrapping_into_column_blocks_unit():
    st = PoseStorage(streams=3, max_offset=M, uniques=2, slots=4, bones=1, max_texture_size=12)
    assert st.row_count == 30
    assert (st.height, st.blocks, st.width) == (12, 3, 9)
    fill_random(st)
    img = st.texture_image()
    assert img.shape == (12, 9, 4)
    flat = st.rows.reshape(30, 3, 4)
    for r in range(30):
        x, y = st.texel_of_row(r)
        assert (x, y) == ((r // 12) * 3, r % 12)
        np.testing.assert_array_equal(img[y, x:x + 3], flat[r])
    x, y = st.texel_of_row(np.arange(30))
    assert x.shape == (30,) and y.max() == 11


def test_regions_split_at_block_boundaries():
    st = PoseStorage(3, M, 2, 4, bones=1, max_texture_size=12)
    fill_random(st, 1)
    st.take_dirty_regions()
    st.mark_dirty(8, 18)                              # rows 8..25 span three blocks
    st.mark_rows_dirty(np.array([28, 29, 27]))
    regions = st.take_dirty_regions()
    assert [r.rows for r in regions] == [(8, 12), (12, 24), (24, 26), (27, 30)]
    img = st.texture_image()
    for r in regions:
        assert r.y + r.height <= st.height
        assert (r.x, r.y) == tuple(int(v) for v in st.texel_of_row(r.rows[0]))
        np.testing.assert_array_equal(r.data, img[r.y:r.y + r.height, r.x:r.x + r.width])
    assert st.take_dirty_regions() == []


def test_wrapped_crowd_texture_holds_same_rows_as_unwrapped():
    wide, _ = build(NT=3, skeleton=tiny_skeleton())
    wrapped, _ = build(NT=3, skeleton=tiny_skeleton(), max_texture_size=16)
    n = wide.storage.row_count
    assert n == M * 3 + 2 + 3 > 16
    assert wrapped.storage.blocks == 2 and wrapped.storage.height == 16
    assert wide.storage.blocks == 1
    for c in (wide, wrapped):
        for _ in range(5):
            c.step()
        c.transition_to_streamed([1, 2], 0, 4)
        c.step()
    a, b = wide.storage.texture_image(), wrapped.storage.texture_image()
    texels = wide.storage.row_texels
    for r in range(n):
        xa, ya = wide.storage.texel_of_row(r)
        xb, yb = wrapped.storage.texel_of_row(r)
        np.testing.assert_array_equal(a[ya, xa:xa + texels], b[yb, xb:xb + texels])
    assert not np.all(a == 0)
    for reg in wrapped.view.take_upload_regions():
        assert reg.y + reg.height <= 16
        np.testing.assert_array_equal(reg.data, b[reg.y:reg.y + reg.height,
                                                  reg.x:reg.x + reg.width])


# --------------------------------------------------------------------- errors


def test_row_wider_than_max_texture_size():
    with pytest.raises(CrowdError, match="cannot fit") as e:
        PoseStorage(2, M, 0, 0, bones=30, max_texture_size=64)
    assert "30 bones" in str(e.value) and "64" in str(e.value)


def test_blocks_wider_than_max_texture_size():
    with pytest.raises(CrowdError, match="cannot fit"):
        PoseStorage(3, M, 2, 4, bones=2, max_texture_size=12)   # 3 blocks x 6 > 12


def test_crowd_reports_texture_that_cannot_fit():
    with pytest.raises(CrowdError, match="cannot fit"):
        build(max_texture_size=80)                    # 30 bones x 3 texels > 80
    with pytest.raises(CrowdError, match="cannot fit"):
        build(skeleton=tiny_skeleton(), max_texture_size=8)


def test_rows_with_interleaved_skeletons_and_slots():
    """Streams, uniques and slots of two skeletons, interleaved (non-contiguous groups)."""
    a, b = humanoid("a", 24), humanoid("b", 28)
    cfg = CrowdConfig(max_offset=6, transition_slots=6)
    cfg.add_skeleton(a)
    cfg.add_skeleton(b)
    skels = [a, b]
    for i in range(4):
        cfg.add_clip(periodic_clip(skels[i % 2], f"k{i}", frames=11 + i, seed=i))
    for i in range(4):
        cfg.add_stream(f"s{i}", "ab"[i % 2], ClipPlayer(f"k{i}"))
    for i in range(3):
        cfg.add_unique(f"u{i}", "ab"[i % 2], ClipPlayer(f"k{i}"))
    cfg.add_agents(16, streams=np.arange(16) % 4, offsets=np.arange(16) % 6)
    crowd = Crowd(cfg)
    crowd.step()
    crowd.transition_to_streamed([0], 2, 5, offset=1)          # skeleton a
    crowd.transition_to_streamed([1], 3, 5, offset=2)          # skeleton b
    crowd.transition_to_unique([2], 0, 5)                      # a
    crowd.transition_to_unique([3], 1, 5)                      # b
    crowd.transition_to_streamed([4], 0, 5, offset=0)          # a
    crowd.step()
    crowd.step()

    def ref(local, sk):
        return skinning_matrices(np.asarray(local, np.float64)[None], sk)[0, :, :3]

    def check(row, local, sk):
        np.testing.assert_allclose(row[:sk.bone_count], ref(local, sk), rtol=1e-5, atol=1e-5)
        np.testing.assert_array_equal(row[sk.bone_count:], np.broadcast_to(
            np.eye(4, dtype=np.float32)[:3], (crowd.bones - sk.bone_count, 3, 4)))

    F, st = crowd.frame, crowd.storage
    for s in range(4):
        for o in range(6):
            k = (F - o) % 6
            check(st.rows[k * 4 + s], crowd.streams.history[k, s], skels[s % 2])
    for u in range(3):
        check(st.unique_rows()[u], crowd.uniques.poses[u], skels[u % 2])
    for ag in range(5):
        assert crowd.agents.kind[ag] == 2
        check(crowd.agent_rows([ag])[0], crowd.agent_poses([ag])[0], skels[ag % 2])


def test_one_block_layout_for_every_block_laid_texture():
    from crowd_addon.core.runtime.pose_storage import block_layout
    assert block_layout(10, 6, 64, "t") == (10, 1, 6)
    assert block_layout(100, 6, 40, "t") == (40, 3, 18)   # rows wrap into 3 column blocks
    s = PoseStorage(3, M, 2, 4, bones=2, max_texture_size=24)
    assert s.blocks == 2 and (s.height, s.blocks, s.width) == block_layout(s.row_count, 6,
                                                                           24, "t")
    with pytest.raises(CrowdError, match="agent texture cannot fit: 100 rows"):
        block_layout(100, 2, 12, "agent texture")      # 9 blocks x 2 > 12
