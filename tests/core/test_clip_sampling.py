"""Clip key times and marker events of a baked action (crowd_addon.core.bake.clip_sampling)
and the between-keys check of its keys (crowd_addon.core.bake.between_keys).
The same through Blender actions: tests/blender/test_bake.py."""

import numpy as np
import pytest

from crowd_addon.core.bake.between_keys import interpolation_misses, interpolation_note
from crowd_addon.core.bake.clip_sampling import marker_events, sample_times
from crowd_addon.core.base.errors import CrowdError


def test_whole_steps_key_every_step():
    times, notes = sample_times("Walk", 1.0, 20.0, 1.0, loop=False)
    np.testing.assert_array_equal(times, np.arange(1.0, 21.0))
    assert notes == []
    times, notes = sample_times("Walk", 1.0, 21.0, 0.8, loop=False)     # 30 fps over 24
    assert len(times) == 26 and times[-1] == pytest.approx(21.0) and notes == []


def test_loops_are_stretched_and_clamped_clips_extended():
    times, notes = sample_times("Wave", 1.0, 20.0, 0.8, loop=True)      # 23.75 steps
    assert len(times) == 25 and times[-1] == pytest.approx(20.0)
    assert notes == ["action 'Wave': 19 frames is not a whole number of crowd frames; the "
                     "loop is resampled to 24 steps of 0.791667 frames so that it still "
                     "closes"]
    times, notes = sample_times("Wave", 1.0, 20.0, 0.8, loop=False)
    assert len(times) == 25 and times[-1] == pytest.approx(20.2)
    assert "last key is sampled at frame 20.2, after the end of the action (20)" in notes[0]


def test_markers_become_clip_frames():
    times = np.arange(1.0, 20.5, 0.5)                                    # 48 fps over 24
    assert marker_events("Wave", [("step", 9), ("clap", 1)], times, 1.0, 20.0) == (
        ("step", 16.0), ("clap", 0.0))
    assert marker_events("Wave", [], times, 1.0, 20.0) == ()
    with pytest.raises(CrowdError, match=r"action 'Wave': pose marker 'late' at frame 40 is "
                                         r"outside the action's frames 1..20"):
        marker_events("Wave", [("late", 40)], times, 1.0, 20.0)


# ------------------------------------------------------------ interpolation check
def euler_z_keys(angle, times):
    """Local SQT (n, 2, 10) of a root at rest and a bone turned ``angle(t)`` about Z."""
    a = np.asarray(angle(np.asarray(times, np.float64)), np.float64)
    out = np.zeros((a.size, 2, 10))
    out[..., :3] = 1
    out[:, :, 3] = 1
    out[:, 1, 3], out[:, 1, 6] = np.cos(a / 2), np.sin(a / 2)
    return out.astype(np.float32)


def wrapping(t):
    """An Euler Z curve keyed 0 at frame 1, 179 degrees at 5, -179 at 6 (Blender goes
    through 0 in between: a full turn in one frame), -90 at 9; linear."""
    return np.radians(np.interp(t, [1, 5, 6, 9], [0, 179, -179, -90]))


def test_interpolation_note_names_a_wrap_and_the_samples_that_follow_it():
    times = np.arange(1.0, 10.0)
    keys = euler_z_keys(wrapping, times)
    misses = interpolation_misses(keys, euler_z_keys(wrapping, times[:-1] + 0.5))
    assert misses.shape == (8, 2) and misses[:, 0].max() < 1e-3
    assert misses[4, 1] == pytest.approx(np.pi, abs=0.04)            # frames 5 .. 6
    assert np.delete(misses[:, 1], 4).max() < 1e-3
    note = interpolation_note("Spin", times, keys, lambda t: euler_z_keys(wrapping, t),
                              ("root", "arm"), samples_per_frame=1)
    assert note.startswith("action 'Spin': bone 'arm' turns too fast between the keys at "
                           "frames 5 and 6 to be interpolated: halfway, the crowd's rotation "
                           "is 3.14 rad off the action's (the long way round, e.g. an Euler "
                           "angle crossing +-180 degrees); 1 key interval of 1 bone misses "
                           "by more than 0.05 rad")
    assert note.endswith("; bake with 2 samples per frame to follow it")


def test_interpolation_note_is_none_for_smooth_motion_and_says_when_16_do_not_do():
    times = np.arange(0.0, 20.0, 0.5)                       # 2 samples per frame
    smooth = lambda t: 0.3 * np.sin(t / 3)                  # noqa: E731
    keys = euler_z_keys(smooth, times)
    assert interpolation_note("Calm", times, keys, lambda t: euler_z_keys(smooth, t),
                              ("root", "arm"), samples_per_frame=2) is None
    # a jump no sampling follows: a constant curve stepping from 0 to 2 rad at frame 7.2
    step = lambda t: np.where(t < 7.2, 0.0, 2.0)            # noqa: E731
    note = interpolation_note("Jump", times, euler_z_keys(step, times),
                              lambda t: euler_z_keys(step, t), ("root", "arm"),
                              samples_per_frame=2)
    assert "between the keys at frames 7 and 7.5" in note
    assert note.endswith("; 16 samples per frame still miss by 1.00 rad there")


def test_between_key_misses_carried_as_differences_equal_composed_poses():
    """The hierarchy pass (misses carried down as differences, float32) against both
    poses composed as model matrices in float64 and compared: heads and rotations,
    with a misses from 1e-4 to a half turn and an armature scaled 100x."""
    from crowd_addon.core.base import pose as sqt
    from crowd_addon.core.bake.between_keys import between_key_misses
    from crowd_addon.core.base.skinning import model_matrices
    from crowd_addon.core.authoring.synthetic import humanoid

    sk = humanoid("fan", 82)
    rng = np.random.default_rng(3)
    n = 40
    lo = np.repeat(sk.bind_pose[None].astype(np.float32), n, 0)
    q = rng.normal(0, 1, (n, sk.bone_count, 4))
    lo[..., 3:7] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    hi = lo.copy()
    hi[..., 3:7] += rng.normal(0, 0.1, hi[..., 3:7].shape)
    hi[..., 3:7] /= np.linalg.norm(hi[..., 3:7], axis=-1, keepdims=True)
    hi[..., 7:10] += rng.normal(0, 0.01, hi[..., 7:10].shape)
    true = sqt.blend2(lo, hi, np.float32(0.5))
    size = 10.0 ** rng.uniform(-4, -1, (n, sk.bone_count, 1))
    true[..., 3:7] += rng.normal(0, 1, (n, sk.bone_count, 4)) * size
    true[..., 7:10] += rng.normal(0, 1, (n, sk.bone_count, 3)) * size
    true[0, 5, 3:7] = -true[0, 5, [4, 3, 6, 5]] * [1, -1, 1, -1]  # a half turn off
    true[..., 3:7] /= np.linalg.norm(true[..., 3:7], axis=-1, keepdims=True)
    position, rotation = between_key_misses(lo, hi, true, sk, unit_scale=100.0)
    a = model_matrices(sqt.blend2(lo, hi, np.float32(0.5)).astype(np.float64), sk)
    b = model_matrices(true.astype(np.float64), sk)
    want_position = np.linalg.norm(a[..., :3, 3] - b[..., :3, 3], axis=-1) * 100
    ra, rb = a[..., :3, :3], b[..., :3, :3]
    chord = np.linalg.norm(ra - rb, axis=(-2, -1)) / (2 * np.sqrt(2))
    want_rotation = 2 * np.arcsin(np.minimum(chord, 1))
    assert rotation.max() > 3.0                                 # the half turn is seen
    np.testing.assert_allclose(position, want_position, rtol=1e-3, atol=2e-4)
    np.testing.assert_allclose(rotation, want_rotation, rtol=1e-3, atol=2e-6)
