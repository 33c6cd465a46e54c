"""The demo stadium's crowd, authored the way an animator would in Blender.

:func:`setup_crowd` fills the scene's Crowd settings of a stadium built by
``sample_scenes/build_stadium.py``: the fan rig and body, one stream per authored
action that seats play or react with, one unique per agent that can be hit by the
ball, M = 60 and the paper's 800 transition slots, and the "Seats" points as the
agent source (heading from their ``heading`` attribute, stream from a ``stream``
attribute written here: home seats play ``idle_a`` / ``idle_c`` / ``clap``, away seats
``idle_b``). :func:`stadium_config` converts it with the extension's own
:func:`~crowd_addon.blender.scene_config.config_from_scene`, then adds the motion
capture character (a second skeleton) for a few home seats. :func:`author_stadium`
does it all on a built ``stadium.blend`` and saves the file with its settings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.config import CrowdConfig
from ..core.controllers import ClipPlayer
from ..core.errors import CrowdError

__all__ = ["STREAMS", "HOME_MIX", "AWAY_MIX", "setup_crowd", "stadium_config", "Stadium",
           "author_stadium"]

#: stream name -> action of FanRig
STREAMS = {"idle_a": "idle_seated_a", "idle_b": "idle_seated_b", "idle_c": "idle_seated_c",
           "clap": "clap", "cheer": "cheer", "wave": "wave_arms", "groan": "disappointment"}
HOME_MIX = {"idle_a": 0.3, "idle_c": 0.3, "clap": 0.4}
AWAY_MIX = {"idle_b": 1.0}
HIT = "hit_by_ball"
MOCAP_ACTION, MOCAP_SHARE = "mocap_01_01", 0.02


@dataclass
class Stadium:
    """A stadium crowd ready to run: the config and what the show needs per agent."""

    config: CrowdConfig
    seat_angle: np.ndarray          # (N,) radians around the bowl's centre
    home: np.ndarray                # (N,) bool
    fan: np.ndarray                 # (N,) bool, on the fan rig (the show's actors)
    hits: tuple                     # unique names, one per agent the ball may hit
    hit_frames: int


def _obj(name):
    obj = bpy.data.objects.get(name)
    if obj is None:
        raise CrowdError(f"stadium scene: object {name!r} is missing (build it with "
                         "sample_scenes/build_stadium.py)")
    return obj


def _action(name):
    act = bpy.data.actions.get(name)
    if act is None:
        raise CrowdError(f"stadium scene: action {name!r} is missing")
    return act


def setup_crowd(scene, hits=6, slots=800, max_offset=60, seed=5):
    """Author the Crowd settings of a stadium scene (replacing any there)."""

    s = scene.crowd
    s.armature = _obj("FanRig")
    s.proxy_mesh = _obj("FanBody")
    s.max_offset, s.transition_slots, s.seed = max_offset, slots, seed
    s.when_full = "QUEUE"
    s.forward_axis = "NEG_Y"
    s.streams.clear()
    s.uniques.clear()
    s.agent_sources.clear()
    for pool, items in (("streams", STREAMS.items()),
                        ("uniques", [(f"hit{k}", HIT) for k in range(hits)])):
        for name, action in items:
            anim = getattr(s, pool).add()
            anim.name = name
            node = anim.nodes.add()
            node.name, node.kind, node.action = "clip", "CLIP", _action(action)
    seats = _obj("Seats")
    me = seats.data
    n = len(me.vertices)
    section = np.zeros(n, np.int32)
    me.attributes["section"].data.foreach_get("value", section)
    rng = np.random.default_rng(seed)
    names = list(STREAMS)
    stream = np.empty(n, np.int32)
    for side, mix in ((0, HOME_MIX), (1, AWAY_MIX)):
        m = section == side
        ids = [names.index(k) for k in mix]
        stream[m] = rng.choice(ids, size=int(m.sum()), p=np.array(list(mix.values())))
    attr = me.attributes.get("stream") or me.attributes.new("stream", "INT", "POINT")
    attr.data.foreach_set("value", stream)
    me.update()
    src = s.agent_sources.add()
    src.name, src.object, src.mode = "seats", seats, "VERTICES"
    src.heading_mode, src.heading_attribute = "ATTRIBUTE", "heading"
    src.stream_mode, src.stream_attribute = "ATTRIBUTE", "stream"
    src.offset_mode = "UNIFORM"
    src.color_mode = "RANDOM"
    return s


def stadium_config(scene, progress=None, hits=6, slots=800, seed=5) -> Stadium:
    """The stadium's :class:`Stadium` from a built stadium scene (see module doc)."""

    from ..blender.armature import proxy_mesh_from_object
    from ..blender.bake import bake_actions
    from ..blender.scene_config import config_from_scene, scene_fps

    setup_crowd(scene, hits=hits, slots=slots, seed=seed)
    cfg = config_from_scene(scene, progress)
    seats = _obj("Seats")
    n = len(seats.data.vertices)
    if cfg.agent_count != n:
        raise CrowdError(f"stadium: {cfg.agent_count} agents from {n} seats")
    section = np.zeros(n, np.int32)
    seats.data.attributes["section"].data.foreach_get("value", section)
    home = section == 0
    # team colours, varied per agent (the random colours of the source as variation)
    team = np.where(home[:, None], (0.85, 0.18, 0.15), (0.2, 0.35, 0.85))
    cfg.agent_color = (0.6 * team + 0.4 * cfg.agent_color).astype(np.float32)
    # the motion-capture character: a second skeleton on a few home seats
    rig, body = _obj("MocapRig"), _obj("MocapBody")
    baked = bake_actions(rig, [_action(MOCAP_ACTION)], scene_fps(scene), loop=True,
                         scene=scene, samples_per_frame=scene.crowd.samples_per_frame)
    skel = baked.skeleton
    cfg.add_skeleton(skel)
    clip = baked.clips[0]
    cfg.add_clip(clip)
    cfg.add_mesh(proxy_mesh_from_object(body, rig, skel))
    mocap = cfg.add_stream("mocap", skel.name, ClipPlayer(clip.name))
    rng = np.random.default_rng(seed + 1)
    fans = np.flatnonzero(home)
    jumpers = rng.choice(fans, size=max(1, int(MOCAP_SHARE * fans.size)), replace=False)
    cfg.agent_stream[jumpers] = mocap
    fan = np.ones(n, bool)
    fan[jumpers] = False
    pos = cfg.agent_position
    centre = 0.5 * (pos.min(0) + pos.max(0))
    angle = np.arctan2(pos[:, 1] - centre[1], pos[:, 0] - centre[0])
    hit_clip = cfg.clips[HIT]                   # its length in crowd frames, keys included
    hit_frames = int(math.ceil(hit_clip.frames_at(cfg.fps) - 1e-6)) + 1
    return Stadium(cfg, angle, home, fan, tuple(f"hit{k}" for k in range(hits)), hit_frames)


def author_stadium(blend, progress=None) -> Stadium:
    """Open the built ``blend``, author its crowd (:func:`setup_crowd`), bake it with the
    extension registered (:func:`stadium_config`; ``progress(done, total, message)``)
    and save the file with its Crowd settings. Returns the :class:`Stadium`."""
    from .registration import register, unregister
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    register()
    try:
        stadium = stadium_config(bpy.context.scene, progress=progress)
        bpy.context.preferences.filepaths.save_version = 0  # no stadium.blend1 backup
        bpy.ops.wm.save_mainfile(filepath=str(blend))       # with its crowd settings
    finally:
        unregister()
    return stadium
