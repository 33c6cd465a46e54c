"""The fan character: a 23-bone humanoid armature ("FanRig") and its skinned body ("FanBody").

The character stands on the origin facing -Y (Blender's front), left side at +X,
1.78 m tall, in an A pose (arms 45 degrees down). The body is low poly: one tube
of octagonal rings for the torso and head, one per arm (shoulder to finger tips),
per leg (hip to ankle) and per foot. Each ring is weighted to the bones along
its tube, blending linearly between neighbours near a joint (spine, neck,
shoulders, elbows, wrists, knees, ankles), so joints bend smoothly.
"""

from __future__ import annotations

from typing import NamedTuple

import bpy
import numpy as np

from crowd_addon.blender.looks import plain_material

__all__ = ["BONES", "build_fan"]

_C = 0.5 ** 0.5
_ARM = np.array([_C, 0.0, -_C])  # left arm direction in the A pose


def _arm_bones(side, sx):
    shoulder = np.array([0.03 * sx, 0.0, 1.40])
    upper = np.array([0.18 * sx, 0.02, 1.40])
    direction = _ARM * [sx, 1, 1]
    elbow = upper + 0.28 * direction
    wrist = elbow + 0.25 * direction
    return [(f"shoulder.{side}", "chest", shoulder, upper - [0.01 * sx, 0, 0]),
            (f"upper_arm.{side}", f"shoulder.{side}", upper, elbow),
            (f"forearm.{side}", f"upper_arm.{side}", elbow, wrist),
            (f"hand.{side}", f"forearm.{side}", wrist, wrist + 0.16 * direction)]


def _leg_bones(side, sx):
    x = 0.1 * sx
    return [(f"thigh.{side}", "hips", (x, 0.0, 0.92), (x, 0.0, 0.50)),
            (f"shin.{side}", f"thigh.{side}", (x, 0.0, 0.50), (x, 0.0, 0.08)),
            (f"foot.{side}", f"shin.{side}", (x, 0.0, 0.08), (x, -0.12, 0.03)),
            (f"toe.{side}", f"foot.{side}", (x, -0.12, 0.03), (x, -0.20, 0.03))]


#: (name, parent, head, tail) in armature space (metres); parents precede children.
BONES = [
    ("root", None, (0.0, 0.0, 0.0), (0.0, -0.25, 0.0)),
    ("hips", "root", (0.0, 0.0, 0.95), (0.0, 0.0, 1.05)),
    ("spine", "hips", (0.0, 0.0, 1.05), (0.0, 0.0, 1.18)),
    ("spine.001", "spine", (0.0, 0.0, 1.18), (0.0, 0.0, 1.30)),
    ("chest", "spine.001", (0.0, 0.0, 1.30), (0.0, 0.0, 1.44)),
    ("neck", "chest", (0.0, 0.0, 1.44), (0.0, -0.01, 1.54)),
    ("head", "neck", (0.0, -0.01, 1.54), (0.0, -0.01, 1.76)),
    *_arm_bones("L", 1), *_arm_bones("R", -1),
    *_leg_bones("L", 1), *_leg_bones("R", -1),
]

#: vertex colours (linear RGBA) by body region
_COLOURS = {"skin": (0.80, 0.55, 0.42, 1.0), "shirt": (0.85, 0.85, 0.85, 1.0),
            "trousers": (0.12, 0.14, 0.25, 1.0), "shoes": (0.05, 0.05, 0.05, 1.0)}


def _chain(points):
    """Cumulative arc length of a polyline of (J, 3) points, starting at 0."""
    points = np.asarray(points, np.float64)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def _weights(t, bones, bounds, blend):
    """Per station (K,) the weights of ``bones`` (B names) split at ``bounds`` (B-1).

    Near each bound the weight moves linearly from one bone to the next over
    ``blend`` (B-1,) metres either side. Returns (K, B) float64 rows summing to 1.
    """
    t = np.asarray(t, np.float64)[:, None]
    ramp = np.clip((t - np.asarray(bounds) + blend) / (2 * np.asarray(blend)), 0.0, 1.0)
    upper = np.concatenate([np.ones((len(t), 1)), ramp], axis=1)
    lower = np.concatenate([ramp, np.zeros((len(t), 1))], axis=1)
    return upper - lower


def _tube(points, t, radii, ref, sides=8):
    """Rings along a polyline: stations at arc lengths ``t`` (K,), radii (K, 2).

    ``ref`` picks each ring's first axis (its component across the polyline);
    the second is ``direction x first``. Returns (vertices (K*sides+2, 3),
    faces list, station per vertex (K*sides+2,)): quads between rings and a
    triangle fan capping each end, all facing outwards.
    """
    points = np.asarray(points, np.float64)
    arc = _chain(points)
    centre = np.column_stack([np.interp(t, arc, points[:, i]) for i in range(3)])
    seg = np.clip(np.searchsorted(arc, t, side="right") - 1, 0, len(points) - 2)
    direction = points[seg + 1] - points[seg]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    u = np.asarray(ref, np.float64) - (direction @ np.asarray(ref, np.float64))[:, None] * direction
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(direction, u)
    phi = 2 * np.pi * np.arange(sides) / sides
    ring = (centre[:, None] + radii[:, None, 0:1] * np.cos(phi)[None, :, None] * u[:, None]
            + radii[:, None, 1:2] * np.sin(phi)[None, :, None] * v[:, None])
    k = len(t)
    verts = np.vstack([ring.reshape(-1, 3), centre[0], centre[-1]])
    j = np.arange(sides)
    i = np.arange(k - 1)[:, None]
    quads = np.stack([i * sides + j, i * sides + (j + 1) % sides,
                      (i + 1) * sides + (j + 1) % sides, (i + 1) * sides + j], -1)
    first, last = k * sides, k * sides + 1
    caps = [(first, (x + 1) % sides, x) for x in j] + \
           [(last, (k - 1) * sides + x, (k - 1) * sides + (x + 1) % sides) for x in j]
    station = np.concatenate([np.repeat(np.arange(k), sides), [0, k - 1]])
    return verts, quads.reshape(-1, 4).tolist() + caps, station


class _Tube(NamedTuple):
    """One body part: a tube along ``points`` (J, 3) with rings at arc lengths ``t`` (K,).

    radii (K, 2) along ``ref`` and across it; ``bones`` (B names) split at arc
    lengths ``bounds`` (B-1,), blended over ``blend`` (B-1,) metres either side;
    ``region`` (K,) names each ring's colour.
    """

    points: list
    t: np.ndarray
    radii: np.ndarray
    ref: tuple
    bones: list
    bounds: np.ndarray
    blend: list
    region: np.ndarray


def _body_parts(heads, tails):
    """The body's tubes (torso and head, then per side arm, leg, foot), from bone positions."""
    parts = []
    torso = [(0, 0, 0.78), heads["hips"], heads["spine"], heads["spine.001"], heads["chest"],
             heads["neck"], heads["head"], tails["head"] + [0, 0, 0.02]]
    tz = _chain(torso)
    bounds = tz[2:7]
    zt = [0.78, 0.86, 0.95, 1.03, 1.10, 1.18, 1.26, 1.34, 1.40, 1.45, 1.50, 1.55, 1.60,
          1.66, 1.72, 1.78]  # ring heights; the torso runs straight up
    rt = [(0.11, 0.08), (0.165, 0.105), (0.175, 0.11), (0.165, 0.10), (0.155, 0.095),
          (0.16, 0.10), (0.175, 0.11), (0.19, 0.115), (0.18, 0.105), (0.07, 0.065),
          (0.05, 0.05), (0.08, 0.09), (0.095, 0.11), (0.095, 0.108), (0.085, 0.095),
          (0.04, 0.045)]
    zt = np.asarray(zt) - 0.78
    parts.append(_Tube(torso, zt, np.asarray(rt), (1, 0, 0),
                  ["hips", "spine", "spine.001", "chest", "neck", "head"], bounds,
                  [0.04, 0.04, 0.04, 0.03, 0.02],
                  np.where(zt < 0.2, "trousers", np.where(zt < 0.66, "shirt", "skin"))))
    for side in "LR":
        arm = [heads[f"shoulder.{side}"], heads[f"upper_arm.{side}"], heads[f"forearm.{side}"],
               heads[f"hand.{side}"], tails[f"hand.{side}"]]
        arc = _chain(arm)
        start = arc[1]  # t is measured from the shoulder joint
        ta = np.array([-0.06, -0.02, 0.04, 0.12, 0.20, 0.26, 0.30, 0.36, 0.44, 0.51, 0.55,
                       0.62, 0.69])
        ra = [(0.055, 0.05), (0.06, 0.055), (0.055, 0.05), (0.05, 0.045), (0.045, 0.042),
              (0.042, 0.04), (0.04, 0.038), (0.042, 0.038), (0.036, 0.03), (0.03, 0.022),
              (0.042, 0.018), (0.045, 0.016), (0.035, 0.012)]
        parts.append(_Tube(arm, ta + start, np.asarray(ra), (0, 1, 0),
                      [f"shoulder.{side}", f"upper_arm.{side}", f"forearm.{side}",
                       f"hand.{side}"], arc[1:4], [0.04, 0.05, 0.025],
                      np.where(ta < 0.2, "shirt", "skin")))
        leg = [heads[f"thigh.{side}"], heads[f"shin.{side}"], heads[f"foot.{side}"]]
        tl = np.array([0.0, 0.08, 0.2, 0.32, 0.40, 0.46, 0.56, 0.68, 0.80, 0.86])
        rl = [(0.085, 0.09), (0.085, 0.085), (0.075, 0.075), (0.065, 0.062), (0.055, 0.055),
              (0.055, 0.052), (0.055, 0.055), (0.045, 0.045), (0.038, 0.038), (0.035, 0.035)]
        parts.append(_Tube(leg, tl, np.asarray(rl), (1, 0, 0), [f"thigh.{side}", f"shin.{side}",
                      f"foot.{side}"], _chain(leg)[1:3], [0.05, 0.03],
                      np.full(len(tl), "trousers")))
        x = heads[f"foot.{side}"][0]
        foot = [(x, 0.06, 0.05), (x, -0.12, 0.04), (x, -0.21, 0.03)]
        tf = np.array([0.0, 0.06, 0.14, 0.20, 0.27])
        rf = [(0.04, 0.045), (0.05, 0.05), (0.05, 0.04), (0.045, 0.03), (0.035, 0.02)]
        parts.append(_Tube(foot, tf, np.asarray(rf), (1, 0, 0), [f"foot.{side}", f"toe.{side}"],
                      _chain(foot)[1:2], [0.03], np.full(len(tf), "shoes")))
    return parts


def _create_armature(collection, name):
    arm = bpy.data.armatures.new(name)
    rig = bpy.data.objects.new(name, arm)
    collection.objects.link(rig)
    view_layer = bpy.context.view_layer
    view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    for bone_name, parent, head, tail in BONES:
        eb = arm.edit_bones.new(bone_name)
        eb.head, eb.tail, eb.roll = head, tail, 0.0
        if parent is not None:
            eb.parent = arm.edit_bones[parent]
            eb.use_connect = np.allclose(eb.parent.tail, head)
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in rig.pose.bones:
        pb.rotation_mode = "QUATERNION"
    return rig


def build_fan(collection, rig_name="FanRig", body_name="FanBody"):
    """Create the armature and its skinned body in ``collection``; returns (rig, body)."""
    rig = _create_armature(collection, rig_name)
    heads = {b.name: np.array(b.head_local) for b in rig.data.bones}
    tails = {b.name: np.array(b.tail_local) for b in rig.data.bones}
    verts, faces, colours, groups, regions = [], [], [], {}, []
    names = list(_COLOURS)
    for part in _body_parts(heads, tails):
        v, f, station = _tube(part.points, part.t, part.radii, part.ref)
        base = sum(len(x) for x in verts)
        verts.append(v)
        faces += [[base + i for i in face] for face in f]
        colours.append(np.array([_COLOURS[r] for r in part.region])[station])
        regions.append(np.array([names.index(r) for r in part.region])[station])
        w = _weights(part.t, part.bones, part.bounds, part.blend)[station]
        for b, bone in enumerate(part.bones):
            hit = np.nonzero(w[:, b] > 1e-6)[0]
            groups.setdefault(bone, []).append((hit + base, w[hit, b]))
    mesh = bpy.data.meshes.new(body_name)
    mesh.from_pydata(np.vstack(verts).tolist(), [], faces)
    mesh.validate()
    colour = mesh.color_attributes.new("color", "FLOAT_COLOR", "POINT")
    colour.data.foreach_set("color", np.vstack(colours).astype(np.float32).ravel())
    # one material a body region (what renders, exports and the preview colour by),
    # each face the region of its first corner
    for name in names:
        mesh.materials.append(plain_material(f"fan_{name}", _COLOURS[name]))
    region = np.concatenate(regions)
    mesh.polygons.foreach_set("material_index",
                              region[[face[0] for face in faces]].astype(np.int32))
    body = bpy.data.objects.new(body_name, mesh)
    collection.objects.link(body)
    for bone in rig.data.bones:
        group = body.vertex_groups.new(name=bone.name)
        for index, weight in groups.get(bone.name, []):
            for w in np.unique(np.round(weight, 6)):
                group.add(index[np.isclose(weight, w, atol=1e-6)].tolist(), float(w), "REPLACE")
    body.parent = rig
    modifier = body.modifiers.new("Armature", "ARMATURE")
    modifier.object = rig
    modifier.use_vertex_groups = True
    return rig, body
