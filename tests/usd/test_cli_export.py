"""``crowd export`` from a saved configuration: progress on stderr, a summary, exit
code 2 and ``crowd export: error: ...`` on bad input, nothing written then."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from pxr import Gf, Usd, UsdSkel

from crowd_addon.cli import main
from crowd_addon.core.authoring.config_io import save_config

from .conftest import FAN_AGENTS, KID_AGENTS, make_config

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def config_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("config") / "crowd.json"
    save_config(make_config(), path)
    return path


def test_export_prints_progress_and_summary(config_path, tmp_path, capsys):
    out = tmp_path / "shot.usdc"
    assert main(["export", "--config", str(config_path), "--out", str(out),
                 "--frames", "0-12"]) == 0
    captured = capsys.readouterr()
    assert "crowd export: simulate 12/12" in captured.err
    assert "crowd export: streams 4/4" in captured.err
    assert f"wrote {out}" in captured.out
    assert f"{FAN_AGENTS + KID_AGENTS} agents" in captured.out
    stage = Usd.Stage.Open(str(out))
    agents = stage.GetPrimAtPath("/Crowd/Agents").GetChildren()
    assert len(agents) == FAN_AGENTS + KID_AGENTS
    assert all(UsdSkel.Root(p) and p.IsInstance() for p in agents)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 12)


def test_first_n_agents_as_json(config_path, tmp_path, capsys):
    out = tmp_path / "shot.usda"
    assert main(["export", "--config", str(config_path), "--out", str(out),
                 "--frames", "3", "--agents", "5", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["agents"] == 5 and summary["frames"] == [3, 3]
    assert summary["bytes"] == sum(summary["files"].values())
    stage = Usd.Stage.Open(str(out))
    names = [p.GetName() for p in stage.GetPrimAtPath("/Crowd/Agents").GetChildren()]
    assert names == [f"agent_{i}" for i in range(5)]
    assert out.read_text().startswith("#usda")


def test_blender_layout_agents_are_not_instances(config_path, tmp_path, capsys):
    out = tmp_path / "shot.usdc"
    assert main(["export", "--config", str(config_path), "--out", str(out),
                 "--frames", "2-9", "--layout", "blender", "--json"]) == 0
    json.loads(capsys.readouterr().out)
    stage = Usd.Stage.Open(str(out))
    agents = stage.GetPrimAtPath("/Crowd/Agents").GetChildren()
    assert len(agents) == FAN_AGENTS + KID_AGENTS
    assert not any(p.IsInstance() or p.IsInstanceable() for p in agents)
    assert stage.GetRootLayer().customLayerData["crowd"]["layout"] == "blender"


def test_substeps_write_samples_between_frames(config_path, tmp_path, capsys):
    out = tmp_path / "shot.usdc"
    assert main(["export", "--config", str(config_path), "--out", str(out),
                 "--frames", "2-6", "--substeps", "4"]) == 0
    assert "(4 samples a frame)" in capsys.readouterr().out
    stage = Usd.Stage.Open(str(out))
    assert stage.GetRootLayer().customLayerData["crowd"]["substeps"] == 4
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (2, 6)
    anim = UsdSkel.Animation(next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation)
                                  and "/Streams/" in str(p.GetPath())))
    times = anim.GetRotationsAttr().GetTimeSamplesInInterval(Gf.Interval(2, 6.75))
    assert times == [2 + k / 4 for k in range(20)]      # the last frame's too (shutter)


def test_an_unknown_layout_is_refused_before_anything_runs(config_path, tmp_path):
    from crowd_addon.core import CrowdError
    from crowd_addon.usd import check_export

    with pytest.raises(CrowdError, match="layout must be one of instanced, blender, got "
                                         "'maya'"):
        check_export(make_config(), tmp_path / "shot.usdc", layout="maya")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("extra, message", [
    (["--agents", "1000"], "crowd export: error: export: 1000 agents requested but the "
                           "crowd has 46"),
    (["--frames", "5-2"], "last frame 2 is before first frame 5"),
    (["--frames", "soon"], "must be FIRST-LAST or a frame"),
    (["--frames=-4-2"], "starts before the crowd's start frame 0"),
    (["--agents", "0"], "must be >= 1"),
    (["--substeps", "0"], "argument --substeps: must be >= 1, got 0"),
    (["--substeps", "17"], "argument --substeps: must be <= 16, got 17"),
    (["--substeps", "2.5"], "argument --substeps: must be an integer"),
])
def test_bad_input_exits_2_and_writes_nothing(config_path, tmp_path, capsys, extra,
                                               message):
    args = ["export", "--config", str(config_path), "--out", str(tmp_path / "s.usdc"),
            "--frames", "0-4", *extra]
    assert main(args) == 2
    assert message in capsys.readouterr().err
    assert os.listdir(tmp_path) == []


def test_negative_frame_range_may_follow_frames_as_its_own_word(tmp_path, capsys):
    """Regression: ``--frames -5-3`` stopped with argparse's "argument --frames: expected
    one argument" (a word starting with ``-`` taken for an option) in every command with
    --frames; only ``--frames=-5-3`` worked. Both forms, an abbreviated option and a
    single negative frame now reach the command; ``--`` ends the joining."""
    from crowd_addon.blender.cli_commands import build_parser as blender_parser
    from crowd_addon.cli import build_parser
    from crowd_addon.cli_args import parse_command

    cfg = make_config()
    cfg.start_frame = -5
    save_config(cfg, tmp_path / "early.json")
    out = tmp_path / "shot.usda"
    assert main(["export", "--config", str(tmp_path / "early.json"), "--out", str(out),
                 "--frames", "-5-3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == [-5, 3]
    stage = Usd.Stage.Open(str(out))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (-5, 3)
    snapshot = ["snapshot", "--config", "c.json", "--out", "d", "--every", "2"]
    for parser, argv in ((build_parser(), snapshot),
                         (blender_parser(), ["export", "--out", "s.usdc"])):
        for frames, expected in ((["--frames", "-5-3"], (-5, 3)),
                                 (["--frames=-5-3"], (-5, 3)),
                                 (["--fram", "-5--2"], (-5, -2)),
                                 (["--frames", " -4 - 1 "], (-4, 1)),
                                 (["--frames", "-7"], (-7, -7))):
            args, code = parse_command(parser, argv + frames)
            assert code is None and args.frames == expected, frames
    assert parse_command(build_parser(), snapshot + ["--frames", "--", "-5-3"]) == (None, 2)
    assert "argument --frames: expected one argument" in capsys.readouterr().err


@pytest.mark.parametrize("option, value, message", [
    # before: a NUL raised a bare ValueError (traceback), an empty --config fell back to
    # the .blend path ("no .blend is open") after importing bpy (found by test_fuzz.py)
    ("--out", "a\x00b.usdc", "argument --out: must not contain a NUL character"),
    ("--out", "", "argument --out: must not be empty"),
    ("--config", "", "argument --config: must not be empty"),
    ("--config", "a\x00b.json", "argument --config: must not contain a NUL character"),
])
def test_empty_or_nul_paths_are_named(config_path, tmp_path, capsys, option, value,
                                      message):
    args = {"--config": str(config_path), "--out": str(tmp_path / "s.usdc")}
    args[option] = value if option == "--config" or not value else str(tmp_path / value)
    assert main(["export", *[x for kv in args.items() for x in kv], "--frames", "0-2"]) == 2
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("crowd export: error: ") and message in err
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("field", ["stream", "unique"])
def test_agent_index_out_of_range_is_named(tmp_path, capsys, field):
    # before: check_export indexed with the unchecked agent arrays (IndexError traceback);
    # the crowd is built, and checks them, first (found by tests/test_fuzz.py)
    cfg = make_config()
    if field == "stream":
        cfg.agent_stream[3] = 25
    else:
        cfg.agent_stream[3], cfg.agent_unique[3] = -1, 7
    save_config(cfg, tmp_path / "crowd.json")
    out = tmp_path / "out"
    out.mkdir()
    assert main(["export", "--config", str(tmp_path / "crowd.json"), "--out",
                 str(out / "s.usdc"), "--frames", "0-2"]) == 2
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("crowd export: error: ") and "agent 3" in err
    assert os.listdir(out) == []


def test_missing_config_is_named(tmp_path, capsys):
    assert main(["export", "--config", str(tmp_path / "nope.json"), "--out",
                 str(tmp_path / "s.usdc"), "--frames", "0-4"]) == 2
    assert f"crowd export: error: {tmp_path / 'nope.json'}: no such file" in \
        capsys.readouterr().err


def test_help_lists_the_options(capsys):
    assert main(["export", "--help"]) == 0
    text = capsys.readouterr().out
    for option in ("--config", "--out", "--frames", "--agents", "--json"):
        assert option in text


def test_python_m_crowd_addon_export(config_path, tmp_path):
    out = tmp_path / "shot.usdc"
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "export", "--config",
                          str(config_path), "--out", str(out), "--frames", "0-6"],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "crowd export: simulate" in run.stderr and "wrote" in run.stdout
    assert (tmp_path / "shot.layers" / "v1" / "characters" / "fan.usdc").is_file()
