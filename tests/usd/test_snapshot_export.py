"""``crowd snapshot`` and ``crowd export --snapshots``: a chunk of a shot exported from
the snapshot before it equals the same frames exported by simulating from the start
frame (the oracle), file for file, with the same events; chunks chain through the
snapshot each export leaves at its last frame."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from crowd_addon.cli import main
from crowd_addon.core.authoring.config_io import save_config
from crowd_addon.core.authoring.show import Action, Cue, Show, Sweep

from .conftest import FAN_AGENTS, make_config

ROOT = Path(__file__).resolve().parents[2]


def show_config():
    """The module's crowd with a show: a held sweep (the queue fills: 3 slots), a
    unique with its return, a trigger, a random-offset stand over many frames."""
    cfg = make_config()
    fans = np.arange(FAN_AGENTS)
    cfg.show = Show((Cue("wave", 4, Action("stream", "cheer.loud", 3, hold=5),
                         sweep=Sweep((0, 0, 0), "angle", 0.8), agents=fans),
                     Cue("solo", 9, Action("unique", "solo", 2, hold=6), agents=fans[:3]),
                     Cue("go", 12, Action("trigger", "wave", name="go")),
                     Cue("stand", 23, Action("stream", "idle", 4, offset="random", hold=8),
                         agents=fans[::2], spread=6, seed=3)))
    return cfg


@pytest.fixture(scope="module")
def config_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("config") / "crowd.json"
    save_config(show_config(), path)
    return path


def export(config_path, out, frames, capsys, *extra):
    assert main(["export", "--config", str(config_path), "--out", str(out), "--frames",
                 frames, "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)


def files(result):
    """Every file an export wrote, by name relative to the main layer's folder."""
    top = Path(result["path"]).parent
    return {name: (top / name).read_bytes() for name in result["files"]}


def test_a_chunk_from_its_snapshot_equals_the_chunk_simulated_from_the_start(
        config_path, tmp_path, capsys):
    snaps = tmp_path / "snaps"
    assert main(["snapshot", "--config", str(config_path), "--frames", "1-40", "--every",
                 "10", "--out", str(snaps), "--json"]) == 0
    written = json.loads(capsys.readouterr().out)
    frames = sorted(int(Path(f).stem.rsplit("_f", 1)[1]) for f in written["files"])
    assert frames == [10, 20, 30, 40]     # before the chunks 11, 21, 31 (1: the start); the last
    plain = export(config_path, tmp_path / "plain" / "shot.usdc", "21-34", capsys)
    chunk = export(config_path, tmp_path / "chunk" / "shot.usdc", "21-34", capsys,
                   "--snapshots", str(snaps))
    assert plain["started_from"] is None and chunk["started_from"] == 20
    assert chunk["events"] == plain["events"] and plain["events"]
    assert files(chunk) == files(plain)
    assert chunk["clip_agents"] > 0 and chunk["blend_frames"] > 0      # the show ran
    stem = Path(written["files"][0]).name.rsplit("_f", 1)[0]
    assert chunk["snapshot"] == str(snaps / f"{stem}_f34.npz")


def test_chunks_chain_through_the_snapshot_each_export_leaves(config_path, tmp_path,
                                                              capsys):
    snaps = tmp_path / "chain"                           # created by the first export
    first = export(config_path, tmp_path / "a" / "shot.usdc", "3-17", capsys,
                   "--snapshots", str(snaps))
    assert first["started_from"] is None and Path(first["snapshot"]).exists()
    second = export(config_path, tmp_path / "b" / "shot.usdc", "18-30", capsys,
                    "--snapshots", str(snaps))
    assert second["started_from"] == 17
    plain = export(config_path, tmp_path / "c" / "shot.usdc", "18-30", capsys)
    assert files(second) == files(plain) and second["events"] == plain["events"]


def test_snapshots_of_another_crowd_are_not_used(config_path, tmp_path, capsys):
    other = tmp_path / "other.json"
    save_config(make_config(), other)                  # no show: another digest
    snaps = tmp_path / "snaps"
    assert main(["snapshot", "--config", str(other), "--frames", "1-20", "--every", "5",
                 "--out", str(snaps)]) == 0
    assert "wrote 4 snapshots" in capsys.readouterr().out      # 5, 10, 15, 20
    assert main(["export", "--config", str(config_path), "--out",
                 str(tmp_path / "x.usdc"), "--frames", "12-14", "--snapshots",
                 str(snaps)]) == 0
    out = capsys.readouterr().out
    assert "no snapshot of this crowd before the shot: simulated from its start frame" in out
    assert "left " in out and "_f14.npz for the next chunk" in out


@pytest.mark.parametrize("argv, message", [
    (["snapshot", "--every", "2", "--out", "{tmp}/s", "--config", "{cfg}"],
     "--frames FIRST-LAST is required"),
    (["snapshot", "--frames", "1-5", "--every", "0", "--out", "{tmp}/s", "--config", "{cfg}"],
     "--every"),
    (["snapshot", "--frames", "9-5", "--every", "2", "--out", "{tmp}/s", "--config", "{cfg}"],
     "last frame 5 is before first frame 9"),
    (["export", "--frames", "3-5", "--out", "{tmp}/x.usdc", "--config", "{cfg}",
      "--snapshots", "{cfg}"], "snapshot folder .*crowd.json: cannot create it"),
])
def test_bad_input_is_named_and_writes_nothing(config_path, tmp_path, capsys, argv, message):
    argv = [a.format(tmp=tmp_path, cfg=config_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "error:" in err and re.search(message, err), err
    assert not (tmp_path / "x.usdc").exists()
    assert not list(tmp_path.glob("s/*.npz"))


def test_a_snapshot_that_cannot_be_written_leaves_the_earlier_export(config_path, tmp_path,
                                                                     capsys):
    """The snapshot an export leaves at its last frame cannot be written (a full disk):
    before, the export was already in place when that failed, so the command reported
    an error over a replaced stage; now the export is not put in place."""
    out, snaps = tmp_path / "out" / "shot.usdc", tmp_path / "snaps"
    first = export(config_path, out, "1-12", capsys, "--snapshots", str(snaps))
    before = {p: p.read_bytes() for p in out.parent.rglob("*") if p.is_file()}
    kept = Path(first["snapshot"])
    kept.unlink()
    kept.mkdir()                                   # the same file cannot be written now
    assert main(["export", "--config", str(config_path), "--out", str(out), "--frames",
                 "1-12", "--agents", "5", "--snapshots", str(snaps)]) == 2
    assert "cannot write the crowd snapshot" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in out.parent.rglob("*") if p.is_file()} == before


def test_a_failed_export_removes_the_snapshot_folder_it_made(config_path, tmp_path, capsys):
    assert main(["export", "--config", str(config_path), "--out", str(tmp_path / "x.usdc"),
                 "--frames=-3-5", "--snapshots", str(tmp_path / "new" / "snaps")]) == 2
    assert "before the crowd's start frame" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_failed_snapshot_run_removes_the_folder_it_made(tmp_path, capsys):
    assert main(["snapshot", "--config", str(tmp_path / "nope.json"), "--out",
                 str(tmp_path / "s4"), "--frames", "0-20", "--every", "5"]) == 2
    assert "nope.json" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_python_m_crowd_addon_snapshot_help():
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "snapshot", "--help"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and "--every N" in run.stdout and "--out DIR" in run.stdout


def test_a_farm_by_hand_animation_only_chunks_stitched_equal_the_whole_export(
        config_path, tmp_path, capsys):
    """The commands a farm runs (docs/snapshots.md): one snapshot pass, the first chunk
    whole, the others ``--animation-only`` (no agents, characters or offset
    animations), ``crowd stitch``: the stitched stage's joints and transforms are the
    single export's at every frame."""
    from pxr import Sdf

    from .test_stitch import read

    snaps = tmp_path / "snaps"
    assert main(["snapshot", "--config", str(config_path), "--frames", "1-30", "--every",
                 "10", "--out", str(snaps)]) == 0
    capsys.readouterr()
    whole = export(config_path, tmp_path / "whole" / "shot.usdc", "1-30", capsys)
    chunks = [export(config_path, tmp_path / f"c{k}" / "shot.usdc", f"{a}-{a + 9}", capsys,
                     "--snapshots", str(snaps), *(("--animation-only",) if k else ()))
              for k, a in enumerate((1, 11, 21))]
    for k, chunk in enumerate(chunks):
        names = {Path(f).name for f in chunk["files"]}
        assert ("layout.usdc" in names) == (k == 0), names
        assert (chunk["characters"] > 0) == (k == 0)
        crowd = Sdf.Layer.FindOrOpen(chunk["path"]).customLayerData["crowd"]
        assert crowd["animationOnly"] == (k > 0)
    assert main(["stitch", "--out", str(tmp_path / "shot.usdc"),
                 *(c["path"] for c in chunks)]) == 0
    times = list(range(1, 31))
    _, want = read(whole["path"], times)
    _, got = read(tmp_path / "shot.usdc", times)
    assert sorted(got) == sorted(want)
    for name, (joints, world) in want.items():
        np.testing.assert_allclose(got[name][0], joints, atol=1e-6, err_msg=name)
        np.testing.assert_allclose(got[name][1], world, atol=1e-6, err_msg=name)
    assert main(["export", "--config", str(config_path), "--out",
                 str(tmp_path / "w.usdc"), "--frames", "1-30", "--workers", "2",
                 "--animation-only"]) == 2
    assert "leave out --animation-only" in capsys.readouterr().err
