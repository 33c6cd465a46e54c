"""The demo stadium's show, ball and camera, authored the way an animator would in
Blender.

Everything the demo runs is scene data, so the saved ``stadium.blend`` holds it all
and ``crowd export --blend`` / ``crowd preview --blend`` in another process make the
same crowd:

- :func:`~.stadium_cast.setup_crowd` (:mod:`.stadium_cast`) fills the scene's Crowd
  settings: the fans and the mocap jumpers, the seats' attributes and the agent
  source.
- :func:`setup_show` authors the show (``scene.crowd.show``, docs/show.md) and sets the
  scene's frame range to the run: the **goal**, a mass reaction (the seat streams are
  state machines that take it, :data:`.stadium_cast.REACTION_STATES`: the goal cues set
  ``celebrate`` on the home fans' streams and ``despair`` on the away fans', and
  ``calm`` when the cheer's hold ends, so every fan follows its stream at its own
  offset; only fans on other streams blend to ``cheer`` / ``groan`` through slots),
  the **Mexican wave** (a sweep round the pitch centre, the world origin, over the
  fans: it starts just before the home stand the camera looks at and takes the whole
  run for one lap, or longer where the transition slots could not carry a faster
  front round a full bowl; each fan stands ``WAVE_HOLD`` frames), the **hits** (one
  cue per hit fan, selected by its ``hit`` attribute, to its own unique animation;
  they interrupt the cheer) and
  nothing for the claps: they are the ``clap`` action's event tags, counted by the
  crowd (``crowd.events``). The **ball** ("Ball", a white sphere made here) is played
  over the pitch from the centre spot and goes into the net of the home end's goal
  (the end away from the away seats) at the goal beat; it is the show's look target
  ``ball``, and a Look At cue on the first frame stepped turns the heads of the fans
  in view (the camera's stand: the seats' ``in_view`` attribute) toward it until
  :data:`BALL_WATCH` frames after the goal (:data:`.stadium_cast.LOOK_RIGS`: neck and head, the
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
from .stadium_cast import (AWAY, CALM, CELEBRATE, DESPAIR, HIT, HOME, camera_stand, setup_crowd,
                           stadium_action, stadium_object, stadium_seats)

__all__ = ["BEATS", "CUES", "CAMERA", "BALL", "BALL_TARGET", "setup_show", "add_stand_camera",
           "stadium_config", "Stadium", "author_stadium"]

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
    me = stadium_object("Seats").data
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
    _, pos, teams = stadium_seats()
    half = _pitch_half()[0]
    away = pos[teams == AWAY]
    return half if away.size and away[:, 0].mean() < 0 else -half


def _pitch_half() -> tuple:
    """Half the pitch's length (x) and width (y), from the "Pitch" object's bounds."""
    from mathutils import Vector
    p = stadium_object("Pitch")
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
    seats = stadium_object("Seats").data
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
    start, end = stadium_action(HIT).frame_range
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

    _, pos, teams = stadium_seats()
    pos = pos.astype(np.float64)
    stand = camera_stand(pos, teams)
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
    n = len(stadium_object("Seats").data.vertices)
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
    register(restore=False)                 # it bakes the crowd itself below
    try:
        stadium = stadium_config(bpy.context.scene, frames, size, progress=progress)
        bpy.context.preferences.filepaths.save_version = 0  # no stadium.blend1 backup
        bpy.ops.wm.save_mainfile(filepath=str(blend))       # with its crowd settings
    finally:
        unregister()
    return stadium
