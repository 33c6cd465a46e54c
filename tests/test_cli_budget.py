"""``crowd budget``: the paper's model and the planner from the command line."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from crowd_addon.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ["budget", "--bones", "82", "--pose-bytes", "800", "--clip-frames", "300",
           "--budget-mb", "520", "--max-offset", "60"]


def test_example_prints_model_and_plan(capsys):
    assert main(EXAMPLE) == 0
    out = capsys.readouterr().out
    assert "ClipSize_OLD            240,000 B" in out
    assert "ClipSize_NEW            48,000 B" in out
    assert "NumClips_OLD            2,166" in out
    assert "NumClips_NEW            10,830" in out
    assert "MemBudget/ClipSize_NEW  10,833" in out
    assert "Plan for 65,000 agents" in out
    assert "max offset M            60 frames" in out
    assert "streams S               271" in out


def test_defaults_are_the_paper_inputs(capsys):
    assert main(["budget"]) == 0
    out = capsys.readouterr().out
    assert "PoseSize                820 B (82 bones x 10 B)" in out
    assert "ClipSize_OLD            246,000 B" in out
    assert "NumClips_OLD            2,113" in out  # not the paper's printed 216


def test_mib_and_json(capsys):
    assert main(["budget", "--mib", "--max-offset", "60", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["units"]["budget_unit_bytes"] == 2**20
    assert data["memory_model"]["budget_bytes"] == 520 * 2**20
    assert data["memory_model"]["num_clips_old"] == 2216
    assert data["memory_model"]["num_clips_new"] == 11080


def test_plan_options(capsys):
    assert main(["budget", "--json", "--agents", "1000", "--streams", "8",
                 "--clip-frames", "300", "45", "--transition-slots", "0"]) == 0
    data = json.loads(capsys.readouterr().out)
    plan = data["plan"]
    assert (plan["streams"], plan["max_offset"]) == (8, 45)
    assert data["memory_model"]["motion_length"] == 172.5  # mean of the clips
    assert data["max_offset_source"] == "planner"


def test_python_m_json_subprocess():
    run = subprocess.run([sys.executable, "-m", "crowd_addon", *EXAMPLE, "--json"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    model = data["memory_model"]
    assert model["clip_size_old"] == 240_000
    assert (model["num_clips_old"], model["num_clips_new"]) == (2166, 10830)
    assert model["num_clips_new_direct"] == 10833
    plan = data["plan"]
    assert plan["max_offset"] == 60
    assert plan["bytes_used"] <= plan["budget_bytes"]


def test_python_m_cli_module_runs_the_command():
    # before: `python -m crowd_addon.cli ...` imported the module and exited 0 silently
    run = subprocess.run([sys.executable, "-m", "crowd_addon.cli", *EXAMPLE, "--json"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["plan"]["max_offset"] == 60


@pytest.mark.parametrize("args, message", [
    (["--max-offset", "0"], "argument --max-offset: must be >= 1, got 0"),
    (["--budget-mb", "nan"], "argument --budget-mb: must be a finite number > 0, got 'nan'"),
    (["--bones", "x"], "argument --bones: must be an integer, got 'x'"),
    (["--max-offset", "400"], "budget: max_offset 400 exceeds the shortest clip "
                              "(300 frames)"),
    (["--budget-mb", "1"], "unique and transition rows need"),
])
def test_bad_input_exit_code_2(capsys, args, message):
    assert main(["budget", *args]) == 2
    err = capsys.readouterr().err
    assert "crowd budget: error: " in err
    assert message in err


def test_help_and_no_command(capsys):
    assert main(["budget", "--help"]) == 0
    assert "--pose-bytes" in capsys.readouterr().out
    assert main([]) == 2
    assert "budget" in capsys.readouterr().err
