"""Second character type from real motion capture: CMU subject 01, trial 01 (BVH).

Debian's ``assimp-testmodels`` ships the cgspeed BVH conversion of the CMU
database (``/usr/share/assimp/models/BVH/01_01.bvh``: "playground, forward jumps,
turn around", 120 fps). Blender's bundled importer turns it into an armature on
its own 31-bone skeleton ("MocapRig"); this module then keeps two forward jumps,
resamples them to the scene's 30 fps (every 4th BVH frame, no interpolation),
makes them jump on the spot (the feet's mean ground position stays at the
origin, so the character stays on its seat point) and tags each jump apex with a
``jump`` pose marker. "MocapBody" is a box per bone, rigidly weighted.

Units: CMU lengths are in units of 1/0.45 inch (the ASF ``length 0.45``), so the
importer's ``global_scale`` is 0.0254 / 0.45 m; the subject's hips stand ~1.0 m
high. Data: mocap.cs.cmu.edu, created with funding from NSF EIA-0196217.
"""

from __future__ import annotations

from pathlib import Path

import addon_utils
import bpy
import numpy as np
from mathutils import Vector

from crowd_addon.blender.compat import action_slots, fcurve_ensure, first_fcurves

__all__ = ["BVH_PATH", "build_mocap"]

BVH_PATH = Path("/usr/share/assimp/models/BVH/01_01.bvh")
CMU_SCALE = 0.0254 / 0.45
#: BVH frames (120 fps, 1-based as imported) kept: standing, two jumps, standing
WINDOW = (141, 541)
STEP = 4
JUMP_RISE = 0.12  # metres above standing hips height that make an apex a jump
_LINEAR = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["LINEAR"].value


def _import(path: Path, collection):
    if not path.is_file():
        raise FileNotFoundError(f"motion capture {path}: not found (Debian package "
                                f"assimp-testmodels)")
    addon_utils.enable("io_anim_bvh", default_set=False)
    layer_collection = bpy.context.view_layer.layer_collection.children[collection.name]
    bpy.context.view_layer.active_layer_collection = layer_collection
    result = bpy.ops.import_anim.bvh(filepath=str(path), global_scale=CMU_SCALE,
                                     rotate_mode="QUATERNION", frame_start=1,
                                     use_fps_scale=False)
    if result != {"FINISHED"}:
        raise RuntimeError(f"motion capture {path}: BVH import failed ({result})")
    return bpy.context.view_layer.objects.active


def _channels(action):
    """{(data_path, index): (frames, values)} of an action's F-curves, as arrays."""
    out = {}
    for fc in first_fcurves(action):
        co = np.empty(2 * len(fc.keyframe_points), np.float64)
        fc.keyframe_points.foreach_get("co", co)
        out[(fc.data_path, fc.array_index)] = co.reshape(-1, 2)
    return out


def _resampled_action(rig, name, imported):
    """New action on ``rig`` with the window of ``imported``, every STEP-th key from frame 1.

    Quaternion tracks are made sign-continuous (the importer converts each frame
    separately, so consecutive keys may sit in opposite hemispheres).
    """
    channels = _channels(imported)
    source_frames = next(iter(channels.values()))[:, 0]  # all channels share them
    picks = np.nonzero((source_frames >= WINDOW[0]) & (source_frames <= WINDOW[1]))[0][::STEP]
    action = bpy.data.actions.new(name)
    rig.animation_data.action = action
    tracks = {}
    for (path, index), co in channels.items():
        tracks.setdefault(path, {})[index] = co[picks, 1]
    frames = np.arange(1, len(picks) + 1, dtype=np.float64)
    for path, comps in tracks.items():
        values = np.column_stack([comps[i] for i in sorted(comps)])
        if path.endswith("rotation_quaternion"):
            flips = np.einsum("ij,ij->i", values[1:], values[:-1]) < 0
            values *= np.concatenate([[1.0], np.where(np.cumsum(flips) % 2, -1.0, 1.0)])[:, None]
        group = path.split('"')[1]
        for i in range(values.shape[1]):
            fc = fcurve_ensure(action, rig, path, i, group)
            fc.keyframe_points.add(len(frames))
            fc.keyframe_points.foreach_set("co", np.column_stack([frames, values[:, i]]).ravel())
            fc.keyframe_points.foreach_set("interpolation", [_LINEAR] * len(frames))
            fc.update()
    return action, frames


def _sample(rig, frames, bones):
    """Armature-space heads (F, len(bones), 3) of ``bones`` at ``frames`` (Blender's evaluation)."""
    scene = bpy.context.scene
    out = np.empty((len(frames), len(bones), 3))
    for i, f in enumerate(frames):
        scene.frame_set(int(f))
        out[i] = [rig.pose.bones[b].head for b in bones]
    return out


def _in_place(rig, action, frames, root):
    """Shift the root's location keys so the feet's mean stays over the origin."""
    feet = ["LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase"]
    drift = _sample(rig, frames, feet).mean(axis=1)
    drift[:, 2] = 0.0
    to_local = rig.data.bones[root].matrix_local.to_3x3().inverted()
    shift = np.array([to_local @ Vector(d) for d in drift])
    for fc in first_fcurves(action):
        if fc.data_path == f'pose.bones["{root}"].location':
            co = np.empty(2 * len(frames))
            fc.keyframe_points.foreach_get("co", co)
            co[1::2] -= shift[:, fc.array_index]
            fc.keyframe_points.foreach_set("co", co)
            fc.update()


def _jump_markers(rig, action, frames, root):
    """A ``jump`` marker at each apex of the hips higher than standing by JUMP_RISE."""
    height = _sample(rig, frames, [root])[:, 0, 2]
    standing = np.median(height)
    apex = (height[1:-1] > height[:-2]) & (height[1:-1] >= height[2:]) & \
        (height[1:-1] > standing + JUMP_RISE)
    for i in np.nonzero(apex)[0] + 1:
        action.pose_markers.new("jump").frame = int(frames[i])


def _box_body(rig, name, collection, min_length=0.03):
    """A box per bone (longer than ``min_length``), each vertex weighted 1 to its bone."""
    verts, faces, groups = [], [], {}
    cube = np.array([[x, y, z] for x in (-1, 1) for y in (0, 1) for z in (-1, 1)], np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    for bone in rig.data.bones:
        if bone.length < min_length:
            continue
        half = 0.1 if bone.name == "Head" else float(np.clip(0.22 * bone.length, 0.02, 0.07))
        local = cube * [half, max(bone.length, 2 * half), half]
        world = bone.matrix_local
        if bone.name == "Head":
            local[:, 1] -= 0.02
        base = len(verts)
        verts += [tuple(world @ Vector(p)) for p in local]
        faces += [tuple(base + i for i in q) for q in quads]
        groups[bone.name] = list(range(base, base + 8))
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.validate()
    body = bpy.data.objects.new(name, mesh)
    collection.objects.link(body)
    for bone_name, indices in groups.items():
        body.vertex_groups.new(name=bone_name).add(indices, 1.0, "REPLACE")
    body.parent = rig
    modifier = body.modifiers.new("Armature", "ARMATURE")
    modifier.object = rig
    return body


def build_mocap(collection, path: Path = BVH_PATH, rig_name="MocapRig",
                body_name="MocapBody", action_name="mocap_01_01", location=(2.0, 0.0, 0.0)):
    """Import the BVH into ``collection``; returns (rig, body, action)."""
    rig = _import(Path(path), collection)
    imported = rig.animation_data.action
    rig.name = rig.data.name = rig_name
    root = rig.data.bones[0].name
    action, frames = _resampled_action(rig, action_name, imported)
    bpy.data.actions.remove(imported)
    if action_slots(action):
        action.slots[0].name_display = rig_name
    _in_place(rig, action, frames, root)
    _jump_markers(rig, action, frames, root)
    action.use_fake_user = True
    action.use_frame_range = True
    action.frame_start, action.frame_end = frames[0], frames[-1]
    body = _box_body(rig, body_name, collection)
    rig.location = location
    return rig, body, action
