"""``crowd demo --layout blender`` writes the stage Blender's own USD importer plays
(issue 35, item 5): the demo wrote only the instanced layout, which that importer
shows frozen. A small demo run is imported with *Import Crowd USD*; the oracles are
``pxr`` (the stage's clock, its agents not instanceable) and Blender's evaluated
meshes (every fan moves over the shot, the scene at the stage's frame rate)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("moderngl")
pytest.importorskip("pxr")
from pxr import Usd  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "blender"))
import crowd_scene as cs  # noqa: E402
from test_usd_import import world_vertices as mesh_positions  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
AGENTS, FRAMES = 40, 12

extension = cs.extension_fixture()


def test_the_demos_blender_layout_plays_in_blender(tmp_path):
    out = tmp_path / "demo"
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "demo", "--out", str(out),
                          "--agents", str(AGENTS), "--frames", str(FRAMES), "--width", "160",
                          "--height", "90", "--no-mp4", "--layout", "blender"],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["usd_layout"] == "blender" and "blender layout" in run.stdout
    stage = Usd.Stage.Open(str(out / "stadium.usdc"))
    agents = stage.GetPrimAtPath("/Crowd/Agents").GetChildren()
    assert len(agents) == AGENTS and not any(p.IsInstanceable() for p in agents)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.crowd.import_usd(filepath=str(out / "stadium.usdc")) == {"FINISHED"}
    scene = bpy.context.scene
    assert scene.render.fps / scene.render.fps_base == stage.GetTimeCodesPerSecond()
    assert (scene.frame_start, scene.frame_end) == (1, FRAMES)
    bodies = [o for o in bpy.data.objects if o.type == "MESH" and o.parent is not None
              and o.find_armature() is not None]
    scene.frame_set(1)
    first = {o.name: mesh_positions(o) for o in bodies}
    scene.frame_set(FRAMES)
    moved = [o.name for o in bodies if np.abs(mesh_positions(o) - first[o.name]).max() > 1e-3]
    assert len(bodies) >= AGENTS and len(moved) >= AGENTS, (len(bodies), len(moved))
