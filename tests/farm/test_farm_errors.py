"""Dask's failures end in the project's error (issue 31, item 3): ``crowd farm`` and
``crowd export --workers`` exit 2 with one ``crowd <command>: error: ...`` line naming
what failed, and Dask's traceback goes only to the shot's ``attempts.log``, never to
the terminal (stderr is captured at the file descriptor, so the worker processes'
output counts too)."""

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from dask.distributed import LocalCluster  # noqa: F401 - a missing Dask fails the run

from crowd_addon.cli import main
from crowd_addon.core.authoring.config_io import save_config
from crowd_addon.farm.chunks import chunk_folder

from .test_dask_export import show_config

#: what Dask prints when it reports an error itself
DASK_NOISE = ("Traceback", "distributed.", "Compute Failed", "Nanny failed")


def only_our_error(err: str, command: str) -> str:
    """The named error line of ``err`` (stderr), checking nothing else but progress
    lines was printed; returns it."""
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert lines, err
    others = [line for line in lines[:-1] if not line.startswith(f"crowd {command}: ")]
    assert not others, err
    assert lines[-1].startswith(f"crowd {command}: error: "), err
    for word in DASK_NOISE[:3]:
        assert word not in err, err
    return lines[-1]


@pytest.fixture(scope="module")
def config(tmp_path_factory):
    path = tmp_path_factory.mktemp("farm_errors") / "crowd.json"
    save_config(show_config(), path)
    return path


def test_a_failing_shot_prints_its_named_error_and_no_dask_traceback(config, tmp_path,
                                                                     capfd):
    # regression: the workers printed Dask's "Compute Failed" traceback before the error
    shots = tmp_path / "shots.json"
    shots.write_text(json.dumps({"shots": [
        {"config": str(config), "frames": "1-10", "out": "c/shot.usdc"}]}))
    chunks = Path(chunk_folder(tmp_path / "c" / "shot.usdc"))
    chunks.mkdir(parents=True)
    (chunks / "snapshots").write_text("in the way of the snapshot folder")
    assert main(["farm", str(shots), "--workers", "1"]) == 2
    line = only_our_error(capfd.readouterr().err, "farm")
    assert "c/shot.usdc: the snapshot pass failed twice" in line
    assert "snapshots: cannot create it" in line
    log = (chunks / "attempts.log").read_text()
    assert log.count("snapshots: failed on") == 2
    assert "Traceback" in log and "snapshots: cannot create it" in log
    assert not (tmp_path / "c" / "shot.usdc").exists()


def workers_killed_at_start(tmp_path):
    """Every Dask worker process kills itself (SIGKILL) as it starts: a preload script,
    which Dask's configuration hands to each worker the cluster spawns."""
    import dask
    die = tmp_path / "die.py"
    die.write_text("import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n")
    return dask.config.set({"distributed.worker.preload": [str(die)]})


@pytest.mark.parametrize("command", ["farm", "export"])
def test_workers_killed_while_the_cluster_starts_are_named(config, tmp_path, capfd,
                                                           command):
    # regression: RuntimeError: Nanny failed to start, a raw traceback
    out = tmp_path / "a" / "shot.usdc"
    if command == "farm":
        shots = tmp_path / "shots.json"
        shots.write_text(json.dumps({"shots": [
            {"config": str(config), "frames": "1-10", "out": "a/shot.usdc"}]}))
        argv = ["farm", str(shots), "--workers", "1"]
    else:
        argv = ["export", "--config", str(config), "--frames", "1-10", "--out", str(out),
                "--workers", "1"]
    with workers_killed_at_start(tmp_path):
        code = main(argv)
    assert code == 2
    line = only_our_error(capfd.readouterr().err, command)
    assert "the local Dask cluster of 1 worker did not start" in line, line
    assert "RuntimeError: Nanny failed to start" in line and "attempts.log" in line
    log = (Path(chunk_folder(out)) / "attempts.log").read_text()
    assert "cluster: the local Dask cluster of 1 worker did not start" in log
    assert "Traceback" in log and "Nanny failed to start" in log
    assert not out.exists()


def test_a_closed_cluster_is_not_kept_alive(config, tmp_path):
    """Farm exports one after another in one process (a Blender session) kept every
    scheduler they started alive, with its tasks, through Dask's unbounded memo of
    handler signatures (distributed.core._expects_comm): memory grew about 0.15 MB an
    export (issue 31, item 6; ``benchmarks/export_memory.py --workers 1``)."""
    import gc

    from distributed import Scheduler
    from distributed.core import Status

    def closed_schedulers():
        gc.collect()
        return [o for o in gc.get_objects()
                if isinstance(o, Scheduler) and o.status == Status.closed]
    before = len(closed_schedulers())
    for k in range(2):
        assert main(["export", "--config", str(config), "--frames", "1-10", "--out",
                     str(tmp_path / f"s{k}" / "shot.usdc"), "--workers", "1"]) == 0
    assert len(closed_schedulers()) <= before


def listing(folder) -> list:
    """Every file and folder under ``folder``, relative to it (hidden ones too)."""
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*"))


def test_a_bad_output_is_refused_before_the_cluster_starts(config, tmp_path, capfd,
                                                           monkeypatch):
    """With --workers the output was not checked: an output under a file was a
    NotADirectoryError traceback, ``--out .`` wrote ``../<folder>.chunks/`` and blamed
    "a stage appeared", and too many agents, a wrong extension or frames before the
    crowd's start ran the snapshot pass and every chunk twice, leaving their files.
    Now each is the single-process export's own error, exit 2, and nothing is
    written."""
    from crowd_addon.core.authoring.config_io import load_config
    start = load_config(config).start_frame
    (tmp_path / "afile").write_text("a file, not a folder")
    (tmp_path / "w").mkdir()
    before = listing(tmp_path)
    frames = ["--frames", f"{start}-{start + 9}"]
    for cwd, extra, wrong in [
            ("", ["--out", "afile/shot.usdc"], "afile: cannot create it"),
            ("w", ["--out", "."], "the output needs a name ending in .usdc"),
            ("", ["--out", "n1/shot.usdc", "--agents", "1000"], "1000 agents requested"),
            ("", ["--out", "n2/shot.txt"], "the output needs a name ending in .usdc"),
            ("", ["--out", "n3/shot.usdc", f"--frames={start - 5}-{start + 9}"],
             f"starts before the crowd's start frame {start}")]:
        monkeypatch.chdir(tmp_path / cwd)
        args = ["export", "--config", str(config), *frames, *extra]
        assert main(args) == 2                              # one process: the reference
        alone = capfd.readouterr().err.strip().splitlines()[-1]
        assert wrong in alone, alone
        assert main(args + ["--workers", "2"]) == 2
        assert only_our_error(capfd.readouterr().err, "export") == alone   # the same error
        assert listing(tmp_path) == before, extra           # nothing written


def test_a_bad_shot_of_a_shot_list_is_named_before_anything_runs(config, tmp_path, capfd):
    """Each shot is checked as crowd export checks its output when the list is loaded:
    the bad one is named (its index and out), exit 2, and no shot's folder is made,
    not even the good shot's before it."""
    from crowd_addon.core.authoring.config_io import load_config
    start = load_config(config).start_frame
    good = {"config": str(config), "frames": f"{start}-{start + 9}", "out": "ok/shot.usdc"}
    (tmp_path / "afile").write_text("a file, not a folder")
    shots = tmp_path / "shots.json"
    for bad, wrong in [({"out": "afile/shot.usdc"}, "afile: cannot create it"),
                       ({"out": ""}, "the output needs a name ending in .usdc"),
                       ({"agents": 1000}, "1000 agents requested but the crowd has"),
                       ({"out": "b/shot.txt"}, "the output needs a name ending in .usdc"),
                       ({"frames": f"{start - 5}-{start + 9}"},
                        f"starts before the crowd's start frame {start}")]:
        shot = {**good, "out": "b/shot.usdc", **bad}
        shots.write_text(json.dumps({"shots": [good, shot]}))
        before = listing(tmp_path)
        assert main(["farm", str(shots), "--workers", "2"]) == 2
        line = only_our_error(capfd.readouterr().err, "farm")
        assert f"{shots}: shot 1 ('out' {shot['out']!r}): " in line and wrong in line, line
        assert listing(tmp_path) == before, bad


def test_outputs_that_differ_only_by_extension_are_refused(config, tmp_path, capfd):
    """``s/shot.usdc`` and ``s/shot.usda`` would both write ``s/shot.layers`` and
    ``s/shot.chunks``: the second shot's stitch failed ("another export wrote
    .../shot.layers/v5 meanwhile"). Both shots are named; nothing runs."""
    shots = tmp_path / "shots.json"
    shot = {"config": str(config), "frames": "1-10"}
    shots.write_text(json.dumps({"shots": [dict(shot, out="s/shot.usdc"),
                                           dict(shot, out="t/other.usdc"),
                                           dict(shot, out="s/shot.usda")]}))
    assert main(["farm", str(shots), "--workers", "2"]) == 2
    line = only_our_error(capfd.readouterr().err, "farm")
    assert (f"{shots}: shot 2: 'out' 's/shot.usda' and shot 0's 's/shot.usdc' differ only "
            "by extension: both would write shot.layers/ and shot.chunks/") in line, line
    assert listing(tmp_path) == ["shots.json"]


#: a worker preload: every export of the workers waits at its commit, its temporary
#: folder full (usd/files.py ``_step("start")``), until the worker is killed
STALL = """
import time
from crowd_addon.usd import files
files._step = lambda name: time.sleep(600) if name == "start" else None
"""


def test_sigterm_leaves_no_temporary_of_a_killed_worker(config, tmp_path):
    """SIGTERM (or Ctrl-C) closes the cluster, killing its workers mid-export; the
    hidden temporary folder of each chunk export they were writing stayed behind
    (``c0000_1-5/.shot.usdc.XXXX.tmp``). Now the run removes them once the workers are
    gone, and leaves no worker process."""
    import psutil
    root = Path(__file__).resolve().parents[2]
    stall = tmp_path / "stall.py"
    stall.write_text(STALL)
    out = tmp_path / "f" / "shot.usdc"
    env = dict(os.environ, PYTHONPATH=str(root),
               DASK_DISTRIBUTED__WORKER__PRELOAD=json.dumps([str(stall)]))
    proc = subprocess.Popen([sys.executable, "-m", "crowd_addon", "export", "--workers",
                             "2", "--config", str(config), "--out", str(out), "--frames",
                             "1-10", "--chunk-frames", "5"], cwd=root, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    children = []
    try:
        deadline = time.monotonic() + 240
        while not list(Path(chunk_folder(out)).glob("c*/.shot.usdc.*.tmp")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk export started"
            time.sleep(0.2)
        children = psutil.Process(proc.pid).children(recursive=True)
        assert children
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        for p in [proc, *children]:          # only when the test failed: none is left
            with contextlib.suppress(Exception):
                p.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "crowd export: stopped by SIGTERM" in err
    assert [p for p in listing(tmp_path / "f") if p.endswith(".tmp")] == []
    _, alive = psutil.wait_procs(children, timeout=10)
    assert alive == []
