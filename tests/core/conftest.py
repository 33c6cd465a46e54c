"""Fixtures shared by the core tests."""

import numpy as np
import pytest

from crowd_addon.core import Crowd, CrowdConfig
from crowd_addon.core.authoring import synthetic
from crowd_addon.core.anim.controllers import ClipPlayer


@pytest.fixture
def two_streams():
    """``two_streams(slots, agents, stream_of=None)``: a small crowd, M = 6, a 24-bone
    humanoid, streams "walk" (period 8) and "idle" (period 12); agents on the streams
    ``stream_of`` gives (default all on "walk")."""
    def make(slots, agents=12, stream_of=None):
        skel = synthetic.humanoid(bones=24)
        cfg = CrowdConfig(max_offset=6, transition_slots=slots)
        cfg.add_skeleton(skel)
        for name, period in (("walk", 9), ("idle", 13)):
            cfg.add_clip(synthetic.periodic_clip(skel, name, frames=period, seed=period))
            cfg.add_stream(name, skel.name, ClipPlayer(name))
        streams = np.zeros(agents, np.int64) if stream_of is None else stream_of
        cfg.add_agents(agents, streams=streams, seed=3)
        return Crowd(cfg)
    return make
