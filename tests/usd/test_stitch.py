"""Chunks stitched into one stage (usd/stitch.py, ``crowd stitch``). The oracle is the
single-process export of the whole range: pxr's UsdSkel joint transforms and the
agents' transforms of every agent at every sample time equal it (to 1e-6), and so do
the event tags of every stream animation. The chunks after the first are exported
animation-only, as a farm does, unless a test says otherwise."""

import json

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdSkel

from crowd_addon.cli import main
from crowd_addon.core import Crowd, CrowdError
from crowd_addon.core.shots.recorder import record
from crowd_addon.usd import export_crowd
from crowd_addon.usd.stitch import stitch

from .conftest import FIRST, LAST, MOVING, make_config, simulate

#: chunk ranges: blends, the queue, a cut and moves cross their boundaries
CHUNKS = ((FIRST, 5), (6, 10), (11, LAST))


def export_chunks(folder, substeps=1, fmt="usdc", animation_only=True, sim=simulate,
                  layout="instanced"):
    """The whole shot in one export, and in chunks each started from the snapshot
    before it (taken from one run, restored into a fresh crowd per chunk); the chunks
    after the first ``animation_only``; all in ``layout``."""
    crowd = Crowd(make_config(), skinning="gpu", substeps=substeps)
    snaps = {}
    while crowd.frame < LAST:
        if crowd.frame + 1 in [a for a, _ in CHUNKS]:
            snaps[crowd.frame + 1] = crowd.snapshot()
        sim(crowd, crowd.frame + 1)
        crowd.step()
    whole = export_crowd(record(Crowd(make_config(), skinning="gpu", substeps=substeps),
                                FIRST, LAST, before_step=sim), folder / f"whole.{fmt}",
                         layout=layout)
    paths = []
    for k, (a, b) in enumerate(CHUNKS):
        chunk = Crowd(make_config(), skinning="gpu", substeps=substeps)
        if snaps[a].frame > chunk.frame:
            chunk.restore(snaps[a])
        path = folder / "chunks" / f"c{k}" / f"shot.{fmt}"
        path.parent.mkdir(parents=True)
        export_crowd(record(chunk, a, b, before_step=sim), path, layout=layout,
                     animation_only=animation_only and k > 0)
        paths.append(path)
    return whole, paths


def sample_times(substeps):
    return [f + k / substeps for f in range(FIRST, LAST + 1) for k in range(substeps)]


def read(path, times):
    """Per agent name: (joint local transforms (T, J, 4, 4), local-to-world (T, 4, 4))."""
    stage = Usd.Stage.Open(str(path))
    cache, pred = UsdSkel.Cache(), Usd.TraverseInstanceProxies()
    out = {}
    for prim in stage.GetPrimAtPath("/Crowd/Agents").GetChildren():
        root = UsdSkel.Root(prim)
        assert cache.Populate(root, pred)
        (binding,) = cache.ComputeSkelBindings(root, pred)
        query = cache.GetSkelQuery(binding.GetSkeleton())
        xf = UsdGeom.Xformable(prim)
        out[prim.GetName()] = (
            np.array([np.array(query.ComputeJointLocalTransforms(t)) for t in times]),
            np.array([np.array(xf.ComputeLocalToWorldTransform(t)) for t in times]))
    return stage, out


def stream_events(stage):
    out = {}
    for prim in stage.Traverse():
        if prim.GetPath().pathString.startswith("/Crowd/Streams/"):
            crowd = prim.GetCustomDataByKey("crowd") or {}
            out[prim.GetPath().pathString] = (list(crowd.get("eventNames", [])),
                                              list(crowd.get("eventFrames", [])))
    return out


@pytest.mark.parametrize("substeps, fmt, animation_only",
                         [(1, "usdc", True), (2, "usda", True), (1, "usdc", False)])
def test_stitched_chunks_read_back_as_the_whole_export(tmp_path, substeps, fmt,
                                                       animation_only):
    whole, chunks = export_chunks(tmp_path, substeps, fmt, animation_only)
    result = stitch(list(reversed(chunks)), tmp_path / f"stitched.{fmt}")
    assert result.frames == (FIRST, LAST) and result.chunks == [str(p) for p in chunks]
    assert result.agents == whole.agents and result.moving_agents == whole.moving_agents
    assert result.shared_agents <= whole.shared_agents and result.clip_agents > 0
    times = sample_times(substeps)
    want_stage, want = read(whole.path, times)
    got_stage, got = read(result.path, times)
    assert sorted(got) == sorted(want)
    worst = 0.0
    for name, (joints, world) in want.items():
        worst = max(worst, float(np.abs(got[name][0] - joints).max()),
                    float(np.abs(got[name][1] - world).max()))
    assert worst < 1e-6, worst
    assert stream_events(got_stage) == stream_events(want_stage)
    info = got_stage.GetRootLayer().customLayerData["crowd"]
    assert (info["firstFrame"], info["lastFrame"], info["substeps"]) == (FIRST, LAST, substeps)
    assert (got_stage.GetStartTimeCode(), got_stage.GetEndTimeCode()) == \
        (want_stage.GetStartTimeCode(), want_stage.GetEndTimeCode())


def test_the_stitched_stage_moves_with_its_chunks(tmp_path):
    """Relative paths: the stitched shot and its chunks can move together."""
    import shutil
    (tmp_path / "a").mkdir()
    whole, chunks = export_chunks(tmp_path / "a")
    stitch(chunks, tmp_path / "a" / "stitched.usdc")
    shutil.move(str(tmp_path / "a"), str(tmp_path / "b"))
    times = sample_times(1)
    _, want = read(tmp_path / "b" / "whole.usdc", times)
    _, got = read(tmp_path / "b" / "stitched.usdc", times)
    for name in want:
        np.testing.assert_allclose(got[name][0], want[name][0], atol=1e-6)


def test_an_agent_placed_on_a_chunks_first_frame_moves_in_the_stitched_stage(tmp_path):
    """Agent 10 is put elsewhere just before the last chunk's first frame: it stands
    still in every chunk, yet not in the shot. Before the per-agent places were
    recorded, the stitch kept it where the first chunk had it."""
    def sim(crowd, frame):
        simulate(crowd, frame)
        if frame == CHUNKS[2][0]:
            crowd.place_agents([10], position=crowd.view.agents.position[10] + (2.0, 0, 0),
                               heading=crowd.view.agents.heading[10] + 1.0)
    whole, chunks = export_chunks(tmp_path, sim=sim)
    result = stitch(chunks, tmp_path / "stitched.usdc")
    assert result.moving_agents == whole.moving_agents == len(MOVING) + 1
    times = sample_times(1)
    _, want = read(whole.path, times)
    _, got = read(result.path, times)
    np.testing.assert_allclose(got["agent_10"][1], want["agent_10"][1], atol=1e-6)
    assert np.abs(want["agent_10"][1][0] - want["agent_10"][1][-1]).max() > 1.0


def test_the_first_chunk_must_hold_the_agents(tmp_path):
    """Only the first chunk's agents are read; a shot whose first chunk was exported
    animation-only is refused by name, and nothing is written."""
    _, chunks = export_chunks(tmp_path)
    stitched = stitch(chunks, tmp_path / "stitched.usdc").path
    with pytest.raises(CrowdError, match="a stitched stage, not a chunk"):
        stitch([stitched], tmp_path / "twice.usdc")
    stages = set()
    again = export_crowd(record(Crowd(make_config(), skinning="gpu"), FIRST, CHUNKS[0][1],
                                before_step=simulate), chunks[0], animation_only=True,
                         progress=lambda stage, done, total: stages.add(stage))
    assert "streams" in stages and not {"layout", "characters"} & stages
    out = tmp_path / "again.usdc"
    with pytest.raises(CrowdError, match="first chunk and holds no agents"):
        stitch(chunks, out)
    assert again.characters == 0 and not out.exists()
    assert not (tmp_path / "twice.usdc").exists()


def test_bad_chunk_sets_are_named_and_nothing_is_written(tmp_path):
    whole, chunks = export_chunks(tmp_path)
    out = tmp_path / "stitched.usdc"
    with pytest.raises(CrowdError, match="leave a gap"):
        stitch([chunks[0], chunks[2]], out)
    with pytest.raises(CrowdError, match="overlap"):
        stitch([chunks[0], whole.path], out)
    other = make_config()
    other.agent_position[0] += 1.0                # the same settings, another crowd
    lone = export_crowd(record(Crowd(other, skinning="gpu"), 6, 10), tmp_path / "other.usdc")
    with pytest.raises(CrowdError, match="configDigest"):
        stitch([chunks[0], lone.path, chunks[2]], out)
    (tmp_path / "text.usda").write_text("#usda 1.0\n")
    with pytest.raises(CrowdError, match="not a crowd export"):
        stitch([tmp_path / "text.usda"], out)
    with pytest.raises(CrowdError, match="no such chunk"):
        stitch([tmp_path / "nope.usdc"], out)
    with pytest.raises(CrowdError, match="no chunks"):
        stitch([], out)
    with pytest.raises(CrowdError, match="is one of the chunks"):
        stitch(chunks, chunks[1])
    assert not out.exists() and not (tmp_path / "stitched.layers").exists()


def test_crowd_stitch_command(tmp_path, capsys):
    _, chunks = export_chunks(tmp_path)
    out = tmp_path / "shot.usdc"
    assert main(["stitch", "--out", str(out), *map(str, chunks), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == [FIRST, LAST] and summary["path"] == str(out)
    assert main(["stitch", "--out", str(out), str(chunks[0]), str(chunks[2])]) == 2
    assert "crowd stitch: error:" in capsys.readouterr().err


def test_crowd_stitch_creates_its_folder_and_removes_it_when_it_fails(tmp_path, capsys):
    """Issue 35, item 6: ``crowd stitch --out new/shot.usdc`` failed on the missing
    folder that ``crowd export`` creates. Now it is created, and gone again (with every
    folder it made) when the stitch fails."""
    _, chunks = export_chunks(tmp_path)
    out = tmp_path / "stitched" / "final" / "shot.usdc"
    assert main(["stitch", "--out", str(out), str(chunks[0]), str(chunks[2])]) == 2
    assert "crowd stitch: error:" in capsys.readouterr().err
    assert not (tmp_path / "stitched").exists()
    assert main(["stitch", "--out", str(out), *map(str, chunks), "--json"]) == 0, \
        capsys.readouterr().err
    assert json.loads(capsys.readouterr().out)["frames"] == [FIRST, LAST]
    assert len(read(out, [FIRST, LAST])[1]) == len(read(chunks[0], [FIRST])[1])


def test_the_stitch_reads_what_each_chunk_records_per_agent(tmp_path):
    """Each export records per agent the stream and offset it plays the whole shot
    (-1 where it changes) and whether it moves; the stitch finds its shared agents from
    them (no agent read one by one) and records the same for the whole shot as the
    single export does. A chunk without them is refused by name."""
    from pxr import Sdf
    whole, chunks = export_chunks(tmp_path)
    result = stitch(chunks, tmp_path / "stitched.usdc")

    def arrays(path):
        crowd = Sdf.Layer.FindOrOpen(str(path)).customLayerData["crowd"]
        return {k: np.array(crowd[k]) for k in ("agentStream", "agentOffset", "agentMoves",
                                                "agentPosition", "agentHeading")}
    want, got = arrays(whole.path), arrays(result.path)
    for k in want:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    # the repetition metric: measured by the first chunk only (the others are
    # animation-only), and the stitched shot's is the first chunk's
    settings = [dict(Sdf.Layer.FindOrOpen(str(p)).customLayerData["crowd"])
                for p in (*chunks, result.path)]
    assert [("repetition" in c) for c in settings] == [True, False, False, True]
    assert settings[3]["repetition"] == settings[0]["repetition"]
    assert (want["agentStream"] >= 0).sum() == result.shared_agents > 0
    assert result.clip_agents == (want["agentStream"] < 0).sum() > 0
    assert result.moving_agents == want["agentMoves"].sum() > 0
    # a chunk written before the arrays were recorded
    layer = Sdf.Layer.FindOrOpen(str(chunks[1]))
    data = dict(layer.customLayerData)
    crowd = dict(data["crowd"])
    del crowd["agentMoves"]
    data["crowd"] = crowd
    layer.customLayerData = data
    layer.Save()
    with pytest.raises(CrowdError, match="lack \\['agentMoves'\\].*export the chunk again"):
        stitch(chunks, tmp_path / "again.usdc")
