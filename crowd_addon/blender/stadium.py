"""The demo stadium's crowd and show, authored the way an animator would in Blender.

Everything the demo runs is scene data, so the saved ``stadium.blend`` holds it all
and ``crowd export --blend`` / ``crowd preview --blend`` in another process make the
same crowd:

- :func:`setup_crowd` fills the scene's Crowd settings of a stadium built by
  ``sample_scenes/build_stadium.py`` with both of its characters: "Fan" (the fan rig
  and body, one stream per authored action that seats play or react with, one unique
  per agent that can be hit by the ball) and "Mocap" (the motion-capture rig and body
  with one looping stream, the jumps), M = 60 and the paper's 800 transition slots,
  and the "Seats" points as the agent source. The seats get point attributes written
  here: ``character`` (0 fan, 1 mocap: 2 % of the home seats), ``stream`` (among the
  character's streams: home seats ``idle_a`` / ``idle_c`` / ``clap``, away seats
  ``idle_b``), ``hit`` (``k`` on the seat of the k-th fan the ball hits, 0 elsewhere),
  ``in_view`` (1 on the seats of the stand the camera looks at) and ``team_colour``
  (home red, away blue, varied per seat); the source scales the fans 0.93 .. 1.07
  (heights vary), and each fan draws a skin tone and trousers from
  the fan's palettes (:data:`FAN_PALETTES`, docs/variety.md), a body (a third of the
  fans wear the broader ``FanBodyBroad``, made from ``FanBody``) and props: a flag in
  the right hand for about one fan in seven, a cap for three in ten (:data:`FAN_PROPS`,
  objects parented to the fan rig's bones), both in the fan's team colour.
- :func:`setup_show` authors the show (``scene.crowd.show``, docs/show.md) and sets the
  scene's frame range to the run: the **goal**, a mass reaction (the seat streams are
  state machines that take it, :data:`REACTION_STATES`: the goal cues set
  ``celebrate`` on the home fans' streams and ``despair`` on the away fans', and
  ``calm`` when the cheer's hold ends, so every fan follows its stream at its own
  offset; only fans on other streams blend to ``cheer`` / ``groan`` through slots),
  the **Mexican wave** (a sweep round the pitch centre, the world origin, over the
  fans: it starts just before the home stand the camera looks at and takes the whole
  run for one lap, or longer where the transition slots could not carry a faster
  front round a full bowl; each fan stands ``WAVE_HOLD`` frames), the **hits** (one cue per hit fan, selected
  by its ``hit`` attribute, to its own unique animation; they interrupt the cheer) and
  nothing for the claps: they are the ``clap`` action's event tags, counted by the
  crowd (``crowd.events``). The **ball** ("Ball", a white sphere made here) is played
  over the pitch from the centre spot and goes into the net of the home end's goal
  (the end away from the away seats) at the goal beat; it is the show's look target
  ``ball``, and a Look At cue on the first frame stepped turns the heads of the fans
  in view (the camera's stand: the seats' ``in_view`` attribute) toward it until
  :data:`BALL_WATCH` frames after the goal (:data:`LOOK_RIGS`: neck and head, the
  mocap's Neck, Neck1 and Head), each fan up to :data:`BALL_LAG` frames late
  (docs/show.md, "Look-at"). The beats are fractions
  of the run (:data:`BEATS`), so a short run has all of them; a beat that still falls
  after the run's last frame (a run of one frame) is authored muted and named in
  :attr:`Stadium.muted`.
- :func:`add_stand_camera` adds "StandCamera", on the pitch looking up at the home
  stand where the wave passes first, as the scene camera: the demo renders through it.

:func:`stadium_config` does all three and converts the scene with the extension's
own :func:`~crowd_addon.blender.scene_config.config_from_scene`;
:func:`author_stadium` does it on a built ``stadium.blend`` and saves the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import bpy
import numpy as np

from ..core.authoring.config import CrowdConfig
from ..core.base.errors import CrowdError
from .looks import plain_material

__all__ = ["STREAMS", "HOME_MIX", "AWAY_MIX", "FAN", "MOCAP", "BEATS", "CUES", "CAMERA",
           "LOOK_RIGS", "BALL", "BALL_TARGET",
           "setup_crowd", "setup_show", "add_stand_camera", "stadium_config", "Stadium",
           "author_stadium"]

#: stream name -> action of FanRig
STREAMS = {"idle_a": "idle_seated_a", "idle_b": "idle_seated_b", "idle_c": "idle_seated_c",
           "clap": "clap", "cheer": "cheer", "wave": "wave_arms", "groan": "disappointment"}
#: The seat streams are templates that take the goal (paper s.5): each is a state
#: machine whose seated state (the stream's own action) turns into a celebration or a
#: disappointment on a trigger from the show and back on ``calm``, so a goal switches
#: whole streams and every fan follows at its own offset, with no transition slot.
#: the triggers; state -> (action, the trigger that enters it); the cross-fade (frames)
CELEBRATE, DESPAIR, CALM = "celebrate", "despair", "calm"
REACTION_STATES = {"celebrating": ("cheer", CELEBRATE),
                   "despairing": ("disappointment", DESPAIR)}
REACTION_FADE = 6
SEAT_STREAMS = ("idle_a", "idle_b", "idle_c", "clap")
HOME_MIX = {"idle_a": 0.3, "idle_c": 0.3, "clap": 0.4}
AWAY_MIX = {"idle_b": 1.0}
HIT = "hit_by_ball"
MOCAP_ACTION, MOCAP_SHARE = "mocap_01_01", 0.02
#: the characters: name -> (armature, body)
FAN, MOCAP = "Fan", "Mocap"
CHARACTERS = {FAN: ("FanRig", "FanBody"), MOCAP: ("MocapRig", "MocapBody")}
HOME, AWAY = 0, 1                       # the seats' ``team`` attribute

#: When the beats start, as fractions of the run: a beat at share ``s`` of a run of
#: ``N`` frames from frame ``F`` starts at frame ``F + 1 + floor(s * N)`` (the first
#: frame stepped is ``F + 1``; in 240 frames from frame 1: the wave at 22, the goal at
#: 47, the hits at 72).
BEATS = {"wave": 20 / 240, "goal": 45 / 240, "hit": 70 / 240}
CHEER_SHARE = 90 / 240                  # how long the goal's cheer and groan are held
WAVE_LAP_SHARE = 1.0                    # one lap of the wave takes the whole run
WAVE_HOLD = 16                          # frames a fan stays up in the wave
WAVE_SLOTS = 0.75                       # the share of the slots the wave may take
BLEND = 6                               # blend length of every cue, frames
#: the wave starts just before the home stand the camera looks at (angle -pi/2)
WAVE_START_ANGLE = -math.pi / 2 - 0.4
#: cue names (the demo's summary reads their stats)
CUES = {"goal_home": "goal home", "goal_away": "goal away", "wave": "wave", "hit": "hit",
        "look": "follow the ball"}
#: the characters' look rigs (docs/show.md, "Look-at"): character -> (look bones,
#: parent first; their shares; yaw and pitch limits, degrees)
LOOK_RIGS = {"Fan": ("neck, head", "0.4, 0.6", 75.0, 50.0),
             "Mocap": ("Neck, Neck1, Head", "0.25, 0.25, 0.5", 75.0, 50.0)}
#: the ball the fans follow: the object, its radius (metres), the look target's name,
#: its smoothing (frames) and the most frames a fan sees it late (a seeded lag: the
#: streams' offsets, up to M = 60 frames, would leave some fans two seconds behind)
BALL, BALL_RADIUS, BALL_TARGET, BALL_SMOOTHING, BALL_LAG = "Ball", 0.2, "ball", 3.0, 6
#: the play before the goal: (share of the time from the run's first frame to the goal
#: beat, x toward the home goal and y, as shares of the pitch's half length and width);
#: at the goal beat the ball is in the net of the home end's goal (the goal the home
#: fans cheer), where it stays
BALL_PLAY = ((0.0, 0.0, 0.0), (0.25, -0.35, 0.45), (0.5, -0.05, -0.5), (0.75, 0.55, 0.3))
BALL_NET = (1.0, 0.02, 1.1)      # metres behind the goal line, y share, height
#: frames the fans in view keep watching after the goal beat before they look away: a
#: look costs a USD export a pose sample per looking agent and frame
#: (docs/usd_export.md, "Looks"), so the demo's looks are the camera's stand (the
#: seats' ``in_view`` attribute) up to a second after the goal, not the whole bowl for
#: the whole run
BALL_WATCH = 30
CAMERA = "StandCamera"
#: where the camera stands, in metres from the middle of the home stand's front row:
#: out over the pitch, along the stand, up; and how far along the stand it looks. The
#: stand's depth and height are added on (see add_stand_camera), so a 65,000-seat
#: stand is seen whole from further away.
CAMERA_OUT, CAMERA_SIDE, CAMERA_UP, CAMERA_LOOK = 14.0, 26.0, 6.0, 8.0
CAMERA_FOV = math.radians(40.0)                  # vertical


@dataclass
class Stadium:
    """A stadium crowd ready to run: the config (its show included), the camera the
    demo renders through, the beats muted because they fall after the run, and the
    stadium itself (bowl, pitch) with its sun as the renderers draw them."""

    config: CrowdConfig
    camera: object                  # crowd_addon.core.base.camera.Camera
    muted: tuple = ()
    scene: object = None            # crowd_addon.gpu.scene_geometry.SceneGeometry
    light: tuple | None = None      # the renderers' light from the scene's sun


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


def _reacting(anim):
    """Make a one-clip stream a template that takes the goal: a state machine over its
    clip ("seated") and the :data:`REACTION_STATES`, entered on their triggers from any
    state and left on ``calm``."""
    for state, (action, _) in REACTION_STATES.items():
        node = anim.nodes.add()
        node.name, node.kind, node.action = state, "CLIP", _action(action)
    sm = anim.nodes.add()
    sm.name, sm.kind, sm.initial_state = "react", "STATE_MACHINE", "seated"
    for state, node in (("seated", "clip"), *((s, s) for s in REACTION_STATES)):
        i = sm.inputs.add()
        i.name, i.node = state, node
    edges = [(s, trigger) for s, (_, trigger) in REACTION_STATES.items()] + [("seated", CALM)]
    for target, trigger in edges:
        tr = sm.transitions.add()
        tr.source, tr.target, tr.trigger, tr.duration = "*", target, trigger, REACTION_FADE
    anim.root = "react"
    return anim


#: the fans' palettes (docs/variety.md): body material -> colours, one per fan at random
FAN_PALETTES = {
    "fan_skin": ((0.92, 0.72, 0.58), (0.80, 0.55, 0.42), (0.62, 0.42, 0.30),
                 (0.42, 0.27, 0.18), (0.27, 0.17, 0.11)),
    "fan_trousers": ((0.12, 0.14, 0.25), (0.05, 0.05, 0.06), (0.55, 0.48, 0.36),
                     (0.25, 0.32, 0.45)),
}


#: the fan's second body (docs/variety.md): "FanBodyBroad", FanBody with its torso
#: (the vertices between the hips and the shoulders, near the spine) this much wider
BROAD_TORSO = 1.22
BROAD_SHARE = 0.35                      # of the fans; FanBody has the rest
#: the fans' props: object -> (bone it rides on, share of the fans carrying it, boxes
#: (centre and half sizes in the bone's rest frame -- y along the bone, from its head
#: -- and material)). White materials take each fan's team colour, as the shirt does.
#: The flag's pole carries on from the hand, so raised arms raise the flag.
FAN_PROPS = {
    "FanFlag": ("hand.R", 0.15, (((0.0, 0.40, 0.0), (0.012, 0.42, 0.012), "fan_pole"),
                                 ((0.0, 0.66, 0.23), (0.006, 0.15, 0.22), "fan_flag"))),
    "FanCap": ("head", 0.30, (((0.0, 0.195, 0.01), (0.095, 0.05, 0.105), "fan_cap"),
                              ((0.0, 0.16, 0.14), (0.075, 0.01, 0.05), "fan_cap"))),
}
_PROP_COLOURS = {"fan_pole": (0.30, 0.20, 0.12, 1.0), "fan_flag": (0.95, 0.95, 0.95, 1.0),
                 "fan_cap": (0.9, 0.9, 0.9, 1.0)}



def _broad_body(rig, body):
    """``FanBodyBroad`` (made once): a copy of the fan's body, skinned the same, with a
    wider torso."""
    obj = bpy.data.objects.get("FanBodyBroad")
    if obj is not None:
        return obj
    obj = body.copy()
    obj.data = body.data.copy()
    obj.name = obj.data.name = "FanBodyBroad"
    for coll in body.users_collection:
        coll.objects.link(obj)
    me = obj.data
    co = np.empty(3 * len(me.vertices), np.float64)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    torso = (np.abs(co[:, 0]) < 0.17) & (co[:, 2] > 0.9) & (co[:, 2] < 1.42)
    co[torso, :2] *= BROAD_TORSO
    me.vertices.foreach_set("co", co.astype(np.float32).ravel())
    me.update()
    obj.hide_render = body.hide_render
    return obj


def _fan_prop(rig, name, bone, boxes):
    """The prop object ``name`` (made once): its boxes as one mesh, parented to
    ``bone`` of ``rig`` where it sits at rest."""
    obj = bpy.data.objects.get(name)
    if obj is not None:
        return obj
    b = rig.data.bones[bone]
    frame = np.array(b.matrix_local, np.float64)
    unit = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3))
    verts, faces, mats, names = [], [], [], []
    for centre, half, material in boxes:
        base = len(verts)
        local = np.array(centre) + unit * half
        verts += [tuple(v) for v in local @ frame[:3, :3].T + frame[:3, 3]]
        faces += [tuple(base + i for i in q) for q in quads]
        if material not in names:
            names.append(material)
        mats += [names.index(material)] * len(quads)
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    for material in names:
        me.materials.append(plain_material(material, _PROP_COLOURS[material]))
    me.polygons.foreach_set("material_index", np.array(mats, np.int32))
    obj = bpy.data.objects.new(name, me)
    for coll in rig.users_collection:
        coll.objects.link(obj)
    world = rig.matrix_world @ obj.matrix_world
    tail = rig.matrix_world @ b.matrix_local @ _translation(b.length)
    obj.parent, obj.parent_type, obj.parent_bone = rig, "BONE", bone
    obj.matrix_parent_inverse = tail.inverted()
    obj.matrix_basis = world
    obj.hide_render = rig.hide_render   # a template, like the rig
    return obj


def _translation(y):
    from mathutils import Matrix
    return Matrix.Translation((0.0, y, 0.0))


def _add_characters(s, hits):
    s.characters.clear()
    for name, (rig, body) in CHARACTERS.items():
        c = s.characters.add()
        c.name, c.armature, c.body = name, _obj(rig), _obj(body)
    fan, mocap = s.characters[FAN], s.characters[MOCAP]
    for name, action in STREAMS.items():
        anim = _animation(fan.streams, name, action)
        if name in SEAT_STREAMS:
            _reacting(anim)
    for k in range(hits):
        _animation(fan.uniques, f"hit{k}", HIT)
    _action(MOCAP_ACTION).use_cyclic = True     # the jumps loop (its manual frame range)
    _animation(mocap.streams, "mocap", MOCAP_ACTION)
    for c in (fan, mocap):                      # heads that follow the ball
        c.look_bones, c.look_shares, yaw, pitch = LOOK_RIGS[c.name]
        c.look_yaw_limit, c.look_pitch_limit = math.radians(yaw), math.radians(pitch)
    for material, colours in FAN_PALETTES.items():    # each fan its skin and trousers
        pal = fan.palettes.add()
        pal.material, pal.mode, pal.count = material, "RANDOM", len(colours)
        for i, c in enumerate(colours):
            setattr(pal, f"color_{i}", c)
    variant = fan.variants.add()                      # heavier builds
    variant.object = _broad_body(fan.armature, fan.body)
    fan.body_weight, variant.weight = 1.0 - BROAD_SHARE, BROAD_SHARE
    for name, (bone, share, boxes) in FAN_PROPS.items():   # flags and caps
        prop = fan.props.add()
        prop.object, prop.share = _fan_prop(fan.armature, name, bone, boxes), share


def _seat_attribute(me, name, values, kind="INT"):
    attr = me.attributes.get(name)
    if attr is not None and attr.data_type != kind:
        me.attributes.remove(attr)
        attr = None
    attr = attr or me.attributes.new(name, kind, "POINT")
    attr.data.foreach_set("color" if kind == "FLOAT_COLOR" else "value",
                          np.ascontiguousarray(values).ravel())


def _seats():
    """The seats object, its positions (n, 3) and teams (n,: HOME or AWAY)."""
    seats = _obj("Seats")
    me = seats.data
    n = len(me.vertices)
    pos = np.zeros(n * 3, np.float32)
    me.vertices.foreach_get("co", pos)
    teams = np.zeros(n, np.int32)
    me.attributes["team"].data.foreach_get("value", teams)
    return seats, pos.reshape(n, 3), teams


def _camera_stand(pos, teams):
    """(n,) bool: the home seats of the near long side (about angle -pi/2 round the
    pitch centre), where the camera looks and the wave passes first."""
    angle = np.arctan2(pos[:, 1], pos[:, 0])
    near = np.abs(np.angle(np.exp(1j * (angle + np.pi / 2)))) < 0.35
    return near & (teams == HOME)


def _seat_casting(seats, teams, pos, seed, hits):
    """Per seat: character (0 fan, 1 mocap), stream index among its character's
    streams, which hit it takes (1..hits, 0 none) and a team colour, written as the
    ``character``, ``stream``, ``hit`` and ``team_colour`` point attributes."""
    me = seats.data
    n = teams.size
    rng = np.random.default_rng(seed)
    names = list(STREAMS)
    stream = np.empty(n, np.int32)
    for side, mix in ((HOME, HOME_MIX), (AWAY, AWAY_MIX)):
        m = teams == side
        ids = [names.index(k) for k in mix]
        stream[m] = rng.choice(ids, size=int(m.sum()), p=np.array(list(mix.values())))
    character = np.zeros(n, np.int32)
    home = np.flatnonzero(teams == HOME)
    jumpers = np.random.default_rng(seed + 1).choice(
        home, size=max(1, int(MOCAP_SHARE * home.size)), replace=False)
    character[jumpers] = 1
    stream[jumpers] = 0                     # the mocap character's only stream
    # the ball lands in the stand the camera looks at (any fan's seat if it has too few)
    fans = character == 0
    pool = np.flatnonzero(fans & _camera_stand(pos, teams))
    if pool.size < hits:
        pool = np.flatnonzero(fans)
    hit = np.zeros(n, np.int32)
    chosen = np.random.default_rng(seed + 2).choice(pool, size=min(hits, pool.size),
                                                    replace=False)
    hit[chosen] = np.arange(1, chosen.size + 1)
    # team colours, varied per seat
    team = np.where((teams == HOME)[:, None], (0.85, 0.18, 0.15), (0.2, 0.35, 0.85))
    vary = 0.8 + 0.5 * (np.random.default_rng(seed + 3).random((n, 3)) - 0.8)
    colour = np.ones((n, 4), np.float32)
    colour[:, :3] = 0.6 * team + 0.4 * vary
    _seat_attribute(me, "character", character)
    _seat_attribute(me, "stream", stream)
    _seat_attribute(me, "hit", hit)
    stand = _camera_stand(pos, teams)            # the fans in view follow the ball
    _seat_attribute(me, "in_view",
                    (stand if stand.any() else np.ones(n, bool)).astype(np.int32))
    _seat_attribute(me, "team_colour", colour, "FLOAT_COLOR")
    me.update()


def setup_crowd(scene, hits=6, slots=800, max_offset=60, seed=5):
    """Author the Crowd settings of a stadium scene (replacing any there): characters,
    the seats' attributes and the agent source. The show is :func:`setup_show`'s."""
    s = scene.crowd
    s.max_offset, s.transition_slots, s.seed = max_offset, slots, seed
    s.when_full = "QUEUE"
    s.forward_axis = "NEG_Y"
    _add_characters(s, hits)
    s.agent_sources.clear()
    seats, pos, teams = _seats()
    _seat_casting(seats, teams, pos, seed, hits)
    src = s.agent_sources.add()
    src.name, src.object, src.mode = "seats", seats, "VERTICES"
    src.heading_mode, src.heading_attribute = "ATTRIBUTE", "heading"
    src.character_mode, src.character_attribute = "ATTRIBUTE", "character"
    src.stream_mode, src.stream_attribute = "ATTRIBUTE", "stream"
    src.offset_mode = "UNIFORM"
    src.color_mode, src.color_attribute = "ATTRIBUTE", "team_colour"
    src.scale_min, src.scale_max = 0.93, 1.07            # fans of different heights
    return s


def _cue(show, name, frame, last, target, action="STREAM", hold=0, **props):
    c = show.cues.add()
    c.name, c.frame, c.action, c.target, c.hold = name, frame, action, target, hold
    c.duration = BLEND
    c.mute = frame > last
    for key, value in props.items():
        setattr(c, key, value)
    return c


def _select(attribute, value):
    return {"select": "ATTRIBUTE", "attribute": attribute, "op": "==", "compare": value}


def _wave_speed(scene, frames):
    """The wave's speed (radians a second): one lap in the run, or slower where the
    bowl is so full that a faster front would need more than :data:`WAVE_SLOTS` of the
    crowd's transition slots (a 65,000-seat bowl: the paper's 800 slots carry a wave
    that goes round in about a minute, as a real one does)."""
    from ..core.authoring.show import Sweep, slot_speed
    from .scene_config import scene_fps

    fps = scene_fps(scene)
    me = _obj("Seats").data
    n = len(me.vertices)
    pos = np.zeros(n * 3, np.float32)
    me.vertices.foreach_get("co", pos)
    character = np.zeros(n, np.int32)
    me.attributes["character"].data.foreach_get("value", character)
    lap = max(1, round(WAVE_LAP_SHARE * frames))
    sweep = Sweep(mode="angle", speed=2 * math.pi * fps / lap, start_angle=WAVE_START_ANGLE)
    slots = int(WAVE_SLOTS * scene.crowd.transition_slots)
    return slot_speed(sweep, pos.reshape(n, 3)[character == 0], fps, slots, BLEND)


def _home_goal_x() -> float:
    """x of the goal line at the home end of the pitch: the end away from the away
    seats (the seats' ``team``; west when there are none)."""
    _, pos, teams = _seats()
    half = _pitch_half()[0]
    away = pos[teams == AWAY]
    return half if away.size and away[:, 0].mean() < 0 else -half


def _pitch_half() -> tuple:
    """Half the pitch's length (x) and width (y), from the "Pitch" object's bounds."""
    from mathutils import Vector
    p = _obj("Pitch")
    box = np.array([tuple(p.matrix_world @ Vector(v)) for v in p.bound_box])
    return 0.5 * float(np.ptp(box[:, 0])), 0.5 * float(np.ptp(box[:, 1]))


def _ball(scene, first, goal):
    """The "Ball" (made once; its keys replaced): a small white sphere played over the
    pitch from the centre spot from frame ``first`` (:data:`BALL_PLAY`) into the net of
    the home end's goal at frame ``goal``, where it stays."""
    import bmesh
    obj = bpy.data.objects.get(BALL)
    if obj is None:
        me = bpy.data.meshes.new(BALL)
        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=BALL_RADIUS)
        bm.to_mesh(me)
        bm.free()
        me.materials.append(plain_material("ball", (0.95, 0.95, 0.95, 1.0)))
        obj = bpy.data.objects.new(BALL, me)
        scene.collection.objects.link(obj)
    obj.animation_data_clear()
    hx, hy = _pitch_half()
    gx = _home_goal_x()
    sign = 1.0 if gx > 0 else -1.0               # toward the home goal
    keys = [(first + round(share * (goal - first)), (sign * x * hx, y * hy, BALL_RADIUS))
            for share, x, y in BALL_PLAY]
    back, y, z = BALL_NET
    keys.append((goal, (gx + sign * back, y * hy, z)))
    done = set()
    for frame, at in keys:
        if frame in done:                         # a short run: fewer touches
            continue
        done.add(frame)
        obj.location = at
        obj.keyframe_insert("location", frame=frame)
    obj.location = keys[0][1]
    return obj


def setup_show(scene, frames: int):
    """Author the stadium's show in ``scene.crowd.show`` (replacing any there) for a run
    of ``frames`` frames from the scene's start frame, and set the scene's frame range
    to that run; one hit cue per seat :func:`setup_crowd` marked. Returns the names of
    the cues muted because they start after the run."""
    seats = _obj("Seats").data
    hit = np.zeros(len(seats.vertices), np.int32)
    if "hit" in seats.attributes:
        seats.attributes["hit"].data.foreach_get("value", hit)
    hits = int(hit.max(initial=0))
    if frames < 1:
        raise CrowdError(f"stadium show: frames must be at least 1, got {frames}")
    first = scene.frame_start
    last = scene.frame_end = first + frames - 1
    at = {beat: first + 1 + int(share * frames) for beat, share in BEATS.items()}
    show = scene.crowd.show
    show.cues.clear()
    show.reactions.clear()
    show.parameters.clear()
    cheer = max(1, round(CHEER_SHARE * frames))
    for name, team, target, trigger in ((CUES["goal_home"], HOME, "cheer", CELEBRATE),
                                        (CUES["goal_away"], AWAY, "groan", DESPAIR)):
        _cue(show, name, at["goal"], last, target, hold=cheer, offset_mode="GIVEN",
             offset=0, switch_trigger=trigger, release_trigger=CALM, **_select("team", team))
    _cue(show, CUES["wave"], at["wave"], last, "wave", hold=WAVE_HOLD, offset_mode="GIVEN",
         offset=0, timing="SWEEP", sweep_mode="ANGLE", sweep_centre=None,
         sweep_speed=_wave_speed(scene, frames), sweep_start=WAVE_START_ANGLE,
         sweep_laps=1, **_select("character", 0))
    start, end = _action(HIT).frame_range
    hit_frames = int(math.ceil(end - start - 1e-6)) + 1     # the whole clip, keys included
    for k in range(hits):
        _cue(show, f"{CUES['hit']} {k + 1}", at["hit"], last, f"hit{k}", action="UNIQUE",
             hold=hit_frames, interrupt=True, **_select("hit", k + 1))
    # the ball: the fans in view follow it from the start until a while after the
    # goal, each a few frames late
    show.look_targets.clear()
    target = show.look_targets.add()
    target.name, target.smoothing = BALL_TARGET, BALL_SMOOTHING
    target.object = _ball(scene, first, min(at["goal"], last))
    show.look_lag, show.look_max_lag = "SEEDED", BALL_LAG
    _cue(show, CUES["look"], first + 1, last, BALL_TARGET, action="LOOK",
         hold=at["goal"] + BALL_WATCH - (first + 1), **_select("in_view", 1))
    return tuple(c.name for c in show.cues if c.mute)


def add_stand_camera(scene, size=(960, 540)):
    """Add (or move) the "StandCamera": out over the pitch in front of the home stand
    where the wave passes first, off to one side and looking along it, so the stand
    recedes into the distance with its rows of fans and the bowl behind (``CAMERA_*``
    plus the stand's depth and height); it becomes the scene camera, and the render
    size ``size``."""
    from mathutils import Vector

    _, pos, teams = _seats()
    pos = pos.astype(np.float64)
    stand = _camera_stand(pos, teams)
    pick = pos[stand] if stand.any() else pos
    centre = pick.mean(0)
    reach = max(float(np.linalg.norm(centre[:2])), 1.0)        # stand to pitch centre
    inward = -centre[:2] / reach
    along = np.array([-inward[1], inward[0]])
    dist = pick[:, :2] @ -inward                                # out from the pitch
    front = pick[dist <= dist.min() + 0.5].mean(0)              # the front row's middle
    depth, height = float(np.ptp(dist)), float(np.ptp(pick[:, 2]))
    eye = front + np.r_[inward * (CAMERA_OUT + 0.5 * depth) + along * (CAMERA_SIDE + depth),
                        CAMERA_UP + 0.6 * height]
    target = front + np.r_[along * CAMERA_LOOK - inward * 0.3 * depth, 0.5 * height]
    obj = bpy.data.objects.get(CAMERA)
    if obj is None:
        obj = bpy.data.objects.new(CAMERA, bpy.data.cameras.new(CAMERA))
        scene.collection.objects.link(obj)
    cam = obj.data
    cam.type, cam.sensor_fit = "PERSP", "VERTICAL"
    cam.lens = cam.sensor_height / 2 / math.tan(CAMERA_FOV / 2)
    cam.clip_start, cam.clip_end = 0.5, 2 * float(np.linalg.norm(eye - target)) + \
        2 * float(np.ptp(pos, 0).max())
    obj.location = Vector(eye)
    obj.rotation_euler = Vector(target - eye).to_track_quat("-Z", "Y").to_euler()
    scene.camera = obj
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    return obj


def stadium_config(scene, frames=240, size=(960, 540), progress=None, hits=6, slots=800,
                   seed=5) -> Stadium:
    """Author the stadium's crowd, show and camera (see the module doc) in a built
    stadium scene and build its :class:`Stadium` for images of ``size`` pixels."""
    from .cameras import camera_from_object
    from .scene_config import config_from_scene
    from .scene_geometry import scene_geometry, scene_light

    setup_crowd(scene, hits=hits, slots=slots, seed=seed)
    muted = setup_show(scene, frames)
    cam = add_stand_camera(scene, size)
    bpy.context.view_layer.update()                 # the camera's matrix_world
    cfg = config_from_scene(scene, progress)
    n = len(_obj("Seats").data.vertices)
    if cfg.agent_count != n:
        raise CrowdError(f"stadium: {cfg.agent_count} agents from {n} seats")
    return Stadium(cfg, camera_from_object(cam, size[0] / size[1]), muted,
                   scene_geometry(scene), scene_light(scene))


def author_stadium(blend, frames=240, size=(960, 540), progress=None) -> Stadium:
    """Open the built ``blend``, author its crowd, show and camera and bake it with the
    extension registered (:func:`stadium_config`; ``progress(done, total, message)``)
    and save the file with its Crowd settings. Returns the :class:`Stadium`."""
    from .registration import register, unregister
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    register()
    try:
        stadium = stadium_config(bpy.context.scene, frames, size, progress=progress)
        bpy.context.preferences.filepaths.save_version = 0  # no stadium.blend1 backup
        bpy.ops.wm.save_mainfile(filepath=str(blend))       # with its crowd settings
    finally:
        unregister()
    return stadium
