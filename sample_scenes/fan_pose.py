"""Key poses of the fan, described by intent and solved to bone rotations.

A :class:`Pose` says where the hips are, how the spine, neck and head turn,
where each wrist and ankle should be (two-bone IK with a pole direction) and
how each hand and foot is oriented. :class:`PoseSolver` turns it into what an
action keys: a rotation quaternion ``(w, x, y, z)`` per bone (bone-local, as in
``pose_bone.rotation_quaternion``) and the hips' bone-local location. Only the
authoring uses IK: the actions hold plain keyed rotations, so the armature has
no constraints.

Conventions: armature space, metres, the character facing -Y with its left at
+X. ``turn`` angles are XYZ Euler degrees about the armature axes, applied to the
bone in its rest orientation and carried by its parent's motion; +X pitches
forward, +Z turns to the character's left. Left-side values mirror to the
right with :func:`mirror` (x negated; rotations about Y and Z reversed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from mathutils import Euler, Matrix, Quaternion, Vector

__all__ = ["Arm", "Pose", "PoseSolver", "mirror", "both", "quaternion_track"]


@dataclass(frozen=True)
class Arm:
    """Where a wrist goes and how the hand is held (left-side values).

    wrist : target point. frame : "chest" (a point of the standing rest pose,
    carried along by the chest's motion) or "root" (armature space).
    pole : direction the elbow points to. hand : finger direction.
    palm : palm normal (made perpendicular to ``hand``). Vectors use ``frame``.
    """

    wrist: tuple
    frame: str = "chest"
    pole: tuple = (0.3, 1.0, -0.3)
    hand: tuple = (0.1, 0.0, -1.0)
    palm: tuple = (-1.0, 0.0, 0.0)


@dataclass(frozen=True)
class Pose:
    """A full-body key pose.

    hips : hips joint position (armature space). turn : {bone: (x, y, z) degrees}.
    arms : {"L"/"R": Arm}. ankles : {"L"/"R": (point, foot pitch degrees)}, by
    default planted where they stand at rest with the foot flat (+pitch lifts
    the toes, -pitch the heel).
    """

    hips: tuple = (0.0, 0.0, 0.94)
    turn: dict = field(default_factory=dict)
    arms: dict = field(default_factory=dict)
    ankles: dict = field(default_factory=dict)

    def with_turn(self, **turns):
        """A copy with extra turns; names use ``_`` for ``.`` (``spine_001``, ``shoulder_L``)."""
        merged = dict(self.turn)
        merged.update({k.replace("_", "."): v for k, v in turns.items()})
        return replace(self, turn=merged)


def mirror(value):
    """Mirror a left-side Arm, point/vector, or rotation triple to the right side."""
    if isinstance(value, Arm):
        return replace(value, wrist=mirror(value.wrist), pole=mirror(value.pole),
                       hand=mirror(value.hand), palm=mirror(value.palm))
    x, y, z = value
    return (-x, y, z)


def both(arm: Arm, right: Arm | None = None):
    """Arms dict: ``arm`` on the left and its mirror (or ``right``) on the right."""
    return {"L": arm, "R": mirror(arm) if right is None else right}


def _mirror_turn(rot):
    x, y, z = rot
    return (x, -y, -z)


def _two_bone(root, target, l1, l2, pole):
    """Middle joint and reachable end of a two-bone chain (mathutils Vectors)."""
    d = target - root
    dist = min(max(d.length, abs(l1 - l2) + 1e-4), l1 + l2 - 1e-4)
    u = d.normalized()
    v = pole - u * pole.dot(u)
    if v.length < 1e-6:
        v = u.orthogonal()
    v.normalize()
    cos_a = max(-1.0, min(1.0, (l1 * l1 + dist * dist - l2 * l2) / (2 * l1 * dist)))
    a = math.acos(cos_a)
    return root + l1 * (math.cos(a) * u + math.sin(a) * v), root + dist * u


def _frame(direction, normal):
    """Rotation whose columns are (direction, normal made perpendicular, their cross)."""
    d = Vector(direction).normalized()
    n = Vector(normal) - d * Vector(normal).dot(d)
    n.normalize()
    return Matrix((d, n, d.cross(n))).transposed()


class PoseSolver:
    """Solves :class:`Pose` for one armature (rest data read once from its bones)."""

    def __init__(self, armature_data):
        bones = armature_data.bones
        self.order = [b.name for b in bones]
        self.parent = {b.name: b.parent.name if b.parent else None for b in bones}
        self.rest = {b.name: b.matrix_local.copy() for b in bones}
        self.rest_inv = {k: m.inverted() for k, m in self.rest.items()}
        self.length = {b.name: b.length for b in bones}
        hand = {s: (bones[f"hand.{s}"].tail_local - bones[f"hand.{s}"].head_local) for s in "LR"}
        # in the A pose the palms face the body and down: perpendicular to the hand, in XZ
        sign = {"L": 1.0, "R": -1.0}
        self.hand_rest = {s: _frame(hand[s], sign[s] * Vector((hand[s].z, 0.0, -hand[s].x)))
                          for s in "LR"}
        self.ankle_rest = {s: bones[f"foot.{s}"].head_local.copy() for s in "LR"}

    def solve(self, pose: Pose):
        """Returns ({bone: (w, x, y, z)}, hips location (x, y, z)) for the pose."""
        posed, rotation, goals = {}, {}, {}
        hips_loc = Vector((0.0, 0.0, 0.0))
        turns = dict(pose.turn)
        for name, rot in pose.turn.items():
            if name.endswith(".L") and name[:-2] + ".R" not in pose.turn:
                turns[name[:-2] + ".R"] = _mirror_turn(rot)
        for name in self.order:
            parent = self.parent[name]
            base = (posed[parent] @ self.rest_inv[parent] @ self.rest[name]) if parent \
                else self.rest[name].copy()
            frame = base.to_3x3()
            side = name[-1]
            kind = name[:-2] if name[-2:] in (".L", ".R") else name
            if name == "hips":
                hips_loc = frame.transposed() @ (Vector(pose.hips) - base.translation)
                base = base @ Matrix.Translation(hips_loc)
            if kind in ("upper_arm", "thigh"):  # swing towards the IK middle joint
                target, pole = self._goal(pose, kind, side, posed)
                lower = "forearm" if kind == "upper_arm" else "shin"
                middle, end = _two_bone(base.translation, target, self.length[name],
                                        self.length[f"{lower}.{side}"], pole)
                goals[f"{lower}.{side}"] = end
                swing = frame.col[1].rotation_difference(middle - base.translation)
                local = frame.transposed() @ swing.to_matrix() @ frame
            elif kind in ("forearm", "shin"):  # swing towards the IK end
                swing = frame.col[1].rotation_difference(goals[name] - base.translation)
                local = frame.transposed() @ swing.to_matrix() @ frame
            elif kind == "hand":  # absolute orientation: finger direction and palm
                local = frame.transposed() @ self._hand(pose, side, posed) @ \
                    self.rest[name].to_3x3()
            elif kind == "foot":  # absolute orientation: the rest foot, pitched
                pitch = self._ankle(pose, side)[1]
                local = frame.transposed() @ \
                    Euler((math.radians(-pitch), 0.0, 0.0)).to_matrix() @ self.rest[name].to_3x3()
            else:  # a turn about armature axes, carried by the parent
                turn = Euler([math.radians(a) for a in turns.get(name, (0, 0, 0))]).to_matrix()
                rest3 = self.rest[name].to_3x3()
                local = rest3.transposed() @ turn @ rest3
            local = local.to_quaternion()
            local.normalize()
            rotation[name] = tuple(local)
            posed[name] = base @ local.to_matrix().to_4x4()
        return rotation, tuple(hips_loc)

    def _ankle(self, pose, side):
        point, pitch = pose.ankles.get(side, (None, 0.0))
        return (self.ankle_rest[side] if point is None else Vector(point)), pitch

    def _goal(self, pose, kind, side, posed):
        """IK target and pole (armature space) of an arm or leg."""
        if kind == "thigh":
            sx = 1.0 if side == "L" else -1.0
            return self._ankle(pose, side)[0], Vector((0.15 * sx, -1.0, 0.0))
        arm = pose.arms[side]
        carry = self._carry(arm, posed)
        return carry(Vector(arm.wrist), True), carry(Vector(arm.pole), False)

    def _carry(self, arm, posed):
        """Maps points / vectors of the arm's frame to armature space."""
        if arm.frame == "root":
            return lambda v, is_point: v
        if arm.frame != "chest":
            raise ValueError(f"arm frame {arm.frame!r}: expected 'chest' or 'root'")
        move = posed["chest"] @ self.rest_inv["chest"]
        return lambda v, is_point: move @ v if is_point else move.to_3x3() @ v

    def _hand(self, pose, side, posed):
        """Armature-space rotation taking the rest hand frame to the pose's hand frame."""
        arm = pose.arms[side]
        carry = self._carry(arm, posed)
        target = _frame(carry(Vector(arm.hand), False), carry(Vector(arm.palm), False))
        return target @ self.hand_rest[side].transposed()


def quaternion_track(keys):
    """Make a sequence of (w, x, y, z) tuples sign-continuous (no hemisphere flips)."""
    out = [Quaternion(keys[0])]
    for q in keys[1:]:
        q = Quaternion(q)
        out.append(-q if q.dot(out[-1]) < 0 else q)
    return [tuple(q) for q in out]
