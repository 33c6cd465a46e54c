"""The look shot of the USD and Blender look tests (issue 34, item 5): conftest's shot
(transitions, a queue, a cut, a unique, moves) with a look rig on both characters and a
ball moving across the crowd; agents start looking before and during the shot, some
through a transition, some look away, one starts on the last frame. No pxr here
(Blender's tests import it beside bpy)."""

import math

import numpy as np

from crowd_addon.core import Crowd
from crowd_addon.core.runtime.look_at import LookChain, LookRig, LookTarget, head_direction

from .conftest import FIRST, LAST, make_config, simulate

#: agents that look: 1, 2 through transitions, 3 to the unique, 39 on the unique from the
#: start, 7 moved, 41 a kid, 20 static then looking away, 12 starting on the last frame
LOOKERS = [1, 2, 3, 5, 7, 12, 20, 39, 41, 43]
QUIET = [0, 4, 6, 11]                   # no look: shared and clip agents as before
AGENTS = LOOKERS + QUIET


def look_config():
    cfg = make_config()
    frames = np.arange(40)
    path = np.c_[-12 + 0.8 * frames, np.full(40, -14.0), 1.0 + 0.05 * frames]
    cfg.look_rigs = {"fan": LookRig(("neck", "head"), (0.4, 0.6)),
                     "kid": LookRig(("spine2", "neck", "head"), yaw_limit=math.radians(80))}
    cfg.look_targets = {"ball": LookTarget("ball", 0, path, smoothing=2.0)}
    return cfg


def simulate_looks(crowd, frame):
    simulate(crowd, frame)
    if frame == 1:
        crowd.look_at([1, 2, 20, 39, 41], "ball", blend=0)       # looking at FIRST
    if frame == 3:
        crowd.look_at([3, 5, 7, 43], "ball", blend=3)             # 3 blends to the unique
    if frame == 8:
        crowd.look_away([20, 5], blend=2)
    if frame == 11:
        crowd.look_at([20], "ball", blend=1, hold=2)              # again, briefly
    if frame == LAST:
        crowd.look_at([12], "ball", blend=0)                      # on LAST only


def chains(cfg):
    return [LookChain(cfg.look_rigs[n], sk) if n in cfg.look_rigs else None
            for n, sk in cfg.skeletons.items()]


def core_heads():
    """{frame: (N, 3) head forward in each agent's model space} and the weights."""
    crowd = Crowd(look_config())
    ch = chains(crowd.config)
    out, weights = {}, {}
    while crowd.frame < LAST:
        simulate_looks(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame >= FIRST:
            rows = crowd.agent_rows().astype(np.float64)
            f = np.zeros((rows.shape[0], 3))
            for k, c in enumerate(ch):
                m = crowd.agent_skeleton == k
                f[m] = head_direction(rows[m], c)[1]
            out[crowd.frame] = f
            weights[crowd.frame] = crowd.looks.weights(crowd.frame, np.arange(rows.shape[0]))
    return out, weights


def core_rows():
    """{frame: (agent_rows (N, B, 3, 4) float64, positions, headings)} and the scales."""
    crowd = Crowd(look_config())
    out = {}
    while crowd.frame < LAST:
        simulate_looks(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame >= FIRST:
            a = crowd.view.agents
            out[crowd.frame] = (crowd.agent_rows().astype(np.float64),
                                np.array(a.position, np.float64),
                                np.array(a.heading, np.float64))
    return out, np.array(crowd.view.agents.scale, np.float64), crowd.agent_skeleton.copy()
