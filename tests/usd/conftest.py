"""A small crowd shot with every kind of agent, recorded and exported once per module,
and the core oracle: the same crowd run again frame by frame (skinned on the CPU),
driven by the same simulation.

Two characters (24- and 26-bone humanoids, so poses are padded to the larger one),
three streams (a clip, a 2-way blend, a state machine driven by a trigger), one
unique, M = 8, NT = 3 (so one request waits in the queue). During the shot, agents
blend to another stream (also from the first frame, and on the last one, and again
while blending), blend to the unique, are cut to another (stream, offset), queue for a slot, and move; one agent
plays the unique from the start.
"""

from __future__ import annotations

import numpy as np
import pytest

from crowd_addon.core import Blend2, ClipPlayer, Crowd, CrowdConfig, StateMachine, StateTransition
from crowd_addon.core.shots.recorder import record
from crowd_addon.core.authoring.synthetic import humanoid, humanoid_mesh, periodic_clip

FIRST, LAST = 2, 16        # start_frame is 0: frames 1 and 2 run before the shot
FAN_AGENTS, KID_AGENTS = 40, 6
UNIQUE_FROM_START = 39


def make_config() -> CrowdConfig:
    """A fresh configuration (callbacks below mutate crowd arrays, so never share one)."""
    fan, kid = humanoid("fan", 24), humanoid("kid", 26)
    cfg = CrowdConfig(max_offset=8, transition_slots=3, seed=5)
    for sk in (fan, kid):
        cfg.add_skeleton(sk)
        cfg.add_mesh(humanoid_mesh(sk), lods=())
    for i in range(3):
        cfg.add_clip(periodic_clip(fan, f"fan{i}", frames=13 + 6 * i, seed=i,
                                   events=[("clap", 4.0)] if i == 0 else ()))
    cfg.add_clip(periodic_clip(kid, "kid0", frames=17, seed=9, events=[("jump", 2.5)]))
    cfg.add_stream("idle", "fan", ClipPlayer("fan0"))
    cfg.add_stream("cheer.loud", "fan", Blend2(ClipPlayer("fan1"), ClipPlayer("fan2"),
                                               weight=0.3))
    cfg.add_stream("wave", "fan", StateMachine(
        {"calm": ClipPlayer("fan0"), "wild": ClipPlayer("fan2")},
        [StateTransition("calm", "wild", 3, trigger="go")]))
    cfg.add_stream("kid play", "kid", ClipPlayer("kid0"))
    cfg.add_unique("solo", "fan", ClipPlayer("fan2"))
    rng = np.random.default_rng(0)
    offsets = np.arange(FAN_AGENTS) % 5             # repeated (stream, offset) keys
    cfg.add_agents(FAN_AGENTS, streams=np.arange(FAN_AGENTS) % 3, offsets=offsets,
                   positions=rng.uniform(-8, 8, (FAN_AGENTS, 3)),
                   headings=rng.uniform(-3, 3, FAN_AGENTS),
                   scales=np.where(np.arange(FAN_AGENTS) % 4 == 0, 1.0,     # some not scaled
                                   rng.uniform(0.8, 1.25, FAN_AGENTS)))
    cfg.add_agents(KID_AGENTS, streams="kid play", offsets=np.arange(KID_AGENTS),
                   positions=rng.uniform(-8, 8, (KID_AGENTS, 3)),
                   headings=rng.uniform(-3, 3, KID_AGENTS))
    cfg.agent_stream[UNIQUE_FROM_START] = -1
    cfg.agent_unique[UNIQUE_FROM_START] = 0
    return cfg


def simulate(crowd, frame):
    """The shot's simulation: before_step(crowd, frame) before the step into ``frame``."""
    if frame == 1:
        crowd.transition_to_streamed([9], "idle", 1, offset=2)     # done before FIRST
    if frame == FIRST:
        crowd.transition_to_streamed([11], "idle", 3)               # blends from FIRST
    if frame == LAST:
        crowd.transition_to_streamed([12], "cheer.loud", 4, offset=6)   # on LAST only
    if frame == 4:
        crowd.transition_to_streamed([1, 2], "cheer.loud", 4, offset=3)
    if frame == 5:
        crowd.transition_to_unique([3], "solo", 3)
        crowd.transition_to_streamed([6], "idle", 5)                # queued: NT = 3
    if frame == 6:
        crowd.transition_to_streamed([2], "idle", 3)                # mid-blend: reuses its slot
    if frame == 7:
        crowd.transition_to_streamed([4], "cheer.loud", 0, offset=5)   # a cut
        crowd.set_trigger("wave", "go")
    if frame == 9:
        crowd.place_agents([7], position=crowd.view.agents.position[7] + (0.5, -0.25, 0.0))
        crowd.place_agents([8], heading=crowd.view.agents.heading[8] + 0.75)


#: agents whose animation is not one (stream, offset) during FIRST..LAST
DYNAMIC = {1, 2, 3, 4, 6, 11, 12, UNIQUE_FROM_START}
MOVING = {7, 8}


@pytest.fixture(scope="module")
def oracle():
    return core_truth()


def core_truth():
    """Core's truth per shot frame: local poses (N, B, 10), positions, headings,
    ``(kind, ref, offset)`` per agent (N, 3), every event delivered to each agent
    as ``(agent, name, frame)``, and the agents' scales (constant)."""
    crowd = Crowd(make_config())
    view = crowd.view
    events = set()
    crowd.on_event("*", lambda name, frame, ids: events.update(
        (int(a), name, int(frame)) for a in ids))
    out = {"poses": {}, "position": {}, "heading": {}, "animation": {}}
    while crowd.frame < LAST:
        simulate(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame >= FIRST:
            a = view.agents
            out["poses"][crowd.frame] = view.agent_poses()
            out["position"][crowd.frame] = np.array(a.position, np.float64)
            out["heading"][crowd.frame] = np.array(a.heading, np.float64)
            out["scale"] = np.array(a.scale, np.float64)
            out["animation"][crowd.frame] = np.stack([a.kind, a.ref, a.offset],
                                                     1).astype(np.int64)
    out["events"] = {e for e in events if FIRST <= e[2] <= LAST}
    return out


def core_samples(substeps):
    """Core's truth at every sample time ``F + k / N`` of the shot (``N = substeps``):
    ``{(F, k): (local poses (N, B, 10), positions, headings)}``, read through
    ``view.agent_poses(sub=k)`` from a crowd that keeps the samples."""
    crowd = Crowd(make_config(), substeps=substeps)
    out = {}
    while crowd.frame < LAST:
        simulate(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame >= FIRST:
            a = crowd.view.agents
            for k in range(substeps):
                out[crowd.frame, k] = (crowd.view.agent_poses(sub=k),
                                       np.array(a.position, np.float64),
                                       np.array(a.heading, np.float64))
    return out


def recording(config=None, frames=(FIRST, LAST), before_step=simulate):
    """The shot recorded (a crowd that skins nothing, as exports use)."""
    return record(Crowd(config or make_config(), skinning="gpu"), *frames, before_step=before_step)


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """The shot recorded once and exported as text USD: ``(ExportResult, path)``."""
    from crowd_addon.usd import export_crowd

    path = tmp_path_factory.mktemp("shot") / "shot.usda"
    return export_crowd(recording(), path), path
