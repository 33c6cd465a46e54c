"""A multi-file export commits in one step, whatever kills it, and what a killed export
leaves behind is cleaned by the next one (defects found by probing: a kill between
the old commit's two renames lost the previous export's layers, or paired its main
layer with the new layers; killed exports left hidden temporary folders for good)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from pxr import Sdf, Usd

from crowd_addon.usd import export_crowd
from crowd_addon.usd import files as files_module

from .conftest import FIRST, recording

ROOT = Path(__file__).resolve().parents[2]

# a child process exports frames FIRST..LAST and dies (os._exit, no clean-up at all)
# at commit step STEP, or exits normally when STEP is "none"
CHILD = textwrap.dedent("""
    import os, sys
    sys.path[:0] = [{root!r}, {tests!r}]
    from usd.conftest import recording
    from crowd_addon.usd import export_crowd, files
    if {step!r} != "none":
        def die(name):
            if name == {step!r}:
                os._exit(9)
        files._step = die
    export_crowd(recording(None, ({first}, {last})), {path!r})
    """)


def export_in_child(path, last, step):
    code = CHILD.format(root=str(ROOT), tests=str(ROOT / "tests"), step=step,
                        first=FIRST, last=last, path=str(path))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)


def shot_frames(path):
    """(start, end) time codes of the stage at ``path``, opened with every layer it
    names resolving (an unresolved layer is an error here)."""
    stage = Usd.Stage.Open(str(path))
    for layer in stage.GetUsedLayers():
        for asset in layer.GetCompositionAssetDependencies():
            resolved = layer.ComputeAbsolutePath(asset)
            assert Sdf.Layer.FindOrOpen(resolved) is not None, f"{asset} does not open"
    return stage.GetStartTimeCode(), stage.GetEndTimeCode()


def leftovers(directory):
    """Hidden temporaries and layer versions in ``directory``."""
    tmp = sorted(n for n in os.listdir(directory) if n.endswith(".tmp"))
    layers = Path(directory) / "shot.layers"
    versions = sorted(os.listdir(layers)) if layers.is_dir() else []
    return tmp, versions


@pytest.mark.parametrize("step, survivor", [("start", 6), ("layers", 6), ("main", 9)])
def test_a_kill_at_any_commit_step_leaves_one_whole_export(tmp_path, step, survivor):
    path = tmp_path / "shot.usdc"
    export_crowd(recording(None, (FIRST, 6)), path)
    assert shot_frames(path) == (FIRST, 6)
    killed = export_in_child(path, 9, step)
    assert killed.returncode == 9, killed.stderr
    # before the main layer's rename the previous export is whole, after it the new one
    assert shot_frames(path) == (FIRST, survivor)
    # the next export cleans what the killed one left and leaves one version
    export_crowd(recording(None, (FIRST, 7)), path)
    assert shot_frames(path) == (FIRST, 7)
    tmp, versions = leftovers(tmp_path)
    assert tmp == [] and len(versions) == 1


def test_a_finished_export_keeps_only_its_own_version(tmp_path):
    path = tmp_path / "shot.usdc"
    first = export_crowd(recording(None, (FIRST, 6)), path)
    second = export_crowd(recording(None, (FIRST, 8)), path)
    assert first.layers_dir != second.layers_dir
    assert leftovers(tmp_path) == ([], [os.path.basename(second.layers_dir)])
    assert shot_frames(path) == (FIRST, 8)


def test_an_old_unversioned_layout_is_replaced(tmp_path):
    """Exports from before versioned layers kept them in shot.layers/ directly."""
    old = tmp_path / "shot.layers" / "characters"
    old.mkdir(parents=True)
    (old / "fan.usdc").write_bytes(b"old")
    (tmp_path / "shot.layers" / "agents.usdc").write_bytes(b"old")
    export_crowd(recording(None, (FIRST, 6)), tmp_path / "shot.usdc")
    assert leftovers(tmp_path) == ([], ["v1"])


def test_stale_temporaries_are_removed_live_ones_and_others_kept(tmp_path):
    dead = tmp_path / ".shot.usdc.abc123.tmp"            # a killed export's
    (dead / "layers").mkdir(parents=True)
    (dead / "owner").write_text(f"{os.uname().nodename} 999999999\n")
    ownerless = tmp_path / ".shot.usdc.def456.tmp"       # killed before its owner file
    ownerless.mkdir()
    live = tmp_path / ".shot.usdc.ghi789.tmp"            # an export running now
    live.mkdir()
    (live / "owner").write_text(f"{os.uname().nodename} {os.getpid()}\n")
    other = tmp_path / ".other.usdc.jkl012.tmp"          # another export's place
    other.mkdir()
    unrelated = tmp_path / ".shot.usdc.notes"            # not our naming
    unrelated.write_text("mine")
    export_crowd(recording(None, (FIRST, 6)), tmp_path / "shot.usdc")
    assert not dead.exists() and not ownerless.exists()
    assert live.is_dir() and other.is_dir() and unrelated.read_text() == "mine"


def test_the_commit_steps_are_where_the_kills_land():
    """Guards the kill test: the commit calls the step hook at each of its points."""
    import inspect
    source = inspect.getsource(files_module.ExportFiles.commit)
    for name in ("start", "layers", "main"):
        assert f'_step("{name}")' in source
