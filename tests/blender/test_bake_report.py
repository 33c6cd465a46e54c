"""The bake report on every path (issue 35, items 1 and 2).

A CMU motion capture take (Debian's ``assimp-testmodels``) baked with one sample a
frame misses Blender's own poses at half frames (``frame_set(f, subframe=0.5)``, the
oracle): the bake warns, naming the frames and the size in scene units. A character
with that take and a body whose vertices have 9 bone influences then goes through
each path (the API, the Bake and Export Crowd USD operators, ``crowd export``,
``preview``, ``plan`` and ``snapshot --blend``): the same notes reach the command
line's stderr and the operators' reports, and ``--strict`` exits 2 with nothing
written.
"""

import glob
import os
import re
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402
from test_many_influences import many_groups  # noqa: E402

from crowd_addon.blender import export, scene_config, scene_export  # noqa: E402
from crowd_addon.blender.bake import bake_actions  # noqa: E402
from crowd_addon.core.bake.bake_report import report_of  # noqa: E402
from crowd_addon.core.anim.clip import ClipBank  # noqa: E402
from crowd_addon.core.base.skinning import model_matrices  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BVH = "/usr/share/assimp/models/BVH"
extension = cs.extension_fixture()
pytestmark = pytest.mark.skipif(not glob.glob(f"{BVH}/*.bvh"),
                                reason="needs Debian's assimp-testmodels (CMU BVH files)")


def import_bvh(name):
    bpy.ops.import_anim.bvh(filepath=f"{BVH}/{name}.bvh")
    rig = bpy.context.object
    return rig, rig.animation_data.action


def test_a_cmu_take_missing_blender_at_half_frames_is_warned_with_frames_and_size():
    scene = cs.reset()
    rig, action = import_bvh("Boxing_Toes")
    result = bake_actions(rig, [action], fps=scene.render.fps / scene.render.fps_base)
    clip = result.clips[0]
    sk = result.skeleton
    start = float(action.frame_range[0])
    halves = np.arange(clip.frame_count - 1) + 0.5             # clip frames
    got = model_matrices(ClipBank([clip]).sample(np.zeros(len(halves), np.int64), halves), sk)
    pbs = rig.pose.bones
    order = [pbs.find(n) for n in sk.bone_names]
    want = np.empty_like(got)
    buf = np.empty(len(pbs) * 16, np.float32)
    for k, t in enumerate(halves):
        f = start + t
        scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
        pbs.foreach_get("matrix", buf)
        want[k] = buf.reshape(-1, 4, 4).transpose(0, 2, 1)[order]
    position = np.linalg.norm(got[..., :3, 3] - want[..., :3, 3], axis=-1)
    ra = got[..., :3, :3] / np.linalg.norm(got[..., :3, :3], axis=-2, keepdims=True)
    rb = want[..., :3, :3] / np.linalg.norm(want[..., :3, :3], axis=-2, keepdims=True)
    rotation = 2 * np.arcsin(np.minimum(np.linalg.norm(ra - rb, axis=(-2, -1))
                                        / (2 * np.sqrt(2)), 1))
    assert position.max() > 1e-3 or rotation.max() > 1e-3     # Blender's oracle: it misses
    note, = result.notes
    assert note.kind == "between_frames" and note.severity == "warning"
    i = int(np.unravel_index(np.argmax(position), position.shape)[0])
    size = float(re.search(r"head is ([0-9.e-]+) scene units off", note).group(1))
    assert size == pytest.approx(position.max(), rel=0.01, abs=2e-5), note
    frames = f"frames {start + i:g} and {start + i + 1:g}"
    assert f"halfway between the keys at {frames} bone" in note, (frames, note)
    if rotation.max() > 1e-3:
        turned = float(re.search(r"is turned ([0-9.e-]+) rad off", note).group(1))
        assert turned == pytest.approx(rotation.max(), rel=0.01, abs=2e-5), note
    assert "samples per frame" in note
    bad = int(((position > 1e-3) | (rotation > 1e-3)).any(1).sum())
    counted = int(re.search(rf"(\d+) of {len(halves)} key intervals miss", note).group(1))
    assert counted == pytest.approx(bad, rel=0.02), (bad, note)      # float32 at the edge


def build_scene():
    """A CMU boxing take on its armature, a body of 9 influences a vertex, four agents,
    frames 1..4."""
    scene = cs.reset()
    rig, action = import_bvh("Boxing_Toes")
    rig.animation_data.action = None
    scene.frame_start, scene.frame_end = 1, 4
    body = many_groups(scene, rig, 9)
    s = scene.crowd
    s.max_offset = 4
    cs.add_stream(cs.add_character(s, rig, body, name="Boxer"), "box", action)
    src = s.agent_sources.add()
    src.name, src.object = "seats", cs.make_seats(2, 2)
    bpy.context.view_layer.update()
    return scene


def is_influence(note):
    return "more than 8 bone influences" in note


def is_between(note):
    return "between frames the crowd's pose misses the action's" in note


@pytest.fixture(scope="module")
def blend(tmp_path_factory):
    path = tmp_path_factory.mktemp("bake_report") / "boxer.blend"
    build_scene()
    bpy.context.preferences.filepaths.save_version = 0
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    return path


def crowd(*args):
    return subprocess.run([sys.executable, "-m", "crowd_addon", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def test_the_api_and_the_operators_report_the_same_notes(tmp_path):
    scene = build_scene()
    config = scene_config.config_from_scene(scene)                # the API
    report = report_of(config)
    kinds = [n.kind for n in report.warnings]      # then the LOD levels refused, if any
    assert kinds[:2] == ["between_frames", "mesh"] and set(kinds[2:]) <= {"lod"}, kinds
    assert is_between(report.warnings[0]) and is_influence(report.warnings[1])
    op = cs.FakeBakeOperator(scene)                              # Bake
    timer = type("Event", (), {"type": "TIMER"})()
    while op.modal(bpy.context, timer) == {"RUNNING_MODAL"}:
        pass
    assert [m for kind, m in op.reports if kind == {"WARNING"}] == list(report.warnings)
    said = []                                                    # Export Crowd USD
    cfg, result = scene_export.export_scene(scene, str(tmp_path / "a.usdc"), (1, 4),
                                            on_bake=lambda d, t, m: said.append(m))
    assert [f"warning: {n}" for n in report.warnings] == \
        [m for m in said if m.startswith("warning: ")]
    fake = type("Op", (), {"reports": [], "_made": ()})()
    fake.report = lambda kind, message: fake.reports.append((kind, message))
    export.CROWD_OT_export_usd._finish(fake, result, cfg)
    assert [m for kind, m in fake.reports if kind == {"WARNING"}] == list(report.warnings)
    with pytest.raises(Exception, match="--strict"):
        scene_export.export_scene(scene, str(tmp_path / "b.usdc"), (1, 4), strict=True)
    assert not (tmp_path / "b.usdc").exists()


def test_every_command_prints_the_notes_and_strict_exits_2(blend, tmp_path):
    out = tmp_path / "shot.usdc"
    r = crowd("export", "--blend", blend, "--out", out)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("crowd export: warning: ")]
    assert len(lines) >= 2 and is_between(lines[0]) and is_influence(lines[1]), r.stderr
    assert out.exists()
    for command, extra in (("export", ["--out", tmp_path / "s.usdc"]),
                           ("preview", ["--out", tmp_path / "frames", "--frames", "1"]),
                           ("plan", ["--no-plot"]),
                           ("snapshot", ["--out", tmp_path / "snaps", "--every", "2"])):
        r = crowd(command, "--blend", blend, "--strict", *extra)
        assert r.returncode == 2, (command, r.stderr)
        warned = [ln for ln in r.stderr.splitlines()
                  if ln.startswith(f"crowd {command}: warning: ")]
        assert [ln.split(": warning: ")[1] for ln in warned] == \
            [ln.split(": warning: ")[1] for ln in lines], (command, r.stderr)
        assert "--strict" in r.stderr.strip().splitlines()[-1], r.stderr
    assert not (tmp_path / "s.usdc").exists() and not os.listdir(tmp_path / "frames") \
        if (tmp_path / "frames").exists() else True
