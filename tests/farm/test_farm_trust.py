"""``crowd farm``: a shot's ``trust_scripts`` holds for that shot only, in every worker
(issue 31). Two .blend shots on one ``LocalCluster`` of two worker processes: the
trusted shot's crowd script runs (its marker files are written), the shot marked
``trust_scripts: false`` never runs its script (module body or ``register``), not in
the same shot list and not in a later run on the same workers."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from dask.distributed import LocalCluster  # a missing Dask fails the run, never skips

from crowd_addon.cli import main

ROOT = Path(__file__).resolve().parents[2]

PREPARE = """
import sys, bpy
sys.path.insert(0, "tests/blender")
import crowd_addon, crowd_scene as cs
crowd_addon.register()
for path, tag in zip(sys.argv[2::2], sys.argv[3::2]):
    cs.scripted_blend(path, sys.argv[1], tag)
"""


@pytest.fixture(scope="module")
def cluster():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as c:
        yield c


def markers(folder, tag) -> list:
    return sorted(p.name for p in Path(folder).glob(f"{tag}.*"))


def workers(out) -> set:
    """The worker processes that ran a shot's tasks (its attempts log)."""
    log = (out.parent / f"{out.stem}.chunks" / "attempts.log").read_text()
    return set(re.findall(r"done on \S+ pid (\d+)", log))


def test_a_shot_marked_untrusted_never_runs_its_script_on_any_worker(cluster, tmp_path,
                                                                     capsys):
    marks = tmp_path / "marks"
    marks.mkdir()
    run = subprocess.run([sys.executable, "-c", PREPARE, str(marks),
                          str(tmp_path / "trusted.blend"), "trusted",
                          str(tmp_path / "untrusted.blend"), "untrusted"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert markers(marks, "*") == []

    def farm(name, *shots):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"shots": list(shots)}))
        code = main(["farm", str(path), "--scheduler", cluster.scheduler_address, "--json"])
        assert code == 0, capsys.readouterr().err[-3000:]
        return json.loads(capsys.readouterr().out)["shots"]

    trusted = {"blend": "trusted.blend", "trust_scripts": True, "frames": "1-8",
               "out": "t/shot.usdc", "chunk_frames": 1}
    untrusted = {"blend": "untrusted.blend", "trust_scripts": False, "frames": "1-8",
                 "out": "u/shot.usdc", "chunk_frames": 2}
    first = farm("both", trusted, untrusted)
    assert [len(s["chunk_exports"]) for s in first] == [8, 4]
    assert markers(marks, "trusted") == ["trusted.body", "trusted.register"]
    assert markers(marks, "untrusted") == []

    # the same workers again (both ran the trusted shot's script), the untrusted shot alone
    again = dict(untrusted, out="u2/shot.usdc")
    farm("again", again)
    assert workers(tmp_path / "t" / "shot.usdc") & workers(tmp_path / "u2" / "shot.usdc")
    assert markers(marks, "untrusted") == []
