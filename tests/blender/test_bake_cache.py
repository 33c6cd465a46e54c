"""A .blend's bake kept in its snapshot folder (crowd_addon/blender/bake_cache.py): the
snapshot pass keeps it, a chunk of the same .blend reads it instead of baking, and
anything that changed or does not check out makes the chunk bake again.

Oracle: the configuration baked from the scene (its digest, as snapshots name their
crowd) and its bake report; a chunk's export from the kept bake equals the export
that baked.
"""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, str(Path(__file__).resolve().parent))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import scene_config  # noqa: E402
from crowd_addon.core.authoring.config_io import config_digest  # noqa: E402
from crowd_addon.core.bake.bake_report import BakeWarnings  # noqa: E402
from crowd_addon.farm.chunks import export_chunk, write_shot_snapshots  # noqa: E402
from crowd_addon.shot_source import ShotSource  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))       # tests/: the usd tests
from usd.test_stitch import read  # noqa: E402

extension = cs.extension_fixture()


def saved_crowd(path, seed=3):
    """The walking crowd with a Bezier action keyed 12 frames apart (its poses between
    frames miss the curves: the bake reports a warning), saved as ``path``."""
    scene = cs.walking_crowd()[0]
    scene.crowd.seed = seed
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def refuse_to_bake(monkeypatch):
    """From here baking the scene fails the test: what runs read a kept bake."""
    def refuse(*_a, **_k):
        pytest.fail("the scene was baked")
    monkeypatch.setattr(scene_config, "config_from_scene", refuse)


def baked(blend, **kw):
    return ShotSource(blend=str(blend)).open((1, 8), **kw).config


def test_a_kept_bake_is_read_instead_of_baking_with_its_report(tmp_path, monkeypatch):
    blend = saved_crowd(tmp_path / "crowd.blend")
    folder = tmp_path / "snaps"
    folder.mkdir()
    want = baked(blend, keep_bake=folder)
    assert want.bake_report.warnings                # the between-frame check's
    kept = sorted(p.name for p in folder.iterdir())
    assert [p for p in kept if not p.endswith((".json", ".npz"))] == []
    assert len(kept) == 3                           # configuration, arrays, key
    refuse_to_bake(monkeypatch)
    said = []
    got = ShotSource(blend=str(blend)).open(
        (1, 8), lambda _d, _t, line: said.append(line), reuse_bake=folder).config
    assert said[0].startswith(f"the bake kept in {folder} by its snapshot pass")
    assert said[1:] == [n.line for n in want.bake_report]       # the notes, as baked
    assert config_digest(got) == config_digest(want)
    assert [(str(n), n.kind, n.severity) for n in got.bake_report] == \
        [(str(n), n.kind, n.severity) for n in want.bake_report]
    with pytest.raises(BakeWarnings):               # --strict as after a bake
        ShotSource(blend=str(blend), strict=True).open((1, 8), reuse_bake=folder).config


@pytest.mark.parametrize("spoil", ["changed blend", "damaged arrays", "other digest",
                                   "no key file"])
def test_a_bake_that_does_not_check_out_is_baked_again(tmp_path, monkeypatch, spoil):
    blend = saved_crowd(tmp_path / "crowd.blend")
    folder = tmp_path / "snaps"
    folder.mkdir()
    baked(blend, keep_bake=folder)
    key_file = next(folder.glob("baked_*.key.json"))
    if spoil == "changed blend":
        saved_crowd(blend, seed=4)
    elif spoil == "damaged arrays":
        next(folder.glob("baked_*.npz")).write_bytes(b"not an npz")
    elif spoil == "other digest":
        record = json.loads(key_file.read_text())
        record["digest"] = "0" * 64
        key_file.write_text(json.dumps(record))
    else:
        key_file.unlink()
    baked_again = []
    monkeypatch.setattr(scene_config, "config_from_scene", lambda *a: baked_again.append(
        1) or _real_config_from_scene(*a))
    baked(blend, reuse_bake=folder)
    assert baked_again == [1]


_real_config_from_scene = scene_config.config_from_scene


def test_a_chunk_from_the_kept_bake_equals_the_chunk_that_baked(tmp_path, monkeypatch):
    """``crowd snapshot`` keeps the bake; ``crowd export --snapshots`` of a later
    chunk reads it (no bake) and writes the stage the baking export writes."""
    blend = saved_crowd(tmp_path / "crowd.blend")
    source, folder = ShotSource(blend=str(blend)), tmp_path / "snaps"
    write_shot_snapshots(source, folder, (1, 12), 6)
    assert list(folder.glob("baked_*.key.json"))
    _, want = export_chunk(source, (7, 12), tmp_path / "baking" / "shot.usdc")
    refuse_to_bake(monkeypatch)
    _, got = export_chunk(source, (7, 12), tmp_path / "kept" / "shot.usdc", str(folder))
    assert got.started_from == 6
    times = list(range(7, 13))
    _, a = read(want.path, times)
    _, b = read(got.path, times)
    assert a.keys() == b.keys() and len(a) == 30
    assert max(float(np.abs(a[k][0] - b[k][0]).max()) for k in a) < 1e-6


def test_the_blend_open_in_a_session_is_baked_as_it_is(tmp_path, monkeypatch):
    """The scene already open (no --blend) may hold changes not saved: its bake is
    neither kept nor read, since the file's bytes are not what is baked."""
    blend = saved_crowd(tmp_path / "crowd.blend")
    folder = tmp_path / "snaps"
    folder.mkdir()
    baked(blend, keep_bake=folder)
    bpy.context.scene.crowd.seed = 9                # open, changed, not saved
    shot = ShotSource().open((1, 8), reuse_bake=folder, keep_bake=folder)
    monkeypatch.setattr(scene_config, "config_from_scene", lambda *a: "baked")
    assert shot.config == "baked"


def test_a_new_bake_of_a_changed_blend_replaces_its_older_one(tmp_path):
    """The snapshot pass of a .blend saved again keeps the new bake and removes the
    older one of the same file and scene; another .blend's bake in the folder stays."""
    blend, other = saved_crowd(tmp_path / "crowd.blend"), tmp_path / "other.blend"
    folder = tmp_path / "snaps"
    folder.mkdir()
    baked(saved_crowd(other), keep_bake=folder)
    baked(blend, keep_bake=folder)
    kept = sorted(p.name for p in folder.glob("baked_*"))
    assert len(kept) == 6
    saved_crowd(blend, seed=4)
    want = baked(blend, keep_bake=folder)
    now = sorted(p.name for p in folder.glob("baked_*"))
    assert len(now) == 6 and now != kept            # one replaced, the other's kept
    assert config_digest(baked(blend, reuse_bake=folder)) == config_digest(want)
    assert len(set(now) & set(kept)) == 3
