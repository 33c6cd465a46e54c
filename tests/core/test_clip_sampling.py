"""Clip key times and marker events of a baked action (crowd_addon.core.clip_sampling).
The same through Blender actions: tests/blender/test_bake.py."""

import numpy as np
import pytest

from crowd_addon.core.clip_sampling import marker_events, sample_times
from crowd_addon.core.errors import CrowdError


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
