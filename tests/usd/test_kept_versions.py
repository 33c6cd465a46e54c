"""Layer versions are immutable and kept while a stage reads them (usd/files.py,
usd/references.py; issue 31 item 2).

A stitched stage reads its chunks' character layers and blend banks where they are.
Re-exporting a chunk in place (a requeued farm job) writes a new version of the
chunk's layers; it used to delete the version the stitched stage reads, which still
opened, with only a USD warning, but whose agents on value clips read no animation for
that chunk's frames. The oracle is pxr: every asset of the stitched stage resolves
(``UsdUtils.ComputeAllDependencies``), and UsdSkel's joint and agent transforms of
every agent at every frame equal the single export of the whole range (1e-6)."""

import os

import numpy as np
from pxr import Sdf, UsdUtils

from crowd_addon.core import Crowd
from crowd_addon.core.shots.recorder import record
from crowd_addon.usd import export_crowd
from crowd_addon.usd.stitch import stitch

from .conftest import make_config, simulate
from .test_stitch import CHUNKS, export_chunks, read, sample_times


def versions(main):
    """The version folders beside the export ``main`` (``shot.layers/v1``, ...)."""
    root = f"{os.path.splitext(main)[0]}.layers"
    return sorted(n for n in os.listdir(root) if n.startswith("v"))


def unresolved(path):
    """The assets the stage at ``path`` names that do not resolve (pxr's own walk over
    its layers, references, sublayers and value clips)."""
    _, _, missing = UsdUtils.ComputeAllDependencies(str(path))
    return list(missing)


def same_as_whole(path, whole):
    times = sample_times(1)
    _, want = read(whole, times)
    _, got = read(path, times)
    assert sorted(got) == sorted(want)
    worst = max(max(float(np.abs(got[n][0] - want[n][0]).max()),
                    float(np.abs(got[n][1] - want[n][1]).max())) for n in want)
    assert worst < 1e-6, worst


def reexport(chunk, k):
    """Chunk ``k`` exported again to ``chunk`` (its frames simulated from the start: the
    same bytes as from its snapshot), as a requeued farm job does."""
    a, b = CHUNKS[k]
    return export_crowd(record(Crowd(make_config(), skinning="gpu"), a, b,
                               before_step=simulate), chunk)


def test_re_exporting_the_middle_chunk_in_place_keeps_the_stitched_stage_whole(tmp_path):
    whole, chunks = export_chunks(tmp_path)
    out = tmp_path / "stitched.usdc"
    stitch(chunks, out)
    assert unresolved(out) == []
    before = out.read_bytes()

    again = reexport(chunks[1], 1)                     # in place: a new version
    assert os.path.basename(again.layers_dir) == "v2"
    assert versions(chunks[1]) == ["v1", "v2"]         # v1: the stitched stage reads it
    assert out.read_bytes() == before
    assert unresolved(out) == []                       # every layer and clip resolves
    same_as_whole(out, whole.path)                     # every agent, every frame

    # stitched again, the stage reads v2; the next re-export frees v1 (nothing reads
    # it), keeps v2 (the stage reads it) and writes v3
    stitch(chunks, out)
    reexport(chunks[1], 1)
    assert versions(chunks[1]) == ["v2", "v3"]
    assert unresolved(out) == []
    same_as_whole(out, whole.path)
    # no stage reads the chunk's old versions any more: the next export collects them
    out.unlink()
    reexport(chunks[1], 1)
    assert versions(chunks[1]) == ["v4"]
    for other in (chunks[0], chunks[2]):               # never re-exported: untouched
        assert versions(other) == ["v1"]


def test_a_stage_beside_the_export_keeps_the_version_it_names(tmp_path):
    """A stage in the export's folder that names a version's layer directly (a
    hand-made review stage) keeps that version; an unreadable file there keeps
    nothing."""
    _, chunks = export_chunks(tmp_path)
    chunk = chunks[2]
    review = Sdf.Layer.CreateNew(str(chunk.parent / "review.usda"))
    review.subLayerPaths.append("./shot.layers/v1/agents.usdc")
    review.Save()
    (chunk.parent / "broken.usda").write_text("not usd at all")
    reexport(chunk, 2)
    assert versions(chunk) == ["v1", "v2"]
    os.unlink(chunk.parent / "review.usda")
    reexport(chunk, 2)
    assert versions(chunk) == ["v3"]


def test_only_version_folders_are_ever_removed(tmp_path):
    """Before: every entry of ``shot.layers/`` but the new version and the readers was
    removed, so notes or a folder a user kept there were deleted by the next export."""
    shot = tmp_path / "shot.usdc"
    crowd = Crowd(make_config(), skinning="gpu")
    rec = record(crowd, crowd.frame, crowd.frame + 3)
    export_crowd(rec, shot)
    layers = tmp_path / "shot.layers"
    (layers / "mine").mkdir()
    (layers / "mine" / "reference_photo.txt").write_text("user file")
    (layers / "NOTES.txt").write_text("user notes")
    (layers / "v").mkdir()                               # not a version's name
    export_crowd(rec, shot)
    assert sorted(os.listdir(layers)) == ["NOTES.txt", "mine", "v", "v2"]
    assert (layers / "mine" / "reference_photo.txt").read_text() == "user file"
