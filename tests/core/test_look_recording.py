"""Looks in a recording (issue 34, item 5): the recorder keeps each agent's look (target,
start, blend, stop) when it changes, so the recording alone rebuilds core's
``Crowd.agent_rows`` (looks applied) at every frame, and the same turn as local poses.

Oracle: a crowd run again with the same simulation, read through ``agent_rows``.
"""

import numpy as np

from crowd_addon.core import Crowd
from crowd_addon.core.shots.recorder import record
from crowd_addon.core.authoring.show import Action, Cue, Show
from crowd_addon.core.base.skinning import skinning_matrices
from .test_look_at import SK, crowd_config

FIRST, LAST = 4, 40


def show():
    return Show((Cue("watch", 8, Action("look", "ball", duration=5, hold=14),
                     agents=np.arange(0, 16, 2)),))


def simulate(crowd, frame):
    if frame == 3:
        crowd.look_at([1, 3], "ball", blend=0)              # looking before the shot
    if frame == 10:
        crowd.transition_to_streamed([0, 1, 5], "idle", 6, offset=4)   # while looking
    if frame == 14:
        crowd.look_at([5, 7], "ball", blend=3)
    if frame == 20:
        crowd.look_away([3, 5], blend=6)
    if frame == 24:
        crowd.place_agents([7], position=crowd.view.agents.position[7] + (0.0, 3.0, 0.0))
    if frame == 30:
        crowd.look_at([9], "ball", blend=2, hold=4)


def truth():
    crowd = Crowd(crowd_config(show()))
    out = {}
    while crowd.frame < LAST:
        simulate(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame >= FIRST:
            out[crowd.frame] = (crowd.agent_rows(), crowd.looks.weights(crowd.frame,
                                                                        np.arange(16)))
    return out


def test_the_recording_rebuilds_the_looked_rows_at_every_frame():
    rec = record(Crowd(crowd_config(show()), skinning="gpu"), FIRST, LAST, before_step=simulate)
    want = truth()
    ids = np.arange(16)
    seen = set()
    for f, (rows, w) in want.items():
        frame = np.full(16, f)
        np.testing.assert_allclose(rec.look_weights(frame, ids), w, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rec.agent_rows(f), rows, rtol=0, atol=1e-5, err_msg=str(f))
        # the same turn as local poses (chain joints' rotations): skinned, the same rows
        looked = rec.looked_pair_poses(frame, ids)
        np.testing.assert_allclose(skinning_matrices(looked, SK)[:, :, :3, :], rows,
                                   rtol=0, atol=1e-5, err_msg=str(f))
        seen.update(np.flatnonzero(w > 0).tolist())
    assert {0, 1, 3, 5, 7, 9} <= seen and 15 not in rec.looking.nonzero()[0]
    assert rec.looking[[0, 1, 3, 5, 7, 9]].all() and not rec.looking[[11, 13, 15]].any()
    # a row per look started or stopped, none per frame
    assert rec.look_agent.size <= 2 + 8 + 2 + 2 + 1 + 1


def test_a_recording_without_looks_has_no_look_rows():
    cfg = crowd_config()
    rec = record(Crowd(cfg, skinning="gpu"), 2, 6)
    assert not rec.has_looks and rec.look_agent.size == 0 and not rec.looking.any()
    rows = rec.agent_rows(np.arange(2, 7))
    crowd = Crowd(crowd_config())
    crowd.advance_to(6)
    np.testing.assert_allclose(rows[-1], crowd.agent_rows(), atol=1e-5)
