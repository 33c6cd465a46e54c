"""Sub-frame samples (``Crowd(..., substeps=N)``): the poses at ``F + k / N`` that a
writer needs for motion blur. Oracles: the clip sampled at that time (a plain clip
stream), the crowd without substeps (keeping them changes nothing at whole frames,
events included), and the live crowd's ``view.agent_poses(sub=k)`` for the recording."""

import numpy as np
import pytest

from crowd_addon.core import Crowd, CrowdError
from crowd_addon.core.runtime.agents import TRANSITION, UNIQUE
from crowd_addon.core.shots.driver import FrameDriver
from crowd_addon.core.shots.recorder import Recorder
from crowd_addon.core.authoring.synthetic import paper_config

from .test_recording import FIRST, LAST, config, jump_reaction, simulate

N = 4


def paper(substeps):
    """Every controller kind (clips, blends, layers, blend spaces, state machines)."""
    return Crowd(paper_config(120, streams=10, max_offset=8, slots=12, bones=30),
                 skinning="gpu", substeps=substeps)


def drive(crowd, frame):
    if frame % 7 == 0:
        crowd.set_trigger(4, "goal" if frame % 14 else "calm")     # state machine fades
        crowd.set_parameter(1, "w", frame / 100)
    if frame % 5 == 0:
        crowd.transition_to_streamed(np.arange(frame % 40, frame % 40 + 9), frame % 10, 4)


@pytest.mark.parametrize("which", ["paper", "tags between frames"])
def test_keeping_substeps_changes_nothing_at_whole_frames(which):
    """The look-ahead leaves the state as it was: poses, state machines and events
    (tags at half frames, which a look-ahead crosses first) equal a crowd without."""
    if which == "paper":
        plain, sub = paper(1), paper(N)
    else:
        plain, sub = (Crowd(config(), skinning="gpu", substeps=n) for n in (1, N))
    heard = {id(plain): [], id(sub): []}
    for c in (plain, sub):
        c.on_event("*", lambda n, f, ids, c=c: heard[id(c)].append((n, f, ids.tolist())))
    for frame in range(1, 60):
        for c in (plain, sub):
            (drive if which == "paper" else simulate)(c, frame)
            c.step()
        np.testing.assert_array_equal(sub.view.agent_poses(), plain.view.agent_poses())
        np.testing.assert_array_equal(sub.view.stream_poses(), plain.view.stream_poses())
        assert sub.evaluator.states(4) == plain.evaluator.states(4)
    assert heard[id(sub)] == heard[id(plain)]
    assert {n for n, _, _ in heard[id(sub)]} == ({"clap"} if which == "paper"
                                                  else {"clap", "jump"})


def test_a_clip_stream_between_frames_is_its_clip_at_that_time():
    crowd = paper(N)
    for _ in range(9):
        crowd.step()
    entry = crowd.bank.entry("clip0", crowd.config.skeletons["fan"])   # stream0 plays clip0
    for k in range(1, N):
        want = crowd.bank.sample(np.array([entry]), np.array([crowd.frame + k / N]))[0]
        np.testing.assert_allclose(crowd.view.stream_poses(sub=k)[0], want, atol=1e-6)
    # a sub-frame sample lies between its frames (the clip moves smoothly)
    before = crowd.view.stream_poses()[0]
    crowd.step()
    assert 0 < np.abs(crowd.view.stream_poses(crowd.frame - 1, sub=2)[0] - before).max() \
        < np.abs(crowd.view.stream_poses()[0] - before).max()


def record_with_substeps():
    crowd = Crowd(config(), skinning="gpu", substeps=N)
    jump_reaction(crowd)
    seen = {}
    recorder = Recorder(crowd, FIRST, LAST)

    def look(crowd):
        v = crowd.view
        if v.frame >= FIRST:
            for k in range(N):
                seen[v.frame + k / N] = (v.agent_poses(sub=k), np.array(v.agents.kind))
    look(crowd)
    FrameDriver(crowd, simulate, [recorder.capture, look]).run(LAST)
    return recorder.finish(), seen


def test_the_recording_rebuilds_every_sample_the_crowd_showed():
    rec, seen = record_with_substeps()
    assert rec.substeps == N and rec.times.size == (LAST - FIRST + 1) * N
    np.testing.assert_array_equal(rec.times, sorted(seen))
    kinds = np.stack([k for _, k in seen.values()])
    assert (kinds == TRANSITION).any() and (kinds == UNIQUE).any()
    for t in rec.times:
        np.testing.assert_array_equal(rec.agent_poses(t), seen[t][0], err_msg=str(t))
    some = np.array([20, 3, 1, 0, 26])
    np.testing.assert_array_equal(rec.agent_poses(rec.times, some),
                                  np.stack([seen[t][0][some] for t in rec.times]))
    # a blending agent between frames follows its weight, not its frames' average
    blending = [t for t in rec.times if t % 1 and seen[t][1][1] == TRANSITION]
    assert blending
    with pytest.raises(CrowdError, match="not a sample time"):
        rec.agent_poses(FIRST + 0.1)


@pytest.mark.parametrize("bad", [0, 17, 2.0, True, "2"])
def test_bad_substeps_are_refused(bad):
    with pytest.raises(CrowdError, match="substeps"):
        Crowd(config(), substeps=bad)


def test_sub_samples_are_only_those_kept():
    crowd = Crowd(config(), skinning="gpu", substeps=2)
    crowd.step()
    with pytest.raises(CrowdError, match="0..1"):
        crowd.view.agent_poses(sub=2)
    with pytest.raises(CrowdError, match="not in the history"):
        crowd.view.stream_poses(crowd.frame - 6, sub=1)
