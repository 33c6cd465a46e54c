"""``crowd export --blend`` and ``crowd preview --blend`` take what the .blend holds: the
scene's frame range and its camera (``--camera NAME``), with only JSON on stdout.

Oracles: Blender's own ``world_to_camera_view`` for where a camera object sees a point
(against :func:`crowd_addon.blender.cameras.camera_from_object`), and for the rendered
frames the drawn pixels against the seats that camera projects; ``json.loads`` of the
whole stdout of a fresh process; the file system for what a failed run leaves.
"""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402
from bpy_extras.object_utils import world_to_camera_view  # noqa: E402
from mathutils import Vector  # noqa: E402

from crowd_addon.blender.cameras import camera_from_object, find_camera  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # tests/pngs.py
from pngs import read_png  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
NX, NY, FIRST, LAST = 8, 6, 3, 8
W, H = 96, 64


extension = cs.extension_fixture()


def _camera(scene, name, location, rotation, lens=35.0, scale=(1.0, 1.0, 1.0)):
    obj = bpy.data.objects.new(name, bpy.data.cameras.new(name))
    obj.location, obj.rotation_euler, obj.scale = location, rotation, scale
    obj.data.lens = lens
    scene.collection.objects.link(obj)
    return obj


def _look(obj, target):
    d = Vector(target) - obj.location
    obj.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()


def build_scene():
    """A crowd of 48 seats on a 8 x 6 m grid, frames 3..8; cameras "Front" (the scene
    camera, looking at the crowd from -Y), "Top" (from above, off to one side) and
    "Away" (looking away); a mesh "Cube"."""
    scene = cs.reset()
    scene.frame_start, scene.frame_end = FIRST, LAST
    rig = cs.make_armature("Rig")
    idle = cs.make_action(rig, "idle", seed=1)
    s = scene.crowd
    s.max_offset, s.transition_slots = 6, 8
    cs.add_stream(cs.add_character(s, rig, cs.make_proxy(rig)), "idle", idle)
    seats = cs.make_seats(NX, NY)
    src = s.agent_sources.add()
    src.name, src.object = "seats", seats
    front = _camera(scene, "Front", (3.5, -9.0, 5.0), (0, 0, 0))
    _look(front, (3.5, 2.5, 0.5))
    top = _camera(scene, "Top", (1.0, 2.0, 14.0), (0, 0, 0), lens=28.0)
    _look(top, (2.0, 2.5, 0.0))
    _camera(scene, "Away", (3.5, -9.0, 5.0), (math.radians(90), 0, math.radians(180)))
    cube = bpy.data.objects.new("Cube", bpy.data.meshes.new("Cube"))
    scene.collection.objects.link(cube)
    scene.camera = front
    bpy.context.view_layer.update()
    return scene


@pytest.fixture(scope="module")
def blend(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli_blend") / "crowd.blend"
    build_scene()
    bpy.context.preferences.filepaths.save_version = 0
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def crowd(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "crowd_addon", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


# ------------------------------------------------------------------ the camera

@pytest.mark.parametrize("fit", ["AUTO", "HORIZONTAL", "VERTICAL"])
@pytest.mark.parametrize("size", [(640, 360), (300, 500)])
def test_a_point_projects_where_blender_says(fit, size):
    scene = cs.reset()
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    # rolled, tilted, non-uniformly scaled: the scale must not change the view
    obj = _camera(scene, "Cam", (2.0, -7.0, 3.0), (1.2, 0.25, 0.4), lens=42.0,
                  scale=(1.5, 0.7, 2.0))
    obj.data.sensor_fit = fit
    obj.data.sensor_width, obj.data.sensor_height = 36.0, 20.0
    obj.data.clip_start, obj.data.clip_end = 0.3, 80.0
    bpy.context.view_layer.update()
    cam = camera_from_object(obj, size[0] / size[1])
    rng = np.random.default_rng(4)
    loc, rot, _ = obj.matrix_world.decompose()
    r = np.array(rot.to_matrix(), np.float64)
    # points in front of the camera, inside and outside its frame
    local = np.c_[rng.uniform(-4, 4, (40, 2)), -rng.uniform(1, 30, 40)]
    points = local @ r.T + np.array(loc)
    for p in points:
        want = world_to_camera_view(scene, obj, Vector(p))
        clip = cam.view_projection @ np.r_[p, 1.0]
        got = (clip[:2] / clip[3] + 1) / 2
        np.testing.assert_allclose(got, want[:2], atol=1e-5)
        assert -(cam.view @ np.r_[p, 1.0])[2] == pytest.approx(want[2], rel=1e-5)
    assert (cam.near, cam.far) == pytest.approx((0.3, 80.0))


def test_bad_cameras_are_named():
    scene = build_scene()
    assert find_camera(scene) == scene.camera
    assert find_camera(scene, "Top").name == "Top"
    with pytest.raises(CrowdError, match=r"camera 'Nope': scene 'Scene' has no object of "
                                         r"that name \(its cameras: \['Away', 'Front', "
                                         r"'Top'\]\)"):
        find_camera(scene, "Nope")
    with pytest.raises(CrowdError, match="camera 'Cube': the object is a mesh, not a camera"):
        find_camera(scene, "Cube")
    top = bpy.data.objects["Top"]
    top.data.type = "ORTHO"
    with pytest.raises(CrowdError, match="camera 'Top': an orthographic camera"):
        camera_from_object(top, 1.5)
    top.data.type, top.data.shift_x = "PERSP", 0.1
    with pytest.raises(CrowdError, match=r"camera 'Top': lens shift \(0.1, 0\)"):
        camera_from_object(top, 1.5)
    top.data.shift_x, top.data.clip_start, top.data.clip_end = 0.0, 5.0, 5.0
    with pytest.raises(CrowdError, match="camera 'Top': clip start 5 must be below clip "
                                         "end 5"):
        camera_from_object(top, 1.5)


# ------------------------------------------------------------------ the commands

def _drawn(png):
    image = read_png(png).astype(np.int16)
    background = image[0, 0]
    return np.abs(image - background).sum(-1) > 30


def _projected_box(camera, aspect_size):
    """Pixel box (x0, y0, x1, y1) of the seats' feet and heads through ``camera`` as
    Blender's world_to_camera_view gives them (rows from the top)."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = aspect_size
    obj = bpy.data.objects[camera]
    pts = []
    for x in range(NX):
        for y in range(NY):
            for z in (0.0, 1.7):
                v = world_to_camera_view(scene, obj, Vector((x, y, z)))
                pts.append((v.x * W, (1 - v.y) * H))
    pts = np.array(pts)
    return (*pts.min(0), *pts.max(0))


@pytest.mark.parametrize("camera", [None, "Top"])
def test_preview_renders_the_scene_frames_through_its_camera(blend, tmp_path, camera):
    """No --frames: the scene's range 3..8; no --camera: the scene camera ("Front")."""
    out = tmp_path / "new" / "frames"
    run = crowd("preview", "--blend", blend, "--out", out, "--width", W, "--height", H,
                "--json", *(["--camera", camera] if camera else []))
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout)                # stdout is the JSON object, only
    assert "Read blend" in run.stderr               # Blender's log went to stderr
    assert summary["frames"] == [FIRST, LAST] and summary["camera"] == (camera or "Front")
    assert sorted(p.name for p in out.iterdir()) == [f"frame_{f:04d}.png"
                                                    for f in range(FIRST, LAST + 1)]
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    x0, y0, x1, y1 = _projected_box(camera or "Front", (W, H))
    drawn = _drawn(out / f"frame_{FIRST:04d}.png")
    rows, cols = np.nonzero(drawn)
    assert drawn.mean() > 0.005
    # every drawn pixel is where Blender's camera sees the seats (an agent's reach
    # beyond its seat and head: a few pixels; the body's arms span 1.32 m, and every
    # level of this 60-triangle body is the body itself, its reach included)
    pad = 0.1 * W
    assert cols.min() >= x0 - pad and cols.max() <= x1 + pad
    assert rows.min() >= y0 - pad and rows.max() <= y1 + pad
    # and they cover most of that box's width: the whole crowd is in view
    assert cols.max() - cols.min() > 0.7 * (min(x1, W) - max(x0, 0))


def test_preview_takes_the_scenes_render_resolution(blend, tmp_path):
    """No --width/--height: the scene's resolution at its percentage; one given wins."""
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    render = bpy.context.scene.render
    render.resolution_x, render.resolution_y, render.resolution_percentage = 320, 180, 50
    small = tmp_path / "small.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(small), copy=True)
    for extra, size in (([], [160, 90]), (["--width", 200], [200, 90])):
        out = tmp_path / f"res{len(extra)}"
        run = crowd("preview", "--blend", small, "--out", out, "--frames", 1, "--json", *extra)
        assert run.returncode == 0, run.stderr[-3000:]
        assert json.loads(run.stdout)["size"] == size
        assert read_png(out / f"frame_{FIRST:04d}.png").shape[:2] == (size[1], size[0])


def test_shadows_only_darken_and_no_shadows_leaves_them_out(blend, tmp_path):
    """The crowd on a floor: the fans' shadows darken it, and --no-shadows leaves it
    as the sun lights it."""
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    bpy.ops.mesh.primitive_plane_add(size=40.0, location=(3.5, 2.5, -0.01))
    s = bpy.context.scene.crowd
    s.lod_near, s.lod_far, s.lod_card, s.lod_joined = 500.0, 600.0, 700.0, 800.0      # near: they cast
    floored = tmp_path / "floor.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(floored), copy=True)
    images = {}
    for extra in ([], ["--no-shadows"]):
        out = tmp_path / ("plain" if extra else "shadowed")
        run = crowd("preview", "--blend", floored, "--out", out, "--frames", 1, "--width", W,
                    "--height", H, "--samples", 0, *extra)
        assert run.returncode == 0, run.stderr[-3000:]
        images[bool(extra)] = read_png(out / f"frame_{FIRST:04d}.png").astype(np.int16)
    darker = images[True].sum(-1) - images[False].sum(-1)
    assert (darker > 30).sum() > 20 and (darker >= -3).all()


def test_a_camera_looking_away_sees_no_agent(blend, tmp_path):
    out = tmp_path / "away"
    run = crowd("preview", "--blend", blend, "--out", out, "--frames", 1, "--width", W,
                "--height", H, "--camera", "Away")
    assert run.returncode == 0, run.stderr[-3000:]
    assert "camera 'Away'" in run.stdout
    assert not _drawn(out / f"frame_{FIRST:04d}.png").any()


@pytest.mark.parametrize("args, message", [
    (["--camera", "Nope"], "camera 'Nope': scene 'Scene' has no object of that name"),
    (["--camera", "Cube"], "camera 'Cube': the object is a mesh, not a camera"),
    (["--start", "9"], "--start 9 is after scene 'Scene''s last frame 8; give --frames"),
    (["--scene", "Other"], "no scene 'Other'"),
])
def test_bad_preview_input_is_named_and_nothing_is_written(blend, tmp_path, args, message):
    out = tmp_path / "missing" / "frames"
    run = crowd("preview", "--blend", blend, "--out", out, "--json", *args)
    assert run.returncode == 2
    last = run.stderr.splitlines()[-1]
    assert last.startswith("crowd preview: error: ") and message in last
    assert run.stdout == "" and not (tmp_path / "missing").exists()


@pytest.mark.parametrize("args, message", [
    (["--camera", "Front"], "--camera needs --blend"),
    (["--scene", "Scene"], "--scene needs --blend"),
    ([], "--frames N is required with --config"),
])
def test_config_previews_need_frames_and_have_no_camera(tmp_path, capsys, args, message):
    from crowd_addon.cli import main
    out = tmp_path / "frames"
    assert main(["preview", "--config", str(tmp_path / "crowd.json"), "--out", str(out),
                 *args]) == 2
    assert f"crowd preview: error: {message}" in capsys.readouterr().err
    assert not out.exists()


def test_export_takes_the_scene_range_and_makes_its_folder(blend, tmp_path):
    out = tmp_path / "a" / "b" / "shot.usdc"
    run = crowd("export", "--blend", blend, "--out", out, "--json", "--substeps", "2")
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout)                # stdout is the JSON object, only
    assert "Read blend" in run.stderr
    assert summary["frames"] == [FIRST, LAST] and summary["agents"] == NX * NY
    assert summary["substeps"] == 2                 # samples between frames, from --blend
    assert out.is_file() and summary["characters"] == 1


@pytest.mark.parametrize("args, message", [
    (["--agents", "1000"], "1000 agents requested but the crowd has 48"),
    (["--frames", "1-4"], "starts before scene 'Scene''s start frame 3"),
])
def test_a_failed_export_leaves_no_folder_behind(blend, tmp_path, args, message):
    out = tmp_path / "a" / "b" / "shot.usdc"
    run = crowd("export", "--blend", blend, "--out", out, "--json", *args)
    assert run.returncode == 2 and message in run.stderr.splitlines()[-1]
    assert run.stdout == "" and os.listdir(tmp_path) == []


def test_export_from_a_config_needs_frames(tmp_path, capsys):
    from crowd_addon.cli import main
    assert main(["export", "--config", str(tmp_path / "crowd.json"), "--out",
                 str(tmp_path / "x.usdc")]) == 2
    assert "crowd export: error: --frames FIRST-LAST is required with --config" in \
        capsys.readouterr().err


def test_plan_and_export_measure_through_the_scene_camera(blend, tmp_path):
    """``crowd plan --blend`` bakes the scene as the exports do and sees it through its
    scene camera at its render size: its default equals the repetition of the export
    at the scene's first frame (no show: the crowd does not change), both measured in
    fresh processes; ``--json`` ends with the plan's line."""
    run = crowd("plan", "--blend", blend, "--budget-mb", "5", "--no-plot", "--json")
    assert run.returncode == 0, run.stderr[-3000:]
    plan = json.loads(run.stdout.strip().splitlines()[-1])
    assert plan["repetition_planned"] <= plan["repetition_default"]
    assert plan["templates"] == ["idle"] and plan["agents"] == NX * NY
    out = tmp_path / "shot.usdc"
    run = crowd("export", "--blend", blend, "--out", out, "--json", "--repetition-frames",
                "1")
    assert run.returncode == 0, run.stderr[-3000:]
    rep = json.loads(run.stdout)["repetition"]
    assert rep["frames"] == [FIRST] and rep["visible"][0] == plan["visible"]
    assert rep["value"] == pytest.approx(plan["repetition_default"], abs=1e-9)
