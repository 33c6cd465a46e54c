"""``crowd export --workers N`` on a Dask cluster (crowd_addon/farm/): a shot exported
in four chunks by a ``LocalCluster`` of two worker processes, then stitched, reads back
as the single-process export of the whole range (pxr UsdSkel joint and agent
transforms of every agent at every frame, to 1e-6) with the same events in its
stream animations. A chunk that fails is retried once, then named, and the stage
already at the output is left as it was."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from dask.distributed import LocalCluster  # a missing Dask fails the run, never skips

from crowd_addon.cli import main
from crowd_addon.core.authoring.config_io import save_config
from crowd_addon.farm.chunks import chunk_folder, chunk_ranges

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))       # tests/: the usd tests
from usd.test_snapshot_export import show_config  # noqa: E402
from usd.test_stitch import read, stream_events  # noqa: E402

FRAMES = (1, 40)


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """The configuration and the single-process export of the whole range."""
    tmp = tmp_path_factory.mktemp("farm")
    config = tmp / "crowd.json"
    save_config(show_config(), config)
    whole = tmp / "whole" / "shot.usdc"
    assert main(["export", "--config", str(config), "--out", str(whole), "--frames",
                 f"{FRAMES[0]}-{FRAMES[1]}"]) == 0
    return tmp, config, whole


@pytest.fixture(scope="module")
def cluster():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as c:
        yield c


def same_shot(path, whole):
    times = list(range(FRAMES[0], FRAMES[1] + 1))
    want_stage, want = read(whole, times)
    got_stage, got = read(path, times)
    assert sorted(got) == sorted(want)
    worst = max(max(float(np.abs(got[n][0] - want[n][0]).max()),
                    float(np.abs(got[n][1] - want[n][1]).max())) for n in want)
    assert worst < 1e-6, worst
    assert stream_events(got_stage) == stream_events(want_stage) != {}


def test_four_chunks_on_two_local_workers_equal_the_single_process_export(shot, capsys):
    tmp, config, whole = shot
    out = tmp / "farm" / "shot.usdc"
    assert main(["export", "--config", str(config), "--out", str(out), "--frames",
                 f"{FRAMES[0]}-{FRAMES[1]}", "--workers", "2", "--chunk-frames", "10",
                 "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert [c["frames"] for c in summary["chunk_exports"]] == \
        [list(r) for r in chunk_ranges(*FRAMES, 10)]                # four chunks
    assert [c["started_from"] for c in summary["chunk_exports"]] == [None, 10, 20, 30]
    assert "crowd export: chunks 4/4" in captured.err
    same_shot(out, whole)
    log = (tmp / "farm" / "shot.chunks" / "attempts.log").read_text().splitlines()
    done = sorted(line.split(": done on")[0].split(" ", 2)[2] for line in log)
    assert done == sorted([f"chunk {k} (frames {a}-{b})"
                           for k, (a, b) in enumerate(chunk_ranges(*FRAMES, 10))]
                          + ["snapshots", "stitch"])


def test_an_existing_scheduler_runs_the_chunks(shot, cluster, capsys):
    tmp, config, whole = shot
    out = tmp / "sched" / "shot.usda"
    assert main(["export", "--config", str(config), "--out", str(out), "--frames",
                 f"{FRAMES[0]}-{FRAMES[1]}", "--scheduler", cluster.scheduler_address,
                 "--chunk-frames", "13"]) == 0
    assert "stitched from 4 chunks" in capsys.readouterr().out     # 13 + 13 + 13 + 1
    same_shot(out, whole)


def test_a_failing_chunk_is_retried_once_named_and_the_old_stage_kept(shot, cluster,
                                                                      capsys):
    tmp, config, whole = shot
    out = tmp / "kept" / "shot.usdc"
    args = ["export", "--config", str(config), "--out", str(out), "--frames",
            f"{FRAMES[0]}-{FRAMES[1]}", "--scheduler", cluster.scheduler_address,
            "--chunk-frames", "10"]
    assert main(args) == 0
    capsys.readouterr()
    before = out.read_bytes()
    # chunk 2's output folder cannot be made: a file stands where it goes
    blocker = next(p for p in (tmp / "kept" / "shot.chunks").glob("c0002_*"))
    for f in blocker.rglob("*"):
        if f.is_file():
            f.unlink()
    import shutil
    shutil.rmtree(blocker)
    blocker.write_text("in the way")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "chunk 2 (frames 21-30) failed twice" in err and "nothing was stitched" in err
    assert out.read_bytes() == before
    blocker.unlink()
    assert main(args) == 0                                          # and it recovers
    same_shot(out, whole)
    log = (tmp / "kept" / "shot.chunks" / "attempts.log").read_text()
    assert log.count("chunk 2 (frames 21-30): failed on") == 2          # tried twice
    assert log.count("chunk 2 (frames 21-30): done on") == 2            # before and after


def test_a_shot_list_runs_every_shot_on_one_cluster(shot, cluster, tmp_path, capsys):
    """Two shots and one whose snapshot folder cannot be made: the two are written
    (the first equals the single export), the third is named and writes nothing."""
    tmp, config, whole = shot
    shots = tmp_path / "shots.json"
    shots.write_text(json.dumps({"shots": [
        {"config": str(config), "frames": f"{FRAMES[0]}-{FRAMES[1]}", "out": "a/shot.usdc",
         "chunk_frames": 15},
        {"config": str(config), "frames": "5-24", "out": "b/shot.usda", "substeps": 2},
        {"config": str(config), "frames": "1-10", "out": "c/shot.usdc"}]}))
    (tmp_path / "c" / "shot.chunks").mkdir(parents=True)
    (tmp_path / "c" / "shot.chunks" / "snapshots").write_text("in the way")
    assert main(["farm", str(shots), "--scheduler", cluster.scheduler_address,
                 "--json"]) == 2
    captured = capsys.readouterr()
    a, b, c = json.loads(captured.out)["shots"]
    assert a["frames"] == list(FRAMES) and len(a["chunk_exports"]) == 3
    assert b["frames"] == [5, 24] and "snapshots: cannot create it" in c["error"]
    assert "crowd farm: error:" in captured.err and "snapshot pass failed" in captured.err
    assert "crowd farm: chunks" in captured.err
    same_shot(tmp_path / "a" / "shot.usdc", whole)
    from pxr import Usd
    stage = Usd.Stage.Open(str(tmp_path / "b" / "shot.usda"))
    assert stage.GetRootLayer().customLayerData["crowd"]["substeps"] == 2
    assert not (tmp_path / "c" / "shot.usdc").exists()


@pytest.mark.parametrize("shots, message", [
    ({"shots": []}, "at least one shot"),
    ([1], "at least one shot"),
    ({"shots": [{"config": "x.json", "frames": "1-4"}]}, "shot 0: 'out' is required"),
    ({"shots": [{"config": "x.json", "out": "a.usdc", "frames": "1-4", "speed": 2}]},
     "shot 0: unknown key 'speed'"),
    ({"shots": [{"config": "x.json", "blend": "y.blend", "out": "a.usdc", "frames": "1-4"}]},
     "give one of 'config' and 'blend'"),
    ({"shots": [{"config": "x.json", "out": "a.usdc", "frames": "4-1"}]}, "shot 0: 'frames'"),
    ({"shots": [{"config": "x.json", "out": "a.usdc", "frames": 4}]},
     "'frames' must be a str"),
    ({"shots": [{"config": "x.json", "out": "a.usdc", "frames": "1-4"},
                {"config": "y.json", "out": "./a.usdc", "frames": "1-4"}]},
     "shot 1: 'out' './a.usdc' is another shot's output too"),
])
def test_bad_shot_lists_are_named_before_anything_runs(tmp_path, capsys, shots, message):
    path = tmp_path / "shots.json"
    path.write_text(json.dumps(shots))
    assert main(["farm", str(path)]) == 2
    assert message in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shots.json"]


def test_farm_options_are_checked(shot, capsys):
    tmp, config, _ = shot
    base = ["export", "--config", str(config), "--out", str(tmp / "x.usdc")]
    assert main(base + ["--workers", "2"]) == 2
    assert "--frames FIRST-LAST is required with --config" in capsys.readouterr().err
    assert main(base + ["--frames", "1-4", "--workers", "2", "--snapshots",
                        str(tmp)]) == 2
    assert "leave out --snapshots" in capsys.readouterr().err
    assert main(base + ["--frames", "1-4", "--scheduler", "tcp://127.0.0.1:9"]) == 2
    assert "cannot connect" in capsys.readouterr().err
    assert chunk_folder(tmp / "x.usdc") == str(tmp / "x.chunks")


PREPARE = """
import sys, bpy
sys.path.insert(0, "sample_scenes")
from build_stadium import build_stadium
from crowd_addon import register
build_stadium(sys.argv[1], log=None)
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
register()
from crowd_addon.blender.stadium_cast import setup_crowd
setup_crowd(bpy.context.scene, hits=2, slots=16)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
"""


def test_a_blend_shot_on_workers_equals_its_single_process_export(tmp_path):
    """Each worker opens the .blend with the bpy module, although the process that
    started the cluster has imported bpy (its Blender script folders on the path the
    workers inherit used to hide the module from them)."""
    import subprocess
    root = Path(__file__).resolve().parents[2]
    blend = tmp_path / "crowd.blend"
    run = subprocess.run([sys.executable, "-c", PREPARE, str(tmp_path / "stadium.blend"),
                          str(blend)], cwd=root, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    outs = {}
    for name, extra in (("plain", ()), ("farm", ("--workers", "2"))):
        outs[name] = tmp_path / name / "shot.usdc"
        run = subprocess.run([sys.executable, "-m", "crowd_addon", "export", "--blend",
                              str(blend), "--frames", "1-16", "--out", str(outs[name]),
                              *extra], cwd=root, capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr[-3000:]
    times = list(range(1, 17))
    want_stage, want = read(outs["plain"], times)
    got_stage, got = read(outs["farm"], times)
    assert len(got) == len(want) == 2000
    worst = max(max(float(np.abs(got[n][0] - want[n][0]).max()),
                    float(np.abs(got[n][1] - want[n][1]).max())) for n in want)
    assert worst < 1e-6, worst
    assert stream_events(got_stage) == stream_events(want_stage)


def stage_layers(path):
    """Every layer file the stage at ``path`` reads (pxr's walk over its sublayers,
    references and value clips), with its bytes, and what does not resolve."""
    from pxr import UsdUtils
    layers, _, unresolved = UsdUtils.ComputeAllDependencies(str(path))
    return {layer.realPath: Path(layer.realPath).read_bytes() for layer in layers}, \
        list(unresolved)


def test_a_re_run_whose_chunk_fails_twice_leaves_the_earlier_stage_whole(shot, cluster,
                                                                         capsys):
    """Issue 31 item 2: the other chunks of the re-run are exported again in place (new
    layer versions) while chunk 2 fails twice; the stage from the earlier run must keep
    every layer it reads (its chunks' blend banks and characters among them) and read
    the same samples, and the message must say so truthfully."""
    tmp, config, whole = shot
    out = tmp / "rerun" / "shot.usdc"
    args = ["export", "--config", str(config), "--out", str(out), "--frames",
            f"{FRAMES[0]}-{FRAMES[1]}", "--scheduler", cluster.scheduler_address,
            "--chunk-frames", "10"]
    assert main(args) == 0
    capsys.readouterr()
    times = list(range(FRAMES[0], FRAMES[1] + 1))
    layers, unresolved = stage_layers(out)
    assert unresolved == [] and len(layers) > 10
    _, samples = read(out, times)
    # chunk 2 fails: a folder stands where its main layer goes (its layers, which the
    # earlier stage reads, are left alone)
    chunk2 = next((tmp / "rerun" / "shot.chunks").glob("c0002_*")) / "shot.usdc"
    chunk2.unlink()
    chunk2.mkdir()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "chunk 2 (frames 21-30) failed twice" in err
    assert f"nothing was stitched ({out} is as it was" in err
    again, unresolved = stage_layers(out)
    assert unresolved == []
    assert again == layers                               # every layer, byte for byte
    _, now = read(out, times)
    for name, (joints, world) in samples.items():        # the same samples
        np.testing.assert_array_equal(now[name][0], joints)
        np.testing.assert_array_equal(now[name][1], world)
    chunk2.rmdir()
    assert main(args) == 0                               # and it recovers
    same_shot(out, whole)


def test_a_failed_run_says_truthfully_whether_the_earlier_stage_is_as_it_was(shot,
                                                                             tmp_path):
    """The words after "nothing was stitched" come from the files the stage read before
    the run, compared with what is there after it: "is as it was" only when every one
    is in place and unchanged."""
    import shutil

    from crowd_addon.farm.cluster import _as_it_was, _stage_state
    tmp, _, whole = shot
    shutil.copytree(whole.parent, tmp_path / "w")
    out = tmp_path / "w" / "shot.usdc"
    before = _stage_state(str(out))
    assert len(before) > 5 and all(before.values())
    whole_now, words = _as_it_was(str(out), before)
    assert whole_now and f"{out} is as it was, with all {len(before)} files" in words
    blend = next(f for f in before if "/blends/" in f)
    Path(blend).unlink()
    whole_now, words = _as_it_was(str(out), before)
    assert not whole_now and "is not as it was" in words and "1 gone" in words
    assert "is as it was" not in words and "blends" in words
    assert _as_it_was(str(tmp_path / "none.usdc"), None) == (
        True, f"there was no stage at {tmp_path / 'none.usdc'}, and there is none")
