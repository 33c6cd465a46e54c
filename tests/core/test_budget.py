"""The paper's memory model (section 5) and the stream/offset planner."""

import math

import numpy as np
import pytest

from crowd_addon.core.planning import budget as b
from crowd_addon.core.base.errors import CrowdError

MB = 10**6
MIB = 2**20


# ----------------------------------------------------------------- paper's figures

def test_paper_clip_size_old_is_246_kb():
    # 82 bones x 10 B (the paper's 0.8 KB pose) x 300 frames
    assert b.pose_size(82, 10) == 820
    assert b.clip_size_old(82, 10, 300) == 246_000


def test_paper_num_clips_new_from_its_printed_old():
    assert b.num_clips_new(num_clips_old=216, motion_length=300, max_offset=60) == 1080
    assert b.num_clips_new(b.PAPER_NUM_CLIPS_OLD, b.PAPER_MOTION_LENGTH,
                           b.PAPER_MAX_OFFSET) == b.PAPER_NUM_CLIPS_NEW


def test_paper_num_clips_old_is_not_216():
    """The paper's 216 does not follow from its inputs, in MB or in MiB."""
    size = b.clip_size_old(82, 10, 300)
    assert b.num_clips_old(520 * MB, size) == 2113
    assert b.num_clips_old(520 * MIB, size) == 2216
    model = b.memory_model(520 * MB, 300, 60, bones=82, bytes_per_bone=10)
    assert model.num_clips_old != b.PAPER_NUM_CLIPS_OLD
    assert (model.num_clips_old, model.num_clips_new) == (2113, 10565)
    model = b.memory_model(520 * MIB, 300, 60, bones=82, bytes_per_bone=10)
    assert (model.num_clips_old, model.num_clips_new) == (2216, 11080)


def test_memory_model_figures():
    model = b.memory_model(520 * MB, 300, 60, pose_bytes=800)
    assert model.pose_bytes == 800
    assert model.clip_size_old == 240_000
    assert model.clip_size_new == 48_000
    assert model.num_clips_old == 2166  # 520e6 / 240,000 = 2166.67
    assert model.num_clips_new == 10830  # 5 x 2166
    assert model.num_clips_new_direct == 10833  # 520e6 / 48,000 = 10833.3


def test_pose_bytes_overrides_bones():
    model = b.memory_model(1e6, 100, 10, pose_bytes=100, bones=82, bytes_per_bone=10)
    assert model.pose_bytes == 100


# ------------------------------------------------------------ formula and floors

@pytest.mark.parametrize("bones, per_bone, length, m", [
    (1, 1, 1, 1), (20, 48, 45, 45), (150, 12.5, 240.5, 30), (82, 40, 300, 1)])
def test_formulas_on_other_inputs(bones, per_bone, length, m):
    pose = bones * per_bone
    assert b.pose_size(bones, per_bone) == pytest.approx(pose)
    assert b.clip_size_old(bones, per_bone, length) == pytest.approx(length * pose)
    assert b.clip_size_new(bones, per_bone, m) == pytest.approx(m * pose)
    for old in (0, 1, 7, 216, 12345):
        assert b.num_clips_new(old, length, m) == math.floor(length / m * old)


def test_floor_is_exact_at_integer_boundaries():
    # 0.3 x 10 is 3.0000000000000004 in floats; the formula must not round it
    assert b.num_clips_old(3, 1) == 3
    assert b.num_clips_old(2.999, 1) == 2
    assert b.num_clips_old(999, 1000) == 0
    assert b.num_clips_new(3, 10, 3) == 10  # 10/3 x 3 exactly 10, not 9
    assert b.num_clips_new(7, 10, 3) == 23  # 23.33
    assert b.num_clips_new(0, 300, 60) == 0
    assert b.num_clips_new_direct(100, 30) == 3


def test_new_is_at_least_old_and_direct_is_close():
    for length, m in [(300, 60), (300, 300), (90, 7), (61, 60)]:
        model = b.memory_model(520 * MB, length, m, bones=82, bytes_per_bone=10)
        assert model.num_clips_new >= model.num_clips_old
        # the paper floors before scaling: it loses at most length / m clips
        gap = model.num_clips_new_direct - model.num_clips_new
        assert 0 <= gap <= math.ceil(length / m)


def test_offset_equal_to_motion_length_gives_old_count():
    assert b.num_clips_new(216, 300, 300) == 216


# ------------------------------------------------------------------- validation

def test_max_offset_longer_than_motion_is_rejected():
    with pytest.raises(CrowdError, match=r"max_offset 301 exceeds motion_length.*cannot "
                                         r"exceed the number of frames"):
        b.num_clips_new(216, 300, 301)
    with pytest.raises(CrowdError, match="max_offset 400 exceeds"):
        b.memory_model(1e6, 300, 400, pose_bytes=800)


@pytest.mark.parametrize("call, message", [
    (lambda: b.clip_size_new(82, 10, 0), r"budget: max_offset must be >= 1, got 0"),
    (lambda: b.num_clips_new(216, 300, -5), r"max_offset must be >= 1, got -5"),
    (lambda: b.num_clips_new(216, 300, 2.5), r"max_offset must be an integer, got 2\.5"),
    (lambda: b.num_clips_new(-1, 300, 60), r"num_clips_old must be >= 0, got -1"),
    (lambda: b.pose_size(0, 10), r"bones must be >= 1, got 0"),
    (lambda: b.pose_size(True, 10), r"bones must be an integer, got True"),
    (lambda: b.pose_size(82, -1), r"bytes_per_bone must be > 0, got -1"),
    (lambda: b.pose_size(82, float("nan")), r"bytes_per_bone must be finite, got nan"),
    (lambda: b.clip_size_old(82, 10, 0), r"motion_length must be > 0, got 0"),
    (lambda: b.clip_size_old(82, 10, float("inf")), r"motion_length must be finite"),
    (lambda: b.num_clips_old(0, 246_000), r"budget_bytes must be > 0, got 0"),
    (lambda: b.num_clips_old(520e6, 0), r"clip_size_old must be > 0, got 0"),
    (lambda: b.num_clips_old("520", 1), r"budget_bytes must be a number, got '520'"),
    (lambda: b.num_clips_new_direct(520e6, -1.0), r"clip_size_new must be > 0"),
    (lambda: b.memory_model(1e6, 300, 60), r"give pose_bytes, or bones and bytes_per_bone"),
])
def test_bad_inputs_name_the_field(call, message):
    with pytest.raises(CrowdError, match=message):
        call()


def test_numpy_scalars_are_accepted():
    assert b.clip_size_old(np.int64(82), np.float32(10), np.int32(300)) == 246_000
    assert b.num_clips_new(np.int64(216), 300.0, 60.0) == 1080


# ----------------------------------------------------------------------- planner

def _fits(p):
    assert p.bytes_used == p.total_rows * p.row_bytes <= p.budget_bytes
    assert p.history_rows == p.streams * p.max_offset
    assert p.total_rows == p.history_rows + p.unique_agents + p.transition_slots


def test_plan_paper_crowd():
    p = b.plan(65000, 520 * MB, 82, 300)
    _fits(p)
    assert p.row_bytes == 82 * 48
    assert p.max_offset == 60  # 2 s at 30 fps
    assert p.streams == math.ceil(65000 / (4 * 60))  # 271, the paper used 256
    assert p.agents_per_key <= 4 and p.meets_target
    assert p.stream_upload_bytes == p.streams * p.row_bytes
    assert p.peak_upload_bytes == (p.streams + 800) * p.row_bytes
    assert p.max_streams == (520 * MB // p.row_bytes - 800) // 60
    assert p.offset_seconds == 2.0
    assert p.notes == ()


@pytest.mark.parametrize("clips, budget", [
    (300, 520 * MB), ([300, 45, 120], 520 * MB), (45.5, 50 * MB), ([20, 400], 5 * MB),
    (3, 520 * MB), ([300], 2 * MB)])
def test_plan_fits_budget_and_clip_length(clips, budget):
    p = b.plan(65000, budget, 82, clips, unique_agents=100, transition_slots=200)
    _fits(p)
    shortest = min(np.atleast_1d(clips))
    assert 1 <= p.max_offset <= shortest
    assert p.streams >= 1
    assert p.key_capacity * p.row_bytes <= budget


def test_plan_caps_offset_at_shortest_clip():
    p = b.plan(1000, 520 * MB, 82, [300, 45])
    assert p.max_offset == 45
    assert any("shortest clip (45 frames)" in n for n in p.notes)


def test_plan_reports_when_budget_cannot_meet_target():
    p = b.plan(65000, 50 * MB, 82, 300)
    _fits(p)
    assert not p.meets_target
    assert p.streams == p.max_streams
    # no split of this budget does better: M x S is bounded by key_capacity
    assert p.agents_per_key >= 65000 / p.key_capacity
    assert any("agents per key" in n for n in p.notes)


def test_plan_shrinks_offset_when_one_stream_does_not_fit():
    row = 82 * 48
    p = b.plan(100, row * 10, 82, 300, transition_slots=0)
    assert (p.streams, p.max_offset) == (1, 10)
    _fits(p)


def test_plan_fixed_offset_and_streams():
    p = b.plan(65000, 520 * MB, 82, 300, max_offset=30, streams=256)
    assert (p.streams, p.max_offset) == (256, 30)
    _fits(p)
    p = b.plan(65000, 520 * MB, 82, 300, max_offset=300)
    assert p.max_offset == 300
    _fits(p)


def test_plan_fixed_streams_shrink_offset_to_fit():
    p = b.plan(65000, 520 * MB, 82, 300, streams=5000)
    assert p.streams == 5000 and p.max_offset == p.key_capacity // 5000 < 60
    assert any("M reduced" in n for n in p.notes)
    _fits(p)


def test_plan_unique_agents_use_no_streams():
    p = b.plan(100, 520 * MB, 82, 300, unique_agents=100)
    assert p.streams == 0 and p.streamed_agents == 0 and p.history_rows == 0
    _fits(p)


def test_plan_few_agents_get_one_stream():
    p = b.plan(10, 520 * MB, 82, 300)
    assert p.streams == 1 and p.agents_per_key == pytest.approx(10 / 60)


def test_plan_offset_longer_than_shortest_clip_is_rejected():
    with pytest.raises(CrowdError, match=r"max_offset 61 exceeds the shortest clip "
                                         r"\(60 frames\).*cannot exceed"):
        b.plan(1000, 520 * MB, 82, [300, 60], max_offset=61)


@pytest.mark.parametrize("kwargs, message", [
    (dict(agents=0), r"budget: agents must be >= 1, got 0"),
    (dict(budget_bytes=0), r"budget_bytes must be > 0, got 0"),
    (dict(budget_bytes=float("nan")), r"budget_bytes must be finite"),
    (dict(bones=-3), r"bones must be >= 1, got -3"),
    (dict(clip_frames=[]), r"clip_frames is empty"),
    (dict(clip_frames=[300, 0]), r"clip_frames\[1\] must be > 0, got 0"),
    (dict(clip_frames=[300, float("inf")]), r"clip_frames\[1\] must be finite"),
    (dict(clip_frames=0.5), r"clip_frames must be >= 1 frame"),
    (dict(clip_frames="300"), r"clip_frames\[0\] must be a number"),
    (dict(bytes_per_bone=0), r"bytes_per_bone must be > 0"),
    (dict(fps=-30), r"fps must be > 0, got -30"),
    (dict(max_agents_per_key=0), r"max_agents_per_key must be > 0"),
    (dict(offset_seconds=float("inf")), r"offset_seconds must be finite"),
    (dict(max_offset=0), r"budget: max_offset must be >= 1, got 0"),
    (dict(streams=0), r"streams must be >= 1, got 0"),
    (dict(unique_agents=-1), r"unique_agents must be >= 0, got -1"),
    (dict(unique_agents=70000), r"unique_agents \(70000\) exceeds agents \(65000\)"),
    (dict(transition_slots=-1), r"transition_slots must be >= 0, got -1"),
    (dict(budget_bytes=1000), r"800 unique and transition rows need 3,148,800 B, more "
                              r"than the budget"),
    (dict(streams=5000, max_offset=60), r"5000 stream\(s\) x M=60 need .* B of pose "
                                        r"history but only .* B are left"),
    (dict(streams=200_000), r"200000 stream\(s\) x M=60 need"),
    (dict(streams=10, max_offset=300, budget_bytes=10 * MB),
     r"10 stream\(s\) x M=300 need 11,808,000 B"),
])
def test_plan_bad_inputs_name_the_field(kwargs, message):
    args = dict(agents=65000, budget_bytes=520 * MB, bones=82, clip_frames=300)
    args.update(kwargs)
    with pytest.raises(CrowdError, match=message):
        b.plan(**args)
