"""The demo's USD export runs in a process of its own beside the frames
(``crowd_addon.demo.usd_beside.UsdExport``): its stage is the one ``export_crowd``
writes in this process (oracle: ``pxr`` reading both), put in place only when the demo
says so; its failure reaches the user as the export's own error, with nothing written,
and it stops when the demo is gone."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

pxr = pytest.importorskip("pxr")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "usd"))
from conftest import make_config  # noqa: E402

from crowd_addon.core.shots.crowd import Crowd  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.core.shots.recorder import record  # noqa: E402
from crowd_addon.core.variety.repetition import RepetitionSettings  # noqa: E402
from crowd_addon.demo.usd_beside import UsdExport  # noqa: E402


@pytest.fixture(scope="module")
def shot():
    crowd = Crowd(make_config())
    return record(crowd, crowd.frame, crowd.frame + 7)


def test_the_export_beside_the_frames_writes_the_stage_this_process_would(shot, tmp_path):
    from crowd_addon.usd.export import export_crowd
    for d in "ab":
        (tmp_path / d).mkdir()
    export = UsdExport(shot, tmp_path / "a" / "crowd.usdc", None, RepetitionSettings(),
                       "instanced")
    export.written()
    assert not (tmp_path / "a" / "crowd.usdc").exists()      # written, not yet in place
    beside = export.commit()
    here = export_crowd(shot, tmp_path / "b" / "crowd.usdc")
    assert beside["counts"]["agents"] == here.agents == shot.agent_count
    assert beside["bytes"] == sum(here.files.values())
    a = pxr.Usd.Stage.Open(beside["path"])
    b = pxr.Usd.Stage.Open(str(here.path))
    paths = [str(p.GetPath()) for p in a.Traverse()]
    assert paths == [str(p.GetPath()) for p in b.Traverse()] and len(paths) > shot.agent_count


def test_a_failed_export_beside_the_frames_is_named_and_writes_nothing(shot, tmp_path):
    bad = tmp_path / "crowd.txt"
    export = UsdExport(shot, bad, None, RepetitionSettings(), "instanced")
    with pytest.raises(CrowdError, match=r"^USD export: .*crowd\.txt"):
        export.written()
    assert not export.running and list(tmp_path.iterdir()) == []


def test_an_export_stopped_beside_the_frames_leaves_nothing(tmp_path):
    """The demo failed or was interrupted while the export ran: stopping it removes what
    it had staged (its hidden layer folder), and writes no stage."""
    crowd = Crowd(make_config())
    long = record(crowd, crowd.frame, crowd.frame + 299)     # seconds of export to stop
    export = UsdExport(long, tmp_path / "crowd.usdc", None, RepetitionSettings(),
                        "instanced")
    deadline = time.monotonic() + 60
    while not list(tmp_path.iterdir()) and time.monotonic() < deadline and export.running:
        time.sleep(0.01)                      # until the child has staged something
    export.stop()
    assert not export.running and list(tmp_path.iterdir()) == []


def test_an_export_written_but_not_committed_leaves_the_earlier_stage(shot, tmp_path):
    """The demo failed after the export had written everything: the stage an earlier
    run left is as it was (before, the export put its stage in place the moment it was
    done, whatever became of the run)."""
    from crowd_addon.usd.export import export_crowd
    earlier = export_crowd(shot, tmp_path / "crowd.usdc", agents=3)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    export = UsdExport(shot, tmp_path / "crowd.usdc", None, RepetitionSettings(), "instanced")
    export.written()
    export.stop()
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before
    assert pxr.Usd.Stage.Open(str(earlier.path)).GetPrimAtPath("/Crowd")


ORPHAN = """
import os, sys, time
sys.path.insert(0, sys.argv[2])
from conftest import make_config
from crowd_addon.core.shots.crowd import Crowd
from crowd_addon.core.shots.recorder import record
from crowd_addon.core.variety.repetition import RepetitionSettings
from crowd_addon.demo.usd_beside import UsdExport
crowd = Crowd(make_config())
shot = record(crowd, crowd.frame, crowd.frame + 599)
export = UsdExport(shot, os.path.join(sys.argv[1], "crowd.usdc"), None,
                   RepetitionSettings(), "instanced")
print(export._proc.pid, flush=True)
while not [n for n in os.listdir(sys.argv[1]) if n.endswith(".tmp")]:
    time.sleep(0.01)
os.kill(os.getpid(), 9)        # the demo killed outright: no clean-up of its own
"""


def test_an_export_whose_demo_was_killed_stops_and_removes_its_staging(tmp_path):
    run = subprocess.run([sys.executable, "-c", ORPHAN, str(tmp_path),
                          str(Path(__file__).resolve().parents[1] / "usd")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == -9, run.stderr[-2000:]
    child = int(run.stdout.split()[0])
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and _alive(child):
        time.sleep(0.1)
    assert not _alive(child), "the export went on for a demo that was gone"
    assert list(tmp_path.iterdir()) == []


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:          # a zombie has ended
        return f.read().split(")")[-1].split()[0] != "Z"
