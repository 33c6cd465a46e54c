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
    return set(re.findall(r"(?:done|failed) on \S+ pid (\d+)", log))


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

    def farm(name, *shots, code=0):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"shots": list(shots)}))
        got = main(["farm", str(path), "--scheduler", cluster.scheduler_address, "--json"])
        assert got == code, capsys.readouterr().err[-3000:]
        return json.loads(capsys.readouterr().out)["shots"]

    trusted = {"blend": "trusted.blend", "trust_scripts": True, "frames": "1-8",
               "out": "t/shot.usdc", "chunk_frames": 1}
    untrusted = {"blend": "untrusted.blend", "trust_scripts": False, "frames": "1-8",
                 "out": "u/shot.usdc", "chunk_frames": 2}
    first = farm("both", trusted, untrusted, code=3)   # the untrusted shot stops (issue 35)
    assert len(first[0]["chunk_exports"]) == 8
    assert first[1]["error"].startswith(f"{tmp_path / 'u' / 'shot.usdc'}: crowd script "
                                        "'show.py' did not run")
    assert not (tmp_path / "u" / "shot.usdc").exists()
    assert markers(marks, "trusted") == ["trusted.body", "trusted.register"]
    assert markers(marks, "untrusted") == []

    # the same workers again (both ran the trusted shot's script), the untrusted shot alone
    again = dict(untrusted, out="u2/shot.usdc")
    farm("again", again, code=3)
    assert workers(tmp_path / "t" / "shot.usdc") & workers(tmp_path / "u2" / "shot.usdc")
    assert markers(marks, "untrusted") == []
    # told to go on without it: exported, and the script still never ran
    (ignored,) = farm("ignored", dict(untrusted, trust_scripts=False, ignore_scripts=True,
                                      out="u3/shot.usdc"))
    assert len(ignored["chunk_exports"]) == 4 and markers(marks, "untrusted") == []


SHORT = PREPARE + """
bpy.context.scene.frame_start, bpy.context.scene.frame_end = 3, 8
bpy.ops.wm.save_mainfile()
"""


def test_export_on_workers_takes_the_blends_frames_and_refuses_its_untrusted_script(
        cluster, tmp_path, capsys):
    """Issue 35, item 6: ``crowd export --workers N --blend`` demanded ``--frames``
    though ``--help`` says the .blend gives them; and an untrusted crowd script was a
    warning with exit 0. Now the scene's frame range is the shot, and the script is
    checked in the command's own process before any task: exit code 3 and the reason,
    no chunk folder; ``--ignore-scripts`` exports without it."""
    marks = tmp_path / "marks"
    marks.mkdir()
    blend = tmp_path / "scripted.blend"
    run = subprocess.run([sys.executable, "-c", SHORT, str(marks), str(blend), "s"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    out = tmp_path / "farm" / "shot.usdc"
    base = ["export", "--blend", str(blend), "--out", str(out), "--scheduler",
            cluster.scheduler_address, "--json"]
    assert main(base) == 3
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("crowd export: error: crowd script 'show.py' did not run") and \
        "--ignore-scripts" in err
    assert not (tmp_path / "farm").exists() and markers(marks, "s") == []
    assert main(base + ["--ignore-scripts"]) == 0, capsys.readouterr().err[-3000:]
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == [3, 8] and markers(marks, "s") == []
