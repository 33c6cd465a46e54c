"""Build the sample stadium scene as a .blend file with the ``bpy`` module.

    .venv/bin/python sample_scenes/build_stadium.py --out stadium.blend [--seats N] [--quiet]

The scene holds (see sample_scenes/README.md for the details):

- "Stands" (terraces and benches round a rounded-rectangle bowl), "Pitch";
- "Seats": a vertex per seat (agent point) with point attributes ``heading``
  (FLOAT, radians about +Z, facing the pitch centre for a character facing -Y),
  ``section`` (INT, 0 home / 1 away), ``seat_row``, ``seat_index`` (INT) and
  vertex groups "home" and "away";
- the fan character "FanRig" (23 bones) with its skinned "FanBody" and ten
  authored actions with event markers (``fan_actions.ACTIONS``);
- "MocapRig"/"MocapBody" with the action "mocap_01_01" from CMU motion capture;
- a camera framing the bowl, a sun, a sky-coloured world (Standard view transform), 30 fps, and scene custom properties
  ``crowd_seat_count``, ``crowd_builder_version`` and friends.

Everything is deterministic: the same arguments give the same scene. Import
:func:`build_stadium` by path (sample_scenes is not a package); it resets the
current bpy session to factory settings before building.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from pathlib import Path

_HERE = Path(__file__).resolve().parent
if str(_HERE) not in sys.path:
    sys.path.insert(0, str(_HERE))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402

import fan_actions  # noqa: E402
import fan_rig  # noqa: E402
import mocap  # noqa: E402
import stadium_layout as layout  # noqa: E402
from crowd_addon.blender.looks import plain_material  # noqa: E402
from crowd_addon.core.errors import CrowdError  # noqa: E402
from crowd_addon.gpu.renderer import BACKGROUND  # noqa: E402

__all__ = ["build_stadium", "BUILDER_VERSION", "DEFAULT_SEATS", "PAPER_SEATS"]

BUILDER_VERSION = "1.1.0"
DEFAULT_SEATS = 2000
PAPER_SEATS = 65000
FPS = 30

#: linear RGB of the GPU preview's background (``gpu.renderer.BACKGROUND``, sRGB display
#: values, all above the decoding's linear segment)
SKY = tuple(((c + 0.055) / 1.055) ** 2.4 for c in BACKGROUND[:3])
_COLOURS = {"concrete": (0.55, 0.55, 0.52, 1.0), "home": (0.30, 0.09, 0.09, 1.0),
            "away": (0.08, 0.13, 0.32, 1.0), "pitch": (0.12, 0.45, 0.12, 1.0),
            "apron": (0.09, 0.30, 0.10, 1.0)}



def _mesh_object(name, collection, verts, faces, materials=()):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(verts, np.float64).tolist(), [], np.asarray(faces).tolist())
    mesh.validate()
    for m in materials:
        mesh.materials.append(plain_material(m, _COLOURS[m]))
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


def _build_stands(bowl, rows, collection):
    """Terraces plus one bench per row (away-end benches in the away colour)."""
    ring, normal = layout.bowl_ring(bowl)
    verts, faces = layout.sweep(ring, normal, layout.stand_profile(bowl, rows))
    parts_v, parts_f, kinds = [verts], [faces], [np.zeros(len(faces), np.int32)]
    offset = len(verts)
    for r in range(rows):
        v, f = layout.sweep(ring, normal, layout.bench_profile(bowl, r), closed_profile=True)
        away = layout.in_away_end(bowl, v[f].mean(axis=1)[:, :2])
        parts_v.append(v)
        parts_f.append(f + offset)
        kinds.append(np.where(away, 2, 1).astype(np.int32))
        offset += len(v)
    obj = _mesh_object("Stands", collection, np.vstack(parts_v), np.vstack(parts_f),
                       ("concrete", "home", "away"))
    obj.data.polygons.foreach_set("material_index", np.concatenate(kinds))
    return obj


def _build_pitch(bowl, collection):
    ring, _ = layout.bowl_ring(bowl)
    _mesh_object("Apron", collection, np.column_stack([ring, np.zeros(len(ring))]),
                 [list(range(len(ring)))], ("apron",))
    px, py = bowl.pitch_half
    _mesh_object("Pitch", collection,
                 [(-px, -py, 0.05), (px, -py, 0.05), (px, py, 0.05), (-px, py, 0.05)],
                 [[0, 1, 2, 3]], ("pitch",))


def _build_seats(seats, collection):
    mesh = bpy.data.meshes.new("Seats")
    mesh.vertices.add(len(seats.position))
    mesh.vertices.foreach_set("co", seats.position.ravel())
    for name, kind, values in (("heading", "FLOAT", seats.heading),
                               ("section", "INT", seats.section),
                               ("seat_row", "INT", seats.row),
                               ("seat_index", "INT", seats.index)):
        mesh.attributes.new(name, kind, "POINT").data.foreach_set("value", values)
    mesh.update()
    obj = bpy.data.objects.new("Seats", mesh)
    collection.objects.link(obj)
    for name, section in (("home", layout.HOME), ("away", layout.AWAY)):
        obj.vertex_groups.new(name=name).add(
            np.nonzero(seats.section == section)[0].tolist(), 1.0, "REPLACE")
    return obj


def _camera_and_sun(scene, bowl, rows, collection):
    """The camera framing the bowl, the sun over the home stand, a world of the
    preview's sky colour and the Standard view transform."""
    a, b = bowl.half_straight
    reach = bowl.corner_radius + rows * bowl.tread + 0.4
    radius = math.hypot(a + reach, b + reach)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = 35.0
    cam.data.clip_start, cam.data.clip_end = 1.0, 20 * radius
    half_fov = math.atan(0.5 * cam.data.sensor_width / cam.data.lens)
    direction = Vector((0.55, -0.75, 0.45)).normalized()
    cam.location = direction * (1.05 * radius / math.sin(half_fov))
    cam.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(40), 0.0, math.radians(210))   # lights the home stand
    collection.objects.link(sun)
    world = bpy.data.worlds.new("Sky")     # the preview's sky, lighting F12 renders too
    world.color = SKY
    if world.node_tree is None:             # Blender before 5.0: nodes on request
        world.use_nodes = True
    for node in world.node_tree.nodes:
        if node.type == "BACKGROUND":
            node.inputs["Color"].default_value = SKY + (1.0,)
    scene.world = world
    # F12 shows the sky in the preview's colour, and colours without the AgX curve's
    # fading (the preview draws its lit colours as they are)
    scene.view_settings.view_transform = "Standard"
    return cam, sun


@contextlib.contextmanager
def _stdout_silenced(silent):
    """Mute file descriptor 1 (Blender's C code and the BVH importer print there)."""
    if not silent:
        yield
        return
    sys.stdout.flush()
    saved, devnull = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def _collection(scene, name):
    col = bpy.data.collections.new(name)
    scene.collection.children.link(col)
    return col


def _save(path: Path):
    """Write the session to ``path`` through a temporary file in the same directory."""
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.blend")
    try:
        result = bpy.ops.wm.save_as_mainfile(filepath=str(tmp), check_existing=False,
                                             compress=True, copy=True)
        if result != {"FINISHED"} or not tmp.is_file():
            raise CrowdError(f"output {path}: Blender could not write {tmp.name}")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _check_output(path):
    path = Path(path).resolve()
    if path.suffix != ".blend":
        raise CrowdError(f"output {path}: expected a .blend file name")
    if not path.parent.is_dir() or not os.access(path.parent, os.W_OK):
        raise CrowdError(f"output {path}: directory {path.parent} is missing or not writable")
    return path


def build_stadium(path, seats=DEFAULT_SEATS, bvh=mocap.BVH_PATH, log=print):
    """Build the stadium scene and save it to ``path`` (.blend); returns a summary dict.

    seats : number of agent points (>= 1). bvh : CMU BVH file for the mocap
    character. log : callable taking one progress string (None: silent).
    Summary keys: path, seats, rows, home, away, actions ({name: {frame_start,
    frame_end, loop, markers: [(name, frame)], rig}}), vertices ({object: count}),
    bytes, seconds.
    """
    say = log or (lambda message: None)
    if isinstance(seats, bool) or not isinstance(seats, (int, np.integer)) or seats < 1:
        raise CrowdError(f"seats: expected a whole number >= 1, got {seats!r}")
    path = _check_output(path)
    start = time.perf_counter()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    scene.frame_start, scene.frame_end = 1, 120
    scene.render.resolution_x, scene.render.resolution_y = 1280, 720

    bowl = layout.Bowl()
    say(f"laying out {seats} seats")
    seat_layout = layout.layout_seats(bowl, int(seats))
    stadium = _collection(scene, "Stadium")
    stand_rows = seat_layout.rows + 1       # a full stand: its seated rows and one behind
    say(f"building stands: {seat_layout.rows} seated rows of {stand_rows}")
    stands = _build_stands(bowl, stand_rows, stadium)
    _build_pitch(bowl, stadium)
    seat_obj = _build_seats(seat_layout, stadium)

    say("building the fan rig, body and actions")
    fan_col = _collection(scene, "Fan")
    rig, body = fan_rig.build_fan(fan_col)
    actions = fan_actions.author_actions(rig)
    rig.animation_data.action = actions[0]

    say(f"importing motion capture {bvh}")
    mocap_col = _collection(scene, "Mocap")
    with _stdout_silenced(log is None):
        mocap_rig, mocap_body, mocap_action = mocap.build_mocap(mocap_col, bvh)

    _camera_and_sun(scene, bowl, stand_rows, stadium)
    scene.frame_set(1)
    scene["crowd_builder_version"] = BUILDER_VERSION
    scene["crowd_seat_count"] = int(seats)
    scene["crowd_seat_rows"] = int(seat_layout.rows)
    scene["crowd_character_forward"] = "-Y"
    scene["crowd_fan_rig"] = rig.name
    scene["crowd_mocap_rig"] = mocap_rig.name

    say(f"saving {path}")
    with _stdout_silenced(log is None):
        _save(path)
    summary = {
        "path": str(path), "seats": int(seats), "rows": int(seat_layout.rows),
        "home": int((seat_layout.section == layout.HOME).sum()),
        "away": int((seat_layout.section == layout.AWAY).sum()),
        "actions": {a.name: {"rig": owner.name, "frame_start": int(a.frame_start),
                             "frame_end": int(a.frame_end), "loop": bool(a.use_cyclic),
                             "markers": sorted((m.name, m.frame) for m in a.pose_markers)}
                    for owner, group in ((rig, actions), (mocap_rig, [mocap_action]))
                    for a in group},
        "vertices": {o.name: len(o.data.vertices)
                     for o in (seat_obj, stands, body, mocap_body)},
        "bytes": path.stat().st_size, "seconds": time.perf_counter() - start,
    }
    return summary


def format_summary(summary):
    """Human-readable lines for a :func:`build_stadium` summary."""
    lines = [f"wrote {summary['path']} ({summary['bytes'] / 1e6:.2f} MB, "
             f"{summary['seconds']:.1f} s)",
             f"seats: {summary['seats']} in {summary['rows']} rows "
             f"(home {summary['home']}, away {summary['away']})",
             "vertices: " + ", ".join(f"{k} {v}" for k, v in summary["vertices"].items()),
             "actions:"]
    for name, info in summary["actions"].items():
        marks = ", ".join(f"{m}@{f}" for m, f in info["markers"]) or "-"
        lines.append(f"  {name:16s} {info['rig']:9s} frames {info['frame_start']}-"
                     f"{info['frame_end']}{' loop' if info['loop'] else ''}  markers: {marks}")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="output .blend path")
    parser.add_argument("--seats", type=int, default=DEFAULT_SEATS,
                        help=f"agent points (default {DEFAULT_SEATS}; the paper's "
                             f"stadium: {PAPER_SEATS})")
    parser.add_argument("--bvh", default=str(mocap.BVH_PATH), help="CMU BVH file")
    parser.add_argument("--quiet", action="store_true", help="print only the summary")
    args = parser.parse_args(argv)
    log = None if args.quiet else (lambda message: print(f"[stadium] {message}", flush=True))
    try:
        summary = build_stadium(args.out, seats=args.seats, bvh=Path(args.bvh), log=log)
    except (CrowdError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(format_summary(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
