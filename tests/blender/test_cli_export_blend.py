"""``crowd export`` from a Blender scene: ``--blend`` with the bpy module, and the
``crowd`` command registered for ``blender -b scene.blend -c crowd export``.

Oracle: pxr reads the exported stage back with one instanced agent SkelRoot per seat
of the scene's agent source.
"""

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("bpy")
pytest.importorskip("pxr")

ROOT = Path(__file__).resolve().parents[2]

PREPARE = r"""
import sys, bpy
sys.path.insert(0, "sample_scenes")
from build_stadium import build_stadium
from crowd_addon import register
build_stadium(sys.argv[1], log=None)       # for the Blender that runs (4.2 cannot read 5.0's)
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
register()
from crowd_addon.blender.stadium_cast import setup_crowd
setup_crowd(bpy.context.scene, hits=2, slots=16)
bpy.context.preferences.filepaths.save_version = 0
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
from crowd_addon.blender.cli_commands import crowd_command
# what `blender -b scene.blend -c crowd export ...` runs
rc = crowd_command(["export", "--out", sys.argv[3], "--frames", "1-12"])
print("RC", rc)
rc = crowd_command(["export", "--out", sys.argv[4], "--frames", "1-3", "--layout", "blender"])
print("RC", rc)
rc = crowd_command(["export", "--out", sys.argv[5], "--frames", "2-4", "--substeps", "2",
                    "--snapshots", sys.argv[6]])
print("RC", rc)
"""


@pytest.fixture(scope="module")
def crowd_blend(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli_blend")
    blend, usd = tmp / "crowd.blend", tmp / "from_cli_command.usdc"
    run = subprocess.run([sys.executable, "-c", PREPARE,
                          str(tmp / "stadium.blend"), str(blend), str(usd),
                          str(tmp / "for_blender.usdc"), str(tmp / "blur.usdc"),
                          str(tmp / "snaps")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.count("RC 0") == 3, run.stdout[-2000:] + run.stderr[-2000:]
    return tmp, blend, usd


def agents_in(path):
    from pxr import Usd, UsdSkel
    stage = Usd.Stage.Open(str(path))
    return sum(1 for p in stage.Traverse() if p.IsA(UsdSkel.Root) and p.IsInstance())


def test_registered_crowd_command_exports_the_open_scene(crowd_blend):
    _, _, usd = crowd_blend
    assert agents_in(usd) == 2000


def test_the_crowd_command_takes_the_layout(crowd_blend):
    from pxr import Usd
    tmp, _, _ = crowd_blend
    stage = Usd.Stage.Open(str(tmp / "for_blender.usdc"))
    agents = stage.GetPrimAtPath("/Crowd/Agents").GetChildren()
    assert len(agents) == 2000 and not any(p.IsInstanceable() for p in agents)


def test_the_crowd_command_takes_substeps_and_a_snapshot_folder(crowd_blend):
    from pxr import Usd
    tmp, _, _ = crowd_blend
    stage = Usd.Stage.Open(str(tmp / "blur.usdc"))
    assert stage.GetRootLayer().customLayerData["crowd"]["substeps"] == 2
    assert [p.name.rsplit("_", 1)[1] for p in (tmp / "snaps").glob("*.npz")] == ["f4.npz"]


def test_python_m_export_with_blend(crowd_blend):
    tmp, blend, _ = crowd_blend
    out = tmp / "from_blend.usda"
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "export", "--blend", str(blend),
                          "--out", str(out), "--frames", "1-12"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "baking action" in run.stderr and agents_in(out) == 2000


@pytest.mark.parametrize("args, message", [
    (["--blend", "missing.blend"], "no such .blend file"),
    (["--scene", "Nope"], "no scene 'Nope'"),
    (["--blend", "notes.blend"], "notes.blend: Blender cannot open it as a .blend file"),
])
def test_bad_blend_input_is_named(crowd_blend, args, message):
    """A text file given as --blend used to end in a RuntimeError traceback."""
    tmp, blend, _ = crowd_blend
    if args[0] == "--scene":
        args = ["--blend", str(blend)] + args
    if args[1] == "notes.blend":
        (tmp / "notes.blend").write_text("not a blend file\n")
        args = ["--blend", str(tmp / "notes.blend")]
    out = tmp / "bad.usdc"
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "export", *args, "--out",
                          str(out), "--frames", "1-5"], cwd=ROOT, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 2 and message in run.stderr
    assert not out.exists()
