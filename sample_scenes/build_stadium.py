"""Build the sample stadium scene as a .blend file with the ``bpy`` module.

    .venv/bin/python sample_scenes/build_stadium.py --out stadium.blend [--seats N] [--quiet]

The scene holds (see sample_scenes/README.md for the details):

- "Stands" (a two-tier bowl of terraces and benches, made by the extension's seat
  generator: ``stadium_layout.SPEC``), "Pitch", "Apron";
- "Seats": a vertex per seat (agent point) with point attributes ``heading``
  (FLOAT, radians about +Z, facing the pitch centre for a character facing -Y),
  ``section``, ``tier``, ``row``, ``seat`` and ``team`` (INT, 0 home / 1 away) and
  vertex groups "home" and "away";
- the fan character "FanRig" (23 bones) with its skinned "FanBody" and ten
  authored actions with event markers (``fan_actions.ACTIONS``);
- "MocapRig"/"MocapBody" with the action "mocap_01_01" from CMU motion capture;
- the broadcast camera high on the north stand looking across the pitch at the far
  stand, an aerial camera that sees the whole bowl ("AerialCamera"), a sun, a sky-coloured world (Standard view transform), 30 fps, and scene custom properties
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
from crowd_addon.blender.seats_operator import seat_objects  # noqa: E402
from crowd_addon.core.authoring.seat_spec import HOME, AWAY  # noqa: E402
from crowd_addon.core.authoring.seats import plan_ring  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.gpu.renderer import BACKGROUND  # noqa: E402

__all__ = ["build_stadium", "BUILDER_VERSION", "DEFAULT_SEATS", "PAPER_SEATS"]

BUILDER_VERSION = "1.2.0"
DEFAULT_SEATS = 2000
PAPER_SEATS = 65000
FPS = 30

#: linear RGB of the GPU preview's background (``gpu.renderer.BACKGROUND``, sRGB display
#: values, all above the decoding's linear segment)
SKY = tuple(((c + 0.055) / 1.055) ** 2.4 for c in BACKGROUND[:3])
_COLOURS = {"pitch": (0.12, 0.45, 0.12, 1.0), "apron": (0.09, 0.30, 0.10, 1.0)}
#: the broadcast camera: its field of view keeps this much room round the far stand
FRAME_MARGIN = 1.08



def _mesh_object(name, collection, verts, faces, materials=()):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(verts, np.float64).tolist(), [], np.asarray(faces).tolist())
    mesh.validate()
    for m in materials:
        mesh.materials.append(plain_material(m, _COLOURS[m]))
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


def _build_pitch(spec, collection):
    ring, _ = plan_ring(spec)
    _mesh_object("Apron", collection, np.column_stack([ring, np.zeros(len(ring))]),
                 [list(range(len(ring)))], ("apron",))
    px, py = 0.5 * spec.pitch[0], 0.5 * spec.pitch[1]
    _mesh_object("Pitch", collection,
                 [(-px, -py, 0.05), (px, -py, 0.05), (px, py, 0.05), (-px, py, 0.05)],
                 [[0, 1, 2, 3]], ("pitch",))


def far_stand(seats, spec):
    """(N,) bool: the seats of the far (south) stand, the straight along the south
    touchline, which the broadcast camera frames."""
    straight = 0.5 * spec.pitch[0] + spec.margin[0] - spec.corner_radius
    return (seats.position[:, 1] < 0) & (np.abs(seats.position[:, 0]) <= straight)


def _framing_camera(name, collection, eye, points, forward, aspect, clip_end):
    """A camera ``name`` at ``eye`` aimed (from ``forward``) at the middle of
    ``points`` as seen from there, with the horizontal field of view that frames them
    all in ``aspect`` (:data:`FRAME_MARGIN` of room)."""
    for _ in range(3):                  # aim at the middle of the points' extent in view
        f = forward / np.linalg.norm(forward)
        right = np.cross(f, (0.0, 0.0, 1.0))
        right /= np.linalg.norm(right)
        up = np.cross(right, f)
        rel = points - eye
        depth = rel @ f
        x, y = (rel @ right) / depth, (rel @ up) / depth
        forward = f + 0.5 * (x.max() + x.min()) * right + 0.5 * (y.max() + y.min()) * up
    tan_half = FRAME_MARGIN * max(0.5 * np.ptp(x), 0.5 * np.ptp(y) * aspect)
    cam = bpy.data.objects.new(name, bpy.data.cameras.new(name))
    cam.data.sensor_fit = "HORIZONTAL"
    cam.data.lens = 0.5 * cam.data.sensor_width / tan_half
    cam.data.clip_start, cam.data.clip_end = 1.0, clip_end
    cam.location = Vector(eye)
    cam.rotation_euler = Vector(forward).to_track_quat("-Z", "Y").to_euler()
    collection.objects.link(cam)
    return cam


def _broadcast_camera(scene, seats, collection):
    """The "Camera": the main broadcast camera on the halfway line of the north stand,
    hung under the top tier's front (or 12 m up if that is lower), looking across the
    pitch at the far stand, which it frames whole in the render's aspect."""
    spec = seats.spec
    edge = 0.5 * spec.pitch[1] + spec.margin[1]       # the north stand's front edge
    eye = np.array([0.0, edge + seats.fronts[-1] - 1.0, max(seats.heights[-1] - 1.0, 12.0)])
    far = seats.position[far_stand(seats, spec)].astype(np.float64)
    aspect = scene.render.resolution_x / scene.render.resolution_y
    cam = _framing_camera("Camera", collection, eye, far, far.mean(0) - eye, aspect,
                          20.0 * float(np.abs(far).max()))
    scene.camera = cam
    return cam


def _aerial_camera(seats, collection, aspect):
    """"AerialCamera": high over the south-west corner, looking down at the middle of
    the bowl, which it frames whole (every seat in view) in ``aspect``: the full stadium
    at a glance (``crowd preview --camera AerialCamera``)."""
    pos = seats.position.astype(np.float64)
    reach = float(np.abs(pos[:, :2]).max())
    eye = np.array([-0.9 * reach, -1.25 * reach, 0.75 * reach])
    return _framing_camera("AerialCamera", collection, eye, pos, -eye, aspect, 10.0 * reach)


def _camera_and_sun(scene, seats, collection):
    """The broadcast camera (the scene camera), the aerial camera, the sun over the home
    stand, a world of the preview's sky colour and the Standard view transform."""
    cam = _broadcast_camera(scene, seats, collection)
    _aerial_camera(seats, collection, scene.render.resolution_x / scene.render.resolution_y)
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
    Summary keys: path, seats, rows (all tiers), tiers (rows per tier), sections,
    home, away, actions ({name: {frame_start,
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

    say(f"laying out {seats} seats")
    seat_layout = layout.layout_seats(int(seats))
    stadium = _collection(scene, "Stadium")
    say(f"building the seats and stands: {' + '.join(map(str, seat_layout.rows))} rows")
    seat_obj, stands = seat_objects(seat_layout, scene, stadium)
    _build_pitch(seat_layout.spec, stadium)

    say("building the fan rig, body and actions")
    fan_col = _collection(scene, "Fan")
    rig, body = fan_rig.build_fan(fan_col)
    actions = fan_actions.author_actions(rig)
    rig.animation_data.action = actions[0]

    say(f"importing motion capture {bvh}")
    mocap_col = _collection(scene, "Mocap")
    with _stdout_silenced(log is None):
        mocap_rig, mocap_body, mocap_action = mocap.build_mocap(mocap_col, bvh)

    _camera_and_sun(scene, seat_layout, stadium)
    scene.frame_set(1)
    scene["crowd_builder_version"] = BUILDER_VERSION
    scene["crowd_seat_count"] = int(seats)
    scene["crowd_seat_rows"] = int(sum(seat_layout.rows))
    scene["crowd_seat_sections"] = int(seat_layout.sections)
    scene["crowd_character_forward"] = "-Y"
    scene["crowd_fan_rig"] = rig.name
    scene["crowd_mocap_rig"] = mocap_rig.name

    say(f"saving {path}")
    with _stdout_silenced(log is None):
        _save(path)
    summary = {
        "path": str(path), "seats": int(seats), "rows": int(sum(seat_layout.rows)),
        "tiers": [int(r) for r in seat_layout.rows], "sections": int(seat_layout.sections),
        "home": int((seat_layout.team == HOME).sum()),
        "away": int((seat_layout.team == AWAY).sum()),
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
             f"seats: {summary['seats']} in {summary['rows']} rows (tiers "
             f"{' + '.join(map(str, summary['tiers']))}), {summary['sections']} sections "
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
