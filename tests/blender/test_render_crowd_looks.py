"""Render Crowd's looks (issue 34, item 4): a looking agent's head turn rounded to
aim classes of ``AIM_STEP`` in yaw and pitch, so pose meshes stay shared.

Oracles: core's look stage (``Crowd.agent_rows``, core/runtime/look_at.py) for the exact
turn; the head's forward of the rounded rows within the rounding's bound of it; agents
without a look drawn exactly as core draws them."""

import math
import os
import sys

import numpy as np
import pytest

pytest.importorskip("bpy")

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(__file__)), "gpu"))
import backend_scenes as scenes  # noqa: E402
from crowd_addon.blender import render_pieces  # noqa: E402
from crowd_addon.core.runtime.look_at import LookRig, LookTarget, head_direction  # noqa: E402


def looking_crowd():
    cfg = scenes.c.make_config(M=8, agents=40)
    cfg.look_rigs["fan"] = LookRig(("neck", "head"), (0.4, 0.6),
                                   yaw_limit=math.radians(70), pitch_limit=math.radians(35))
    t = np.arange(60.0)
    cfg.look_targets["ball"] = LookTarget(
        "ball", 0, np.c_[4 + 8 * np.cos(t / 7), 4 + 8 * np.sin(t / 7), 2 + np.sin(t / 4)])
    crowd = scenes.c.Crowd(cfg)
    crowd.look_at(np.arange(0, 40, 2), "ball", blend=2)
    for _ in range(5):
        crowd.step()
    return crowd


def test_aim_classes_round_the_head_turn_and_leave_the_others_exact():
    crowd = looking_crowd()
    ev = np.arange(crowd.agents.count)
    aim, turns = render_pieces.aim_classes(crowd)
    assert (aim[1::2] == 0).all() and (aim[::2] > 0).all()
    # every class is a whole number of steps
    steps = turns / render_pieces.AIM_STEP
    np.testing.assert_allclose(steps, np.rint(steps), atol=1e-9)
    rows = render_pieces.aimed_rows(crowd, ev, aim, turns)
    exact = crowd.agent_rows(ev)
    np.testing.assert_array_equal(rows[1::2], exact[1::2])       # not looking: as core
    chain = crowd.view.look_chains[0]
    a, b = head_direction(exact, chain)[1], head_direction(rows, chain)[1]
    err = np.degrees(np.arccos(np.clip((a * b).sum(1), -1, 1)))
    bound = np.degrees(render_pieces.AIM_STEP) * math.sqrt(2) / 2 + 0.05
    assert 0 < err[::2].max() <= bound                            # rounded, no further
    # agents of one pose row and one class get one pose mesh's rows
    key = crowd.view.agent_rows_index(ev) * turns.shape[0] + aim
    for k in np.unique(key):
        same = np.flatnonzero(key == k)
        np.testing.assert_array_equal(rows[same], np.broadcast_to(rows[same[0]],
                                                                  rows[same].shape))
