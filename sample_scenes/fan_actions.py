"""The fan's authored actions: key poses, timing and event markers.

Every action keys every bone's ``rotation_quaternion`` (and the hips'
``location``) at every key, so switching actions leaves no bone behind; keys are
Bezier (auto clamped). Actions start at frame 1 (30 fps). Looping actions end on
their first pose (same key values) and are flagged ``use_cyclic``; the repeat
period is ``frame_end - frame_start`` frames (whole seconds). Pose markers are event tags.
Seated actions start and end in :data:`SEAT`, standing ones in :data:`STAND`,
so transitions between them blend between similar poses.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import bpy

from crowd_addon.blender.compat import fcurve_ensure
from fan_pose import Arm, Pose, PoseSolver, both, quaternion_track

__all__ = ["ActionSpec", "ACTIONS", "SEAT", "STAND", "author_actions"]


@dataclass(frozen=True)
class ActionSpec:
    """name; keys: ((frame, Pose), ...) from frame 1; markers: ((name, frame), ...)."""

    name: str
    keys: tuple
    markers: tuple
    loop: bool


def _hands_on_thighs(y=0.10, z=0.63):
    return both(Arm(wrist=(0.15, y, z), frame="root", pole=(0.4, 1.0, 0.0),
                    hand=(0.0, -1.0, -0.2), palm=(0.0, 0.0, -1.0)))


STAND = Pose(hips=(0.0, 0.0, 0.94),
             arms=both(Arm(wrist=(0.21, 0.0, 0.89), pole=(0.2, 1.0, 0.0),
                           hand=(0.05, 0.0, -1.0))))
SEAT = Pose(hips=(0.0, 0.40, 0.53), turn={"spine": (4, 0, 0)}, arms=_hands_on_thighs())

_LEAN = Pose(hips=SEAT.hips,
             turn={"spine": (14, 0, 0), "spine.001": (10, 0, 0), "chest": (6, 0, 0),
                   "neck": (-10, 0, 0), "head": (-12, 0, 0)},
             arms=both(Arm(wrist=(0.06, -0.08, 0.66), frame="root", pole=(0.6, 0.6, -0.5),
                           hand=(-0.5, -1.0, 0.0), palm=(0.0, 0.0, -1.0))))
_BACK = Pose(hips=(0.0, 0.42, 0.52),
             turn={"spine": (-6, 0, 0), "spine.001": (-3, 0, 0), "head": (6, 0, 0)},
             arms={"L": Arm(wrist=(-0.10, -0.20, 1.20), pole=(0.5, 0.3, -1.0),
                            hand=(-1.0, 0.0, 0.1), palm=(0.0, 1.0, 0.0)),
                   "R": Arm(wrist=(0.10, -0.13, 1.15), pole=(-0.5, 0.3, -1.0),
                            hand=(1.0, 0.0, 0.1), palm=(0.0, 1.0, 0.0))})
_TAP = replace(_BACK, ankles={"L": (None, 20.0)})

_CLAP = SEAT.with_turn(spine=(6, 0, 0))
_CLAP_OPEN = replace(_CLAP, arms=both(Arm(wrist=(0.17, -0.26, 1.18), pole=(1.0, 0.4, -0.6),
                                          hand=(-0.3, -0.6, 0.75))))
_CLAP_SHUT = replace(_CLAP, arms=both(Arm(wrist=(0.02, -0.33, 1.20), pole=(1.0, 0.4, -0.6),
                                          hand=(0.0, -0.6, 0.8))))

_ARMS_UP = Pose(hips=(0.0, 0.0, 0.94),
                turn={"spine": (-4, 0, 0), "chest": (-4, 0, 0), "head": (-14, 0, 0),
                      "shoulder.L": (0, -12, 0)},
                arms=both(Arm(wrist=(0.36, -0.06, 1.95), pole=(1.0, 0.2, 0.0),
                              hand=(0.3, 0.0, 1.0))))
_PUMP = Pose(hips=(0.0, 0.02, 0.88), turn={"spine": (3, 0, 0), "head": (-6, 0, 0)},
             arms=both(Arm(wrist=(0.33, -0.12, 1.66), pole=(1.0, 0.3, -0.3),
                           hand=(0.1, 0.0, 1.0))))

_PUSH = Pose(hips=(0.0, 0.34, 0.55),
             turn={"hips": (12, 0, 0), "spine": (12, 0, 0), "spine.001": (6, 0, 0),
                   "head": (-14, 0, 0)},
             arms=_hands_on_thighs(-0.02, 0.62))
_RISE = Pose(hips=(0.0, 0.12, 0.78),
             turn={"hips": (14, 0, 0), "spine": (10, 0, 0), "head": (-12, 0, 0)},
             arms=both(Arm(wrist=(0.20, -0.05, 0.82), frame="root", pole=(0.3, 1.0, 0.0),
                           hand=(0.0, -0.4, -1.0))))
_LOWER = replace(_RISE, hips=(0.0, 0.14, 0.78),
                 arms=both(Arm(wrist=(0.22, -0.22, 1.00), pole=(0.3, 1.0, -0.3),
                               hand=(0.0, -1.0, -0.3))))
_NEAR = Pose(hips=(0.0, 0.36, 0.58),
             turn={"hips": (8, 0, 0), "spine": (8, 0, 0), "head": (-8, 0, 0)},
             arms=_hands_on_thighs(0.06, 0.64))

_ON_HEAD = Arm(wrist=(0.13, 0.02, 1.63), pole=(1.0, -0.2, 0.2), hand=(-0.4, 0.2, 1.0))
_DESPAIR = Pose(hips=SEAT.hips,
                turn={"spine": (-6, 0, 0), "spine.001": (-4, 0, 0), "head": (-18, 0, 0)},
                arms=both(_ON_HEAD))

_UP_RISING = Pose(hips=(0.0, 0.20, 0.74), turn={"hips": (10, 0, 0), "spine": (6, 0, 0)},
                  arms=both(Arm(wrist=(0.28, -0.32, 1.62), pole=(1.0, 0.3, -0.5),
                                hand=(0.2, -0.5, 1.0))))
_WAVE_TOP = Pose(hips=(0.0, 0.03, 0.93), turn={"head": (-8, 0, 0), "shoulder.L": (0, -10, 0)},
                 arms=both(Arm(wrist=(0.24, -0.08, 1.97), pole=(1.0, 0.0, 0.0),
                               hand=(0.0, 0.0, 1.0))))
_WAVE_SWAY = replace(_WAVE_TOP.with_turn(spine=(0, -6, 0)),
                     arms=both(Arm(wrist=(0.42, -0.08, 1.90), pole=(1.0, 0.0, 0.0),
                                   hand=(0.5, 0.0, 1.0)),
                               Arm(wrist=(-0.09, -0.08, 1.95), pole=(-1.0, 0.0, 0.0),
                                   hand=(0.3, 0.0, 1.0), palm=(1.0, 0.0, 0.0))))
_SINKING = replace(_UP_RISING, hips=(0.0, 0.28, 0.66))

_FLINCH = Pose(hips=(0.0, 0.43, 0.53),
               turn={"spine": (-8, 0, 0), "chest": (-6, 0, -6), "neck": (-10, 0, 0),
                     "head": (-25, 0, 18)},
               arms=both(Arm(wrist=(0.16, -0.24, 1.45), pole=(1.0, 0.4, -1.0),
                             hand=(0.0, -0.3, 1.0), palm=(0.0, -1.0, 0.0))))
_RUB = replace(SEAT.with_turn(head=(10, 0, -10)),
               arms={"L": Arm(wrist=(0.10, -0.06, 1.66), pole=(1.0, -0.2, 0.2),
                              hand=(-0.3, 0.0, 1.0)), "R": SEAT.arms["R"]})

ACTIONS = (
    ActionSpec("idle_seated_a", ((1, SEAT),
                                 (23, SEAT.with_turn(chest=(-2, 0, 0), neck=(0, 0, 8),
                                                     head=(0, 0, 15))),
                                 (45, SEAT.with_turn(chest=(1.5, 0, 0), head=(-4, 0, 0))),
                                 (68, SEAT.with_turn(chest=(-1, 0, 0), neck=(0, 0, -6),
                                                     head=(3, 0, -14))),
                                 (91, SEAT)), (("look", 23), ("look", 68)), True),
    ActionSpec("idle_seated_b", ((1, _LEAN), (30, _LEAN.with_turn(head=(-4, 0, 0))),
                                 (60, _LEAN.with_turn(hips=(0, 0, 4), head=(-14, 0, 10))),
                                 (90, _LEAN.with_turn(head=(-8, 0, -8))), (121, _LEAN)),
               (("nod", 30),), True),
    ActionSpec("idle_seated_c", ((1, _BACK), (10, _TAP), (20, _BACK),
                                 (30, _TAP.with_turn(head=(6, 0, 8))), (40, _BACK),
                                 (61, _BACK)), (("tap", 10), ("tap", 30)), True),
    ActionSpec("clap", ((1, _CLAP_OPEN), (8, _CLAP_SHUT), (16, _CLAP_OPEN), (23, _CLAP_SHUT),
                        (31, _CLAP_OPEN)), (("clap", 8), ("clap", 23)), True),
    ActionSpec("cheer", ((1, _ARMS_UP), (16, _PUMP), (31, _ARMS_UP), (46, _PUMP),
                         (61, _ARMS_UP)), (("cheer", 31),), True),
    ActionSpec("stand_up", ((1, SEAT), (10, _PUSH), (22, _RISE), (34, STAND), (45, STAND)),
               (("stand", 34),), False),
    ActionSpec("sit_down", ((1, STAND), (12, _LOWER), (26, _NEAR), (32, SEAT), (45, SEAT)),
               (("sit", 32),), False),
    ActionSpec("disappointment", ((1, SEAT), (12, _DESPAIR),
                                  (30, _DESPAIR.with_turn(spine=(-10, 0, 0), head=(-22, 0, 5))),
                                  (50, _DESPAIR.with_turn(spine=(14, 0, 0), spine_001=(8, 0, 0),
                                                          head=(18, 0, 0))),
                                  (75, SEAT)), (("groan", 12),), False),
    ActionSpec("wave_arms", ((1, SEAT), (10, _UP_RISING), (20, _WAVE_TOP), (28, _WAVE_SWAY),
                             (38, _SINKING), (48, SEAT), (61, SEAT)), (("wave", 20),), True),
    ActionSpec("hit_by_ball", ((1, SEAT), (4, _FLINCH), (12, _RUB),
                               (24, _RUB.with_turn(head=(12, 0, -4))), (40, SEAT)),
               (("hit", 4),), False),
)


def _write_curves(action, rig, path, index_values, frames, group):
    """Key ``path[i]`` at ``frames`` with ``index_values[i]`` (one list per array index)."""
    for index, values in enumerate(index_values):
        fc = fcurve_ensure(action, rig, path, index, group)
        points = fc.keyframe_points
        points.add(len(frames))
        points.foreach_set("co", [c for f, v in zip(frames, values) for c in (f, v)])
        fc.update()


def author_actions(rig, specs=ACTIONS, fps=30):
    """Create one action per spec on ``rig`` (fake user, frame range, markers); returns them."""
    solver = PoseSolver(rig.data)
    rig.animation_data_create()
    actions = []
    for spec in specs:
        frames = [float(f) for f, _ in spec.keys]
        solved = [solver.solve(pose) for _, pose in spec.keys]
        action = bpy.data.actions.new(spec.name)
        rig.animation_data.action = action
        for bone in solver.order:
            track = quaternion_track([rot[bone] for rot, _ in solved])
            if spec.loop and track[0] != track[-1]:
                raise RuntimeError(f"action {spec.name!r}: bone {bone!r} does not loop")
            _write_curves(action, rig, f'pose.bones["{bone}"].rotation_quaternion',
                          list(zip(*track)), frames, bone)
        _write_curves(action, rig, 'pose.bones["hips"].location',
                      list(zip(*[loc for _, loc in solved])), frames, "hips")
        for name, frame in spec.markers:
            action.pose_markers.new(name).frame = frame
        action.use_fake_user = True
        action.use_frame_range = True
        action.frame_start, action.frame_end = frames[0], frames[-1]
        action.use_cyclic = spec.loop
        actions.append(action)
    return actions
