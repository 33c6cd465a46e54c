"""The demo's USD export runs in a process of its own beside the frames
(``crowd_addon.demo.run._UsdExport``): its stage is the one ``export_crowd`` writes in
this process (oracle: ``pxr`` reading both), and its failure reaches the user as the
export's own error, with nothing written."""

import sys
from pathlib import Path

import pytest

pxr = pytest.importorskip("pxr")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "usd"))
from conftest import make_config  # noqa: E402

from crowd_addon.core.shots.crowd import Crowd  # noqa: E402
from crowd_addon.core.base.errors import CrowdError  # noqa: E402
from crowd_addon.core.shots.recorder import record  # noqa: E402
from crowd_addon.core.variety.repetition import RepetitionSettings  # noqa: E402
from crowd_addon.demo.run import _UsdExport  # noqa: E402


@pytest.fixture(scope="module")
def shot():
    crowd = Crowd(make_config())
    return record(crowd, crowd.frame, crowd.frame + 7)


def test_the_export_beside_the_frames_writes_the_stage_this_process_would(shot, tmp_path):
    from crowd_addon.usd.export import export_crowd
    for d in "ab":
        (tmp_path / d).mkdir()
    beside = _UsdExport(shot, tmp_path / "a" / "crowd.usdc", None, RepetitionSettings(),
                        "instanced").result()
    here = export_crowd(shot, tmp_path / "b" / "crowd.usdc")
    assert beside["counts"]["agents"] == here.agents == shot.agent_count
    assert beside["bytes"] == sum(here.files.values())
    a = pxr.Usd.Stage.Open(beside["path"])
    b = pxr.Usd.Stage.Open(str(here.path))
    paths = [str(p.GetPath()) for p in a.Traverse()]
    assert paths == [str(p.GetPath()) for p in b.Traverse()] and len(paths) > shot.agent_count


def test_a_failed_export_beside_the_frames_is_named_and_writes_nothing(shot, tmp_path):
    bad = tmp_path / "crowd.txt"
    export = _UsdExport(shot, bad, None, RepetitionSettings(), "instanced")
    with pytest.raises(CrowdError, match=r"^USD export: .*crowd\.txt"):
        export.result()
    assert not export.running and list(tmp_path.iterdir()) == []


def test_an_export_stopped_beside_the_frames_leaves_nothing(tmp_path):
    """The demo failed or was interrupted while the export ran: stopping it removes what
    it had staged (its hidden layer folder), and writes no stage."""
    import time
    crowd = Crowd(make_config())
    long = record(crowd, crowd.frame, crowd.frame + 299)     # seconds of export to stop
    export = _UsdExport(long, tmp_path / "crowd.usdc", None, RepetitionSettings(),
                        "instanced")
    deadline = time.monotonic() + 60
    while not list(tmp_path.iterdir()) and time.monotonic() < deadline and export.running:
        time.sleep(0.01)                      # until the child has staged something
    export.stop()
    assert not export.running and list(tmp_path.iterdir()) == []
