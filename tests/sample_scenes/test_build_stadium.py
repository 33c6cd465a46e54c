"""The sample stadium .blend, checked with Blender's own evaluation (bpy module).

One small stadium is built per module through ``build_stadium`` and reopened
from disk, so every test reads the saved file. The command line is exercised in
a subprocess.
"""

import functools
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
from bpy_extras.object_utils import world_to_camera_view  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "sample_scenes" / "build_stadium.py"
BVH = Path("/usr/share/assimp/models/BVH/01_01.bvh")
SEATS = 300
FAN_ACTIONS = {"idle_seated_a": set(), "idle_seated_b": set(), "idle_seated_c": set(),
               "clap": {"clap"}, "cheer": {"cheer"}, "stand_up": {"stand"},
               "sit_down": {"sit"}, "disappointment": set(), "wave_arms": {"wave"},
               "hit_by_ball": {"hit"}}
LOOPS = {"idle_seated_a", "idle_seated_b", "idle_seated_c", "clap", "cheer", "wave_arms"}

pytestmark = pytest.mark.skipif(not BVH.is_file(), reason="needs Debian's assimp-testmodels")


@functools.lru_cache(maxsize=None)
def _load_builder():
    spec = importlib.util.spec_from_file_location("build_stadium", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    path = tmp_path_factory.mktemp("stadium") / "stadium.blend"
    summary = _load_builder().build_stadium(path, seats=SEATS, log=None)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return summary


def _play(rig_name, action_name):
    rig = bpy.data.objects[rig_name]
    action = bpy.data.actions[action_name]
    rig.animation_data.action = action
    from crowd_addon.blender.compat import SLOTTED_ACTIONS, assigned_slot
    assert not SLOTTED_ACTIONS or assigned_slot(rig.animation_data) is not None, \
        f"{action_name}: no slot assigned"
    return rig, action


def _pose(rig, frame):
    """(B, 4, 4) pose matrices (armature space) Blender evaluates at ``frame``."""
    bpy.context.scene.frame_set(frame)
    return np.array([np.array(pb.matrix) for pb in rig.pose.bones])


def _evaluated_points(obj):
    dg = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(dg).data
    co = np.empty(3 * len(mesh.vertices))
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def test_scene_settings_and_summary(built):
    scene = bpy.context.scene
    assert scene.render.fps == 30 and scene.render.fps_base == 1.0
    assert scene["crowd_seat_count"] == SEATS
    assert scene["crowd_builder_version"] == _load_builder().BUILDER_VERSION
    assert built["seats"] == SEATS and built["home"] + built["away"] == SEATS
    assert set(built["actions"]) == set(FAN_ACTIONS) | {"mocap_01_01"}
    assert bpy.data.objects["Sun"].data.type == "SUN"
    assert Path(built["path"]).stat().st_size == built["bytes"] < 3e6


def test_every_engine_sees_the_same_colours(built):
    """Each material's Principled BSDF base colour is its viewport colour, so Workbench,
    EEVEE, Cycles and the crowd's looks agree (Blender 5 gives new materials a grey
    node tree of their own: the pitch rendered grey in F12 before); the world is the
    preview's sky, seen through the Standard view transform."""
    from crowd_addon.blender.looks import principled
    from crowd_addon.gpu.renderer import BACKGROUND
    for mat in bpy.data.materials:
        bsdf = principled(mat)
        assert bsdf is not None, mat.name
        np.testing.assert_allclose(bsdf.inputs["Base Color"].default_value,
                                   mat.diffuse_color, atol=1e-6, err_msg=mat.name)
    scene = bpy.context.scene
    assert scene.view_settings.view_transform == "Standard"
    sky = [n for n in scene.world.node_tree.nodes if n.type == "BACKGROUND"][0]
    linear = np.asarray(sky.inputs["Color"].default_value[:3])
    display = np.where(linear <= 0.0031308, 12.92 * linear,
                       1.055 * linear ** (1 / 2.4) - 0.055)          # sRGB encoding
    np.testing.assert_allclose(display, BACKGROUND[:3], atol=2e-3)


def test_broadcast_camera_looks_across_the_pitch_at_the_far_stand(built):
    """The camera is high on the north stand, on the halfway line, looking across the
    pitch; the far (south) stand's seats are all in its frame."""
    scene = bpy.context.scene
    cam = scene.camera
    spec = _load_builder().layout.SPEC
    touchline = 0.5 * spec.pitch[1]
    assert abs(cam.location.x) < 1e-6 and cam.location.y > touchline
    assert cam.location.z >= 12.0
    forward = cam.matrix_world.to_3x3() @ Vector((0, 0, -1))
    assert forward.y < -0.8 and forward.z < 0
    seats = bpy.data.objects["Seats"]
    pos = np.array([seats.matrix_world @ v.co for v in seats.data.vertices])
    straight = 0.5 * spec.pitch[0] + spec.margin[0] - spec.corner_radius
    far = (pos[:, 1] < 0) & (np.abs(pos[:, 0]) <= straight)
    assert far.sum() > 0.15 * SEATS
    ndc = np.array([world_to_camera_view(scene, cam, Vector(p)) for p in pos[far]])
    assert np.all((ndc[:, :2] > 0.0) & (ndc[:, :2] < 1.0)) and np.all(ndc[:, 2] > 0)
    assert ndc[:, 0].min() < 0.1 and ndc[:, 0].max() > 0.9     # framed, not lost in it


def test_aerial_camera_sees_the_whole_bowl(built):
    """"AerialCamera" looks down at the bowl from over a corner, every seat in frame
    and the bowl filling it (the full stadium at a glance)."""
    scene = bpy.context.scene
    cam = bpy.data.objects["AerialCamera"]
    assert cam.type == "CAMERA" and scene.camera.name == "Camera"    # not the main one
    forward = cam.matrix_world.to_3x3() @ Vector((0, 0, -1))
    assert forward.z < -0.3
    seats = bpy.data.objects["Seats"]
    pos = np.array([seats.matrix_world @ v.co for v in seats.data.vertices])
    ndc = np.array([world_to_camera_view(scene, cam, Vector(p)) for p in pos])
    assert np.all((ndc[:, :2] > 0.0) & (ndc[:, :2] < 1.0)) and np.all(ndc[:, 2] > 0)
    assert np.ptp(ndc[:, 0]) > 0.8                              # fills the frame


def test_seats_have_attributes_and_groups(built):
    seats = bpy.data.objects["Seats"]
    mesh = seats.data
    assert len(mesh.vertices) == SEATS
    kinds = {a.name: (a.data_type, a.domain) for a in mesh.attributes}
    assert kinds["heading"] == ("FLOAT", "POINT")
    for name in ("section", "tier", "row", "seat", "team"):
        assert kinds[name] == ("INT", "POINT"), name
    heading = np.array([d.value for d in mesh.attributes["heading"].data])
    team = np.array([d.value for d in mesh.attributes["team"].data])
    pos = np.array([seats.matrix_world @ v.co for v in mesh.vertices])
    # the fan faces -Y at rest; rotating it by heading about +Z must face the pitch centre
    forward = np.array([(Matrix.Rotation(h, 3, "Z") @ Vector((0, -1, 0)))[:2] for h in heading])
    to_centre = -pos[:, :2] / np.linalg.norm(pos[:, :2], axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", forward, to_centre).min() > 0.999
    groups = {g.index: g.name for g in seats.vertex_groups}
    member = [[groups[g.group] for g in v.groups if g.weight > 0] for v in mesh.vertices]
    assert all(len(m) == 1 for m in member)
    np.testing.assert_array_equal([m == ["away"] for m in member], team == 1)
    assert 0 < (team == 1).sum() < SEATS
    # the away fans sit behind the east goal
    assert np.all(pos[team == 1, 0] > 0.5 * _load_builder().layout.SPEC.pitch[0])


def test_seats_sit_on_the_terraces_with_a_bench_behind(built):
    stands = bpy.data.objects["Stands"]
    seats = bpy.data.objects["Seats"]
    heading = [d.value for d in seats.data.attributes["heading"].data]
    inv = stands.matrix_world.inverted()
    for v, h in list(zip(seats.data.vertices, heading))[::7]:
        p = seats.matrix_world @ v.co
        hit, loc, normal, _ = stands.ray_cast(inv @ (p + Vector((0, 0, 0.3))), Vector((0, 0, -1)))
        assert hit and abs(loc.z - p.z) < 1e-3 and normal.z > 0.99
        back = Matrix.Rotation(h, 3, "Z") @ Vector((0, 1, 0))  # behind the fan
        hit, loc, _, _ = stands.ray_cast(inv @ (p + Vector((0, 0, 0.3))), back, distance=1.0)
        assert hit and 0.1 < (loc - p).xy.length < 0.5  # the bench under the seated hips


def test_fan_is_bound_and_free_of_constraints(built):
    rig, body = bpy.data.objects["FanRig"], bpy.data.objects["FanBody"]
    bones = {b.name for b in rig.data.bones}
    assert 20 <= len(bones) <= 30 and all(b.use_deform for b in rig.data.bones)
    assert {"root", "hips", "head", "hand.L", "hand.R", "foot.L", "foot.R"} <= bones
    assert all(len(pb.constraints) == 0 for pb in rig.pose.bones)
    assert len(rig.animation_data.drivers) == 0
    assert body.parent == rig and 300 <= len(body.data.vertices) <= 1500
    mods = [m for m in body.modifiers if m.type == "ARMATURE"]
    assert len(mods) == 1 and mods[0].object == rig
    assert {g.name for g in body.vertex_groups} <= bones
    totals = np.array([sum(g.weight for g in v.groups) for v in body.data.vertices])
    np.testing.assert_allclose(totals, 1.0, atol=1e-5)
    blended = sum(1 for v in body.data.vertices if sum(g.weight > 0.05 for g in v.groups) > 1)
    assert blended > 0.1 * len(body.data.vertices)  # smooth joints, not rigid parts


@pytest.mark.parametrize("name", sorted(FAN_ACTIONS))
def test_action_has_range_markers_and_moves_bones(built, name):
    rig, action = _play("FanRig", name)
    assert action.use_fake_user and action.use_frame_range
    start, end = int(action.frame_start), int(action.frame_end)
    assert start == 1 and 30 <= end - start <= 120  # 1-4 s at 30 fps
    markers = {(m.name, m.frame) for m in action.pose_markers}
    assert markers and FAN_ACTIONS[name] <= {m for m, _ in markers}
    assert all(start <= f <= end for _, f in markers)
    poses = np.array([_pose(rig, f) for f in range(start, end + 1, 3)])
    assert np.abs(poses - poses[0]).max() > 0.05
    assert action.use_cyclic == (name in LOOPS)
    if name in LOOPS:
        np.testing.assert_allclose(_pose(rig, start), _pose(rig, end), atol=1e-5)


def test_clap_markers_tag_hand_contact(built):
    rig, action = _play("FanRig", "clap")
    pb = rig.pose.bones

    def gap(frame):
        bpy.context.scene.frame_set(frame)
        return (pb["hand.L"].head - pb["hand.R"].head).length

    claps = [m.frame for m in action.pose_markers if m.name == "clap"]
    assert len(claps) == 2
    for f in claps:
        assert gap(f) < 0.06
    assert gap((claps[0] + claps[1]) // 2) > 0.2


def test_fans_sit_stand_and_keep_their_feet_down(built):
    rig = bpy.data.objects["FanRig"]
    pb = rig.pose.bones
    for name in FAN_ACTIONS:
        _, action = _play("FanRig", name)
        for f in range(int(action.frame_start), int(action.frame_end) + 1):
            bpy.context.scene.frame_set(f)
            for side in "LR":
                ankle = pb[f"foot.{side}"].head
                assert 0.05 < ankle.z < 0.12 and abs(ankle.y) < 0.06, (name, f, side)
    _play("FanRig", "idle_seated_a")
    bpy.context.scene.frame_set(1)
    assert pb["hips"].head.z < 0.6
    _, action = _play("FanRig", "stand_up")
    bpy.context.scene.frame_set(next(m.frame for m in action.pose_markers if m.name == "stand"))
    assert pb["hips"].head.z > 0.9


def test_body_deforms_with_the_clap(built):
    rig, action = _play("FanRig", "clap")
    body = bpy.data.objects["FanBody"]
    rest = np.array([v.co for v in body.data.vertices])
    bpy.context.scene.frame_set(next(m.frame for m in action.pose_markers))
    posed = _evaluated_points(body)
    assert posed.shape == rest.shape
    moved = np.linalg.norm(posed - rest, axis=1)
    assert moved.max() > 0.3
    # rigid hand vertices follow the hand bone exactly (linear blend skinning)
    hand = body.vertex_groups["hand.L"].index
    rigid = [v.index for v in body.data.vertices
             if any(g.group == hand and g.weight == 1.0 for g in v.groups)]
    bone = rig.pose.bones["hand.L"]
    skin = np.array(bone.matrix @ bone.bone.matrix_local.inverted())
    expected = rest[rigid] @ skin[:3, :3].T + skin[:3, 3]
    np.testing.assert_allclose(posed[rigid], expected, atol=1e-4)


def test_mocap_character_is_metric_animated_and_tagged(built):
    rig, action = _play("MocapRig", "mocap_01_01")
    body = bpy.data.objects["MocapBody"]
    assert action.use_fake_user
    start, end = int(action.frame_start), int(action.frame_end)
    jumps = [m.frame for m in action.pose_markers if m.name == "jump"]
    assert jumps and all(start < f < end for f in jumps)
    hips = rig.pose.bones["Hips"]
    heights = []
    for f in range(start, end + 1):
        bpy.context.scene.frame_set(f)
        heights.append(hips.head.z)
    standing = np.median(heights)
    assert 0.85 < standing < 1.15  # metres: an adult's hip height
    for f in jumps:
        assert heights[f - start] > standing + 0.1
    poses = np.array([_pose(rig, f) for f in (start, (start + end) // 2, end)])
    assert np.abs(poses - poses[0]).max() > 0.05
    mods = [m for m in body.modifiers if m.type == "ARMATURE"]
    assert body.parent == rig and len(mods) == 1 and mods[0].object == rig
    assert all(len(v.groups) == 1 and v.groups[0].weight == 1.0 for v in body.data.vertices)
    bpy.context.scene.frame_set(start)
    first = _evaluated_points(body)
    bpy.context.scene.frame_set(jumps[0])
    assert np.abs(_evaluated_points(body) - first).max() > 0.2


def test_command_line_writes_atomically_and_rejects_bad_input(tmp_path):
    out = tmp_path / "small.blend"
    run = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--seats", "40",
                          "--quiet"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "seats: 40" in run.stdout and "clap" in run.stdout and "mocap_01_01" in run.stdout
    assert [p.name for p in tmp_path.iterdir()] == ["small.blend"]
    bad = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "x.blend"),
                          "--seats", "0", "--quiet"], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode == 2 and "seats" in bad.stderr
    missing = tmp_path / "no_such_dir" / "x.blend"
    bad = subprocess.run([sys.executable, str(SCRIPT), "--out", str(missing), "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "no_such_dir" in bad.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["small.blend"]
