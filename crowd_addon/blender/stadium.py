"""The demo stadium's crowd, authored the way an animator would in Blender.

:func:`setup_crowd` fills the scene's Crowd settings of a stadium built by
``sample_scenes/build_stadium.py`` with both of its characters: "Fan" (the fan rig
and body, one stream per authored action that seats play or react with, one unique
per agent that can be hit by the ball) and "Mocap" (the motion-capture rig and body
with one looping stream, the jumps), M = 60 and the paper's 800 transition slots, and
the "Seats" points as the agent source: heading from their ``heading`` attribute,
character from a ``character`` attribute and stream (among the character's) from a
``stream`` attribute written here: home seats play ``idle_a`` / ``idle_c`` /
``clap``, away seats ``idle_b``, and 2 % of the home seats are the mocap character.
:func:`stadium_config` converts it with the extension's own
:func:`~crowd_addon.blender.scene_config.config_from_scene` and gives the agents
team colours. :func:`author_stadium` does it all on a built ``stadium.blend`` and
saves the file with its settings, so the file holds every character of the show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.config import CrowdConfig
from ..core.errors import CrowdError

__all__ = ["STREAMS", "HOME_MIX", "AWAY_MIX", "FAN", "MOCAP", "setup_crowd",
           "stadium_config", "Stadium", "author_stadium"]

#: stream name -> action of FanRig
STREAMS = {"idle_a": "idle_seated_a", "idle_b": "idle_seated_b", "idle_c": "idle_seated_c",
           "clap": "clap", "cheer": "cheer", "wave": "wave_arms", "groan": "disappointment"}
HOME_MIX = {"idle_a": 0.3, "idle_c": 0.3, "clap": 0.4}
AWAY_MIX = {"idle_b": 1.0}
HIT = "hit_by_ball"
MOCAP_ACTION, MOCAP_SHARE = "mocap_01_01", 0.02
#: the characters: name -> (armature, body)
FAN, MOCAP = "Fan", "Mocap"
CHARACTERS = {FAN: ("FanRig", "FanBody"), MOCAP: ("MocapRig", "MocapBody")}


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


def _animation(pool, name, action):
    anim = pool.add()
    anim.name = name
    node = anim.nodes.add()
    node.name, node.kind, node.action = "clip", "CLIP", _action(action)
    return anim


def _add_characters(s, hits):
    s.characters.clear()
    for name, (rig, body) in CHARACTERS.items():
        c = s.characters.add()
        c.name, c.armature, c.body = name, _obj(rig), _obj(body)
    fan, mocap = s.characters[FAN], s.characters[MOCAP]
    for name, action in STREAMS.items():
        _animation(fan.streams, name, action)
    for k in range(hits):
        _animation(fan.uniques, f"hit{k}", HIT)
    _action(MOCAP_ACTION).use_cyclic = True     # the jumps loop (its manual frame range)
    _animation(mocap.streams, "mocap", MOCAP_ACTION)


def _seat_attribute(me, name, values):
    attr = me.attributes.get(name) or me.attributes.new(name, "INT", "POINT")
    attr.data.foreach_set("value", values)


def _seat_casting(seats, seed):
    """Per seat: character (0 fan, 1 mocap) and stream index among its character's
    streams, written as the ``character`` and ``stream`` point attributes."""
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
    character = np.zeros(n, np.int32)
    home = np.flatnonzero(section == 0)
    jumpers = np.random.default_rng(seed + 1).choice(
        home, size=max(1, int(MOCAP_SHARE * home.size)), replace=False)
    character[jumpers] = 1
    stream[jumpers] = 0                     # the mocap character's only stream
    _seat_attribute(me, "character", character)
    _seat_attribute(me, "stream", stream)
    me.update()


def setup_crowd(scene, hits=6, slots=800, max_offset=60, seed=5):
    """Author the Crowd settings of a stadium scene (replacing any there)."""

    s = scene.crowd
    s.max_offset, s.transition_slots, s.seed = max_offset, slots, seed
    s.when_full = "QUEUE"
    s.forward_axis = "NEG_Y"
    _add_characters(s, hits)
    s.agent_sources.clear()
    seats = _obj("Seats")
    _seat_casting(seats, seed)
    src = s.agent_sources.add()
    src.name, src.object, src.mode = "seats", seats, "VERTICES"
    src.heading_mode, src.heading_attribute = "ATTRIBUTE", "heading"
    src.character_mode, src.character_attribute = "ATTRIBUTE", "character"
    src.stream_mode, src.stream_attribute = "ATTRIBUTE", "stream"
    src.offset_mode = "UNIFORM"
    src.color_mode = "RANDOM"
    return s


def stadium_config(scene, progress=None, hits=6, slots=800, seed=5) -> Stadium:
    """The stadium's :class:`Stadium` from a built stadium scene (see module doc)."""

    from ..blender.scene_config import config_from_scene

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
    fan = np.array([d.skeleton == FAN for d in cfg.streams])[cfg.agent_stream]
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
