"""The demo stadium's ball (issue 34, item 6): the fans in view follow it with their
heads.

Oracles: the seats' own ``team`` attribute and the "Pitch" object's bounds (which end is
the home end, where the goal goes in), and the heads' directions measured from the
skinning rows the crowd draws with (``Crowd.agent_rows``), in each agent's model space,
against the ball's sampled path read as the core defines it (smoothed, each fan its
seeded lag late); the same crowd without its look cue is the control.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import stadium, stadium_cast  # noqa: E402
from crowd_addon.core import Crowd  # noqa: E402
from crowd_addon.core.runtime.look_at import LookChain, head_direction  # noqa: E402
from crowd_addon.core.authoring.show import Show  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BUILDER = ROOT / "sample_scenes" / "build_stadium.py"
FRAMES = 240

extension = cs.extension_fixture()


@pytest.fixture(scope="module")
def built(extension, tmp_path_factory):
    # built for the Blender that runs (4.2 cannot read a .blend saved by 5.x), in a
    # process of its own (the builder resets the session to factory settings)
    blend = tmp_path_factory.mktemp("look_stadium") / "stadium.blend"
    run = subprocess.run([sys.executable, str(BUILDER), "--out", str(blend), "--quiet"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    st = stadium.stadium_config(bpy.context.scene, frames=FRAMES, size=(320, 180))
    return bpy.context.scene, st


def _yaw_pitch(v, forward):
    left = np.cross([0.0, 0.0, 1.0], forward)
    return (np.degrees(np.arctan2(v @ left, v @ forward)),
            np.degrees(np.arctan2(v[:, 2], np.hypot(v @ left, v @ forward))))


def _angle(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


def heads(crowd, targets):
    """Per agent, in its model space: the angle (degrees) between its head's forward
    and the direction to ``targets`` (n, 3, model space), and whether that direction
    lies within its rig's limits (then the head can point there)."""
    cfg = crowd.config
    ids = np.arange(crowd.agents.count)
    rows = crowd.agent_rows(ids).astype(np.float64)
    ang, inside = np.zeros(ids.size), np.zeros(ids.size, bool)
    for sk, name in enumerate(cfg.skeletons):
        m = crowd.agent_skeleton == sk
        chain = LookChain(cfg.look_rigs[name], cfg.skeletons[name])
        pivot, f = head_direction(rows[m], chain)
        d = targets[m] - pivot
        yaw, pitch = _yaw_pitch(d, chain.forward)
        inside[m] = (np.abs(yaw) < np.degrees(chain.rig.yaw_limit) - 2) & \
            (np.abs(pitch) < np.degrees(chain.rig.pitch_limit) - 2)
        ang[m] = _angle(f, d)
    return ang, inside


def _model(crowd, world):
    """(n, 3) world points ``world`` (n, 3) in each agent's model space."""
    a = crowd.agents
    d = world - a.position
    h = -a.heading.astype(np.float64)
    c, s = np.cos(h), np.sin(h)
    return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]],
                    1) / a.scale[:, None]


def test_the_stadium_has_look_rigs_and_the_ball_goes_into_the_home_goal(built):
    scene, st = built
    cfg = st.config
    assert cfg.look_rigs["Fan"].bones == ("neck", "head")
    assert cfg.look_rigs["Mocap"].bones == ("Neck", "Neck1", "Head")
    ball = cfg.look_targets[stadium.BALL_TARGET]
    assert ball.positions.shape == (FRAMES, 3) and ball.first == scene.frame_start
    np.testing.assert_allclose(ball.positions[0], [0, 0, stadium.BALL_RADIUS], atol=1e-6)
    # the home end: away from the away seats; the goal beat puts the ball in its net
    seats = bpy.data.objects["Seats"].data
    pos = np.array([v.co for v in seats.vertices])
    team = np.array([d.value for d in seats.attributes["team"].data])
    home_side = -np.sign(pos[team == stadium_cast.AWAY, 0].mean())
    half = 0.5 * np.ptp([v[0] for v in bpy.data.objects["Pitch"].bound_box])
    goal = scene.frame_start + 1 + int(stadium.BEATS["goal"] * FRAMES)
    at_goal = ball.positions[goal - ball.first]
    assert at_goal[0] * home_side > half and abs(at_goal[1]) < 3.66     # between the posts
    assert np.ptp(ball.positions[: goal - ball.first, :2], 0).min() > 10  # play over the pitch
    look = [c for c in cfg.show.cues if c.action.kind == "look"]
    assert len(look) == 1 and look[0].frame == scene.frame_start + 1
    # the fans in view: the stand the camera looks at, watching until after the goal
    in_view = np.array([d.value for d in seats.attributes["in_view"].data])
    np.testing.assert_array_equal(look[0].agents, np.flatnonzero(in_view))
    assert 0 < in_view.sum() < in_view.size
    cam = bpy.data.objects[stadium.CAMERA]
    pos_view = np.array([cam.matrix_world.inverted() @ v.co for v in seats.vertices])
    assert (pos_view[in_view == 1, 2] < 0).all()                # in front of the camera
    assert look[0].frame + look[0].action.hold == goal + stadium.BALL_WATCH
    assert (cfg.look_lag, cfg.look_max_lag) == ("seeded", stadium.BALL_LAG)
    # the ball moves: the renderers' one-frame scene geometry leaves it out
    assert stadium.BALL not in st.scene.objects and "Pitch" in st.scene.objects


@pytest.mark.parametrize("frame", [45, 60])   # the ball near and in the home goal
def test_the_fans_heads_follow_the_ball(built, frame):
    _, st = built
    cfg = st.config
    crowd = Crowd(cfg)
    crowd.advance_to(frame)
    ids = np.arange(crowd.agents.count)
    (cue,) = [c for c in cfg.show.cues if c.action.kind == "look"]
    watching = np.isin(ids, cue.agents)
    w = crowd.looks.weights(frame, ids)
    assert (w[watching] == 1).all() and (w[~watching] == 0).all()   # the fans in view
    seen = crowd.look_targets_model(ids)                          # smoothed, lag late
    ang, inside = heads(crowd, seen)
    ang, inside = ang[watching], inside[watching]
    assert inside.mean() > 0.9                 # the ball within reach for most fans
    assert ang[inside].max() < 1.0
    # and the ball now, not only as each fan saw it: heads on it within a few degrees
    now = _model(crowd, np.tile(cfg.look_targets[stadium.BALL_TARGET].at([frame]),
                                (ids.size, 1)))
    near = heads(crowd, now)[0][watching]
    assert np.median(near[inside]) < 10.0      # each a few frames late: a moving ball
    # the control: the same crowd without the look cue does not look at the ball
    cfg.show, show = Show(tuple(c for c in cfg.show.cues if c.action.kind != "look"),
                          cfg.show.reactions, cfg.show.tracks), cfg.show
    try:
        quiet = Crowd(cfg)
    finally:
        cfg.show = show
    quiet.advance_to(frame)
    before = heads(quiet, now)[0][watching]
    assert (near < before).mean() > 0.9                 # most heads turned toward it
    assert np.median(before) > np.median(near[inside]) + 20.0
