"""Dask's failures end in the project's error (issue 31, item 3): ``crowd farm`` and
``crowd export --workers`` exit 2 with one ``crowd <command>: error: ...`` line naming
what failed, and Dask's traceback goes only to the shot's ``attempts.log``, never to
the terminal (stderr is captured at the file descriptor, so the worker processes'
output counts too)."""

import json
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
        {"config": "missing.json", "frames": "1-10", "out": "c/shot.usdc"}]}))
    assert main(["farm", str(shots), "--workers", "1"]) == 2
    line = only_our_error(capfd.readouterr().err, "farm")
    assert "c/shot.usdc: the snapshot pass failed twice" in line
    assert "missing.json: no such file" in line
    log = (Path(chunk_folder(tmp_path / "c" / "shot.usdc")) / "attempts.log").read_text()
    assert log.count("snapshots: failed on") == 2
    assert "Traceback" in log and "missing.json: no such file" in log
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
