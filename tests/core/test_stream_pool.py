"""StreamPool pose history and UniquePool (paper s.4.1-4.2; docs/architecture.md, Behaviour).

Every expected value is computed independently of the crowd runtime: clip
sampling (``Clip.sample``), ``pose.blend2`` and the float64 reference skinning.
"""

import numpy as np
import pytest

from crowd_addon.core import (STREAM, UNIQUE, Blend2, ClipPlayer, Crowd, CrowdConfig,
                              SkinningPlan, skinning_matrices)
from crowd_addon.core.base import pose as sqt
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

M = 9


def build(start_frame=0, M=M, agents=30):
    sk = humanoid(bones=26)
    cfg = CrowdConfig(max_offset=M, transition_slots=4, start_frame=start_frame)
    cfg.add_skeleton(sk)
    for i in range(4):
        cfg.add_clip(periodic_clip(sk, f"c{i}", frames=11 + 6 * i, seed=i))
    cfg.add_stream("walk", "fan", ClipPlayer("c0"))
    cfg.add_stream("fast", "fan", ClipPlayer("c1", speed=1.5, start=2.0))
    cfg.add_stream("mix", "fan", Blend2(ClipPlayer("c0"), ClipPlayer("c2"), 0.3))
    cfg.add_unique("solo", "fan", ClipPlayer("c3"))
    cfg.add_agents(agents, seed=5)
    return Crowd(cfg), cfg, sk


def expected_root(cfg, stream, t):
    """Independent evaluation of the test's stream roots at time ``t`` (frames)."""
    c = cfg.clips
    if stream == 0:
        return c["c0"].sample(float(t))
    if stream == 1:
        return c["c1"].sample(2.0 + 1.5 * t)
    a, b = c["c0"].sample(float(t)), c["c2"].sample(float(t))
    return sqt.blend2(a, b, np.float32(0.3))


def snapshot(crowd):
    return (crowd.frame, crowd.streams.history.copy(), crowd.uniques.poses.copy(),
            crowd.storage.rows.copy(), crowd.agents.kind.copy(), crowd.agents.ref.copy(),
            crowd.agents.offset.copy())


def assert_same(a, b):
    assert a[0] == b[0]
    for x, y in zip(a[1:], b[1:]):
        np.testing.assert_array_equal(x, y)


# ------------------------------------------------------------------ history


@pytest.mark.parametrize("steps", [1, 5, 2 * M + 3])
def test_pose_at_offset_is_root_at_frame_minus_offset(steps):
    crowd, cfg, _ = build()
    for _ in range(steps):
        crowd.step()
    F = crowd.frame
    assert F == steps
    for s in range(3):
        for o in range(M):
            np.testing.assert_allclose(crowd.pose(s, o), expected_root(cfg, s, F - o),
                                       atol=2e-6, err_msg=f"stream {s} offset {o}")


def test_pose_by_name_equals_pose_by_index():
    crowd, _, _ = build()
    crowd.step()
    for i, name in enumerate(["walk", "fast", "mix"]):
        np.testing.assert_array_equal(crowd.pose(name, 3), crowd.pose(i, 3))


def test_offset_equals_head_pose_offset_frames_ago():
    crowd, _, _ = build()
    heads = []
    for _ in range(3 * M):
        crowd.step()
        heads.append([crowd.pose(s, 0) for s in range(3)])
        for o in range(min(M, len(heads))):
            for s in range(3):
                np.testing.assert_array_equal(crowd.pose(s, o), heads[-1 - o][s])


def test_history_valid_for_all_offsets_right_after_reset():
    crowd, cfg, _ = build(start_frame=40)
    assert crowd.frame == 40
    for s in range(3):
        for o in range(M):
            np.testing.assert_allclose(crowd.pose(s, o), expected_root(cfg, s, 40 - o),
                                       atol=2e-6)
    # every agent's pose is its stream at its delay, nothing is left at identity
    poses = crowd.agent_poses()
    for a in range(crowd.agents.count):
        s, o = int(cfg.agent_stream[a]), int(cfg.agent_offset[a])
        np.testing.assert_allclose(poses[a], expected_root(cfg, s, 40 - o), atol=2e-6)


def test_agent_poses_follow_their_stream_and_offset_while_stepping():
    crowd, cfg, _ = build()
    for _ in range(M + 2):
        crowd.step()
    poses = crowd.agent_poses()
    assert (crowd.agents.kind == STREAM).all()
    for a in range(crowd.agents.count):
        s, o = int(cfg.agent_stream[a]), int(cfg.agent_offset[a])
        np.testing.assert_allclose(poses[a], expected_root(cfg, s, crowd.frame - o),
                                   atol=2e-6)


def test_reset_is_deterministic():
    crowd, _, _ = build()
    for _ in range(13):
        crowd.step()
    first = snapshot(crowd)
    crowd.reset()
    for _ in range(13):
        crowd.step()
    assert_same(first, snapshot(crowd))


def test_reset_restores_agents_after_transitions():
    crowd, cfg, _ = build()
    for _ in range(3):
        crowd.step()
    crowd.transition_to_streamed([0, 1, 2], 1, 4, offset=2)
    crowd.transition_to_unique([5], "solo", 0)
    crowd.step()
    crowd.reset()
    np.testing.assert_array_equal(crowd.agents.kind, np.full(crowd.agents.count, STREAM))
    np.testing.assert_array_equal(crowd.agents.ref, cfg.agent_stream)
    np.testing.assert_array_equal(crowd.agents.offset, cfg.agent_offset)
    assert not crowd.slots.active.any()
    assert len(crowd.slots.queue) == 0


def test_advance_to_backwards_resimulates_identically():
    crowd, _, _ = build()
    states = {}
    for _ in range(20):
        crowd.step()
        if crowd.frame in (6, 11, 20):
            states[crowd.frame] = snapshot(crowd)
    crowd.advance_to(11)
    assert crowd.frame == 11
    assert_same(states[11], snapshot(crowd))
    crowd.advance_to(6)
    assert_same(states[6], snapshot(crowd))
    crowd.advance_to(20)
    assert_same(states[20], snapshot(crowd))


def test_advance_to_backwards_before_start_frame():
    crowd, cfg, _ = build(start_frame=10)
    crowd.advance_to(15)
    crowd.advance_to(4)
    assert crowd.frame == 4
    for o in range(M):
        np.testing.assert_allclose(crowd.pose(0, o), expected_root(cfg, 0, 4 - o), atol=2e-6)


# --------------------------------------------------------- pose texture rows


def reference_rows(local, sk):
    """float64 reference: top three rows of model @ inverse_bind per bone."""
    return skinning_matrices(np.asarray(local, np.float64)[None], sk)[0, :, :3, :]


@pytest.mark.parametrize("steps", [0, 4, M + 1])
def test_texture_rows_of_current_slice_match_reference_skinning(steps):
    crowd, cfg, sk = build()
    for _ in range(steps):
        crowd.step()
    F, S = crowd.frame, crowd.streams.count
    st = crowd.storage
    plan = SkinningPlan(sk, crowd.bones)
    for s in range(S):
        row = st.rows[(F % M) * S + s]
        local = expected_root(cfg, s, F)
        ref = reference_rows(local, sk)
        np.testing.assert_allclose(row[:sk.bone_count], ref, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(row, plan.rows(local[None])[0], rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(crowd.stream_rows(s, 0), row)


def test_texture_rows_for_every_offset_match_history():
    crowd, cfg, sk = build()
    for _ in range(M + 4):
        crowd.step()
    F, S = crowd.frame, crowd.streams.count
    for o in range(M):
        for s in range(S):
            row = crowd.storage.rows[((F - o) % M) * S + s]
            ref = reference_rows(expected_root(cfg, s, F - o), sk)
            np.testing.assert_allclose(row, ref, rtol=1e-5, atol=1e-5)
    # agents read exactly their stream's delayed row
    rows = crowd.agent_rows()
    for a in range(crowd.agents.count):
        s, o = int(cfg.agent_stream[a]), int(cfg.agent_offset[a])
        np.testing.assert_allclose(rows[a], reference_rows(expected_root(cfg, s, F - o), sk),
                                   rtol=1e-5, atol=1e-5)


# --------------------------------------------------------------- unique pool


def test_unique_pool_holds_current_pose_only():
    crowd, cfg, sk = build()
    assert crowd.uniques.poses.shape == (1, crowd.bones, sqt.WIDTH)
    assert crowd.storage.row_count == (M * crowd.streams.count + crowd.uniques.count
                                       + crowd.slots.count)
    clip = cfg.clips["c3"]
    # whatever its phase, the unique advances one clip frame per crowd frame
    p0 = crowd.uniques.poses[0].copy()
    cand = [t for t in range(clip.frame_count - 1)
            if np.allclose(clip.sample(float(t)), p0, atol=2e-6)]
    assert cand, "unique pose is not a sample of its clip"
    for k in range(1, 8):
        crowd.step()
        assert any(np.allclose(crowd.uniques.poses[0], clip.sample(float(t + k)), atol=2e-6)
                   for t in cand)
        np.testing.assert_allclose(crowd.storage.unique_rows()[0],
                                   reference_rows(crowd.uniques.poses[0], sk),
                                   rtol=1e-5, atol=1e-5)


def test_transition_to_unique_restarts_it():
    crowd, cfg, sk = build()
    for _ in range(7):
        crowd.step()
    clip = cfg.clips["c3"]
    crowd.transition_to_unique([0], "solo", 3, restart=True)
    for k in range(1, 6):
        crowd.step()
        np.testing.assert_allclose(crowd.uniques.poses[0], clip.sample(float(k - 1)),
                                   atol=2e-6, err_msg=f"{k} frames after restart")
    assert crowd.agents.kind[0] == UNIQUE
    np.testing.assert_allclose(crowd.agent_poses([0])[0], crowd.uniques.poses[0])


def test_transition_to_unique_without_restart_keeps_clock():
    crowd, cfg, _ = build()
    for _ in range(7):
        crowd.step()
    before = crowd.uniques.poses[0].copy()
    crowd.transition_to_unique([0], "solo", 2, restart=False)
    crowd.step()
    crowd2, _, _ = build()
    for _ in range(8):
        crowd2.step()
    np.testing.assert_array_equal(crowd.uniques.poses[0], crowd2.uniques.poses[0])
    assert not np.array_equal(before, crowd.uniques.poses[0])
