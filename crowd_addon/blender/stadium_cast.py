"""The demo stadium's cast, authored the way an animator would in Blender.

:func:`setup_crowd` fills the scene's Crowd settings of a stadium built by
``sample_scenes/build_stadium.py`` with both of its characters: "Fan" (the fan rig
and body, one stream per authored action that seats play or react with, one unique
per agent that can be hit by the ball) and "Mocap" (the motion-capture rig and body
with one looping stream, the jumps), M = 60 and the paper's 800 transition slots,
and the "Seats" points as the agent source. The seats get point attributes written
here: ``character`` (0 fan, 1 mocap: 2 % of the home seats), ``stream`` (among the
character's streams: home seats ``idle_a`` / ``idle_c`` / ``clap``, away seats
``idle_b``), ``hit`` (``k`` on the seat of the k-th fan the ball hits, 0 elsewhere),
``in_view`` (1 on the seats of the stand the camera looks at) and ``team_colour``
(:func:`team_colours`: home red, away blue, each shirt a little lighter or darker, one
fan in five in clothes of their own); the source scales the fans 0.93 .. 1.07
(heights vary), and each fan draws a skin tone and trousers from
the fan's palettes (:data:`FAN_PALETTES`, docs/variety.md), a body (a third of the
fans wear the broader ``FanBodyBroad``, made from ``FanBody``) and props: a flag in
the right hand for about one fan in seven, a cap for three in ten (:data:`FAN_PROPS`,
objects parented to the fan rig's bones), both in the fan's team colour. The seat
streams are state machines that take the goal (:data:`REACTION_STATES`), and both
characters have look rigs (:data:`LOOK_RIGS`). The show, the ball and the camera are
:mod:`.stadium`'s.
"""

from __future__ import annotations

import math

import bpy
import numpy as np

from ..core.base.errors import CrowdError
from .looks import plain_material

__all__ = ["STREAMS", "HOME_MIX", "AWAY_MIX", "FAN", "MOCAP", "LOOK_RIGS", "setup_crowd"]

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
#: the characters' look rigs (docs/show.md, "Look-at"): character -> (look bones,
#: parent first; their shares; yaw and pitch limits, degrees)
LOOK_RIGS = {"Fan": ("neck, head", "0.4, 0.6", 75.0, 50.0),
             "Mocap": ("Neck, Neck1, Head", "0.25, 0.25, 0.5", 75.0, 50.0)}


def stadium_object(name):
    obj = bpy.data.objects.get(name)
    if obj is None:
        raise CrowdError(f"stadium scene: object {name!r} is missing (build it with "
                         "sample_scenes/build_stadium.py)")
    return obj


def stadium_action(name):
    act = bpy.data.actions.get(name)
    if act is None:
        raise CrowdError(f"stadium scene: action {name!r} is missing")
    return act


def _animation(pool, name, action):
    anim = pool.add()
    anim.name = name
    node = anim.nodes.add()
    node.name, node.kind, node.action = "clip", "CLIP", stadium_action(action)
    return anim


def _reacting(anim):
    """Make a one-clip stream a template that takes the goal: a state machine over its
    clip ("seated") and the :data:`REACTION_STATES`, entered on their triggers from any
    state and left on ``calm``."""
    for state, (action, _) in REACTION_STATES.items():
        node = anim.nodes.add()
        node.name, node.kind, node.action = state, "CLIP", stadium_action(action)
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
        c.name, c.armature, c.body = name, stadium_object(rig), stadium_object(body)
    fan, mocap = s.characters[FAN], s.characters[MOCAP]
    for name, action in STREAMS.items():
        anim = _animation(fan.streams, name, action)
        if name in SEAT_STREAMS:
            _reacting(anim)
    for k in range(hits):
        _animation(fan.uniques, f"hit{k}", HIT)
    stadium_action(MOCAP_ACTION).use_cyclic = True     # the jumps loop (its manual frame range)
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


def stadium_seats():
    """The seats object, its positions (n, 3) and teams (n,: HOME or AWAY)."""
    seats = stadium_object("Seats")
    me = seats.data
    n = len(me.vertices)
    pos = np.zeros(n * 3, np.float32)
    me.vertices.foreach_get("co", pos)
    teams = np.zeros(n, np.int32)
    me.attributes["team"].data.foreach_get("value", teams)
    return seats, pos.reshape(n, 3), teams


def camera_stand(pos, teams):
    """(n,) bool: the home seats of the near long side (about angle -pi/2 round the
    pitch centre), where the camera looks and the wave passes first."""
    angle = np.arctan2(pos[:, 1], pos[:, 0])
    near = np.abs(np.angle(np.exp(1j * (angle + np.pi / 2)))) < 0.35
    return near & (teams == HOME)


#: the teams' shirt colours (linear) and the share of fans in their own clothes instead,
#: drawn from OWN_CLOTHES. Saturated on purpose: a shirt mixed toward grey reads as skin
#: at a few pixels a fan, and 65,000 such fans as one pink slope.
TEAM_SHIRTS = {HOME: (0.70, 0.03, 0.03), AWAY: (0.03, 0.10, 0.62)}
OWN_SHARE = 0.2
OWN_CLOTHES = ((0.04, 0.04, 0.05), (0.75, 0.75, 0.72), (0.18, 0.18, 0.20), (0.05, 0.07, 0.16))


def team_colours(teams, seed):
    """(n, 4) float32 RGBA: each seat's colour (its shirt; flags and caps take it too)
    from its team (:data:`TEAM_SHIRTS`), 0.75 .. 1.15 times as bright per seat, and
    for :data:`OWN_SHARE` of the seats one of :data:`OWN_CLOTHES`."""
    rng = np.random.default_rng(seed)
    n = teams.size
    colour = np.ones((n, 4), np.float32)
    colour[:, :3] = np.where((teams == HOME)[:, None], TEAM_SHIRTS[HOME], TEAM_SHIRTS[AWAY])
    colour[:, :3] *= 0.75 + 0.4 * rng.random((n, 1))
    own = rng.random(n) < OWN_SHARE
    colour[own, :3] = np.asarray(OWN_CLOTHES)[rng.integers(0, len(OWN_CLOTHES), own.sum())]
    return colour


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
    pool = np.flatnonzero(fans & camera_stand(pos, teams))
    if pool.size < hits:
        pool = np.flatnonzero(fans)
    hit = np.zeros(n, np.int32)
    chosen = np.random.default_rng(seed + 2).choice(pool, size=min(hits, pool.size),
                                                    replace=False)
    hit[chosen] = np.arange(1, chosen.size + 1)
    colour = team_colours(teams, seed + 3)
    _seat_attribute(me, "character", character)
    _seat_attribute(me, "stream", stream)
    _seat_attribute(me, "hit", hit)
    stand = camera_stand(pos, teams)            # the fans in view follow the ball
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
    seats, pos, teams = stadium_seats()
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
