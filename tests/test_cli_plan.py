"""``crowd plan`` from a saved configuration: every candidate printed, the proposal,
the JSON line with ``repetition_default`` and ``repetition_planned``, and the plot
(matplotlib) with its chosen point; bad input named with exit code 2."""

import json
import os
import sys

import numpy as np
import pytest

from crowd_addon.cli import main
from crowd_addon.core.authoring.config_io import save_config

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from core.test_variety_plan import config  # noqa: E402


@pytest.fixture(scope="module")
def crowd_json(tmp_path_factory):
    path = tmp_path_factory.mktemp("plan") / "crowd.json"
    save_config(config(), path)
    return path


def test_plan_prints_the_candidates_the_proposal_and_plots_them(crowd_json, tmp_path,
                                                                 capsys):
    png = tmp_path / "plan.png"
    assert main(["plan", "--config", str(crowd_json), "--budget-mb", "4",
                 "--max-streams", "12", "--plot", str(png), "--json"]) == 0
    out, err = capsys.readouterr()
    result = json.loads(out)         # stdout is the JSON object alone (issue 35, item 6)
    lines = [line for line in err.splitlines() if not line.startswith("crowd plan:")]
    assert result["repetition_planned"] < result["repetition_default"]
    assert result["planned"]["bytes"] <= 4e6 and result["planned"]["streams"] <= 12
    assert result["plot"] == str(png) and result["k"] == 6
    assert result["sub_key_bytes"] == 0 and "resampled" not in err     # no speed streams
    assert lines[0].split() == ["M", "copies", "offsets", "streams", "memory", "MB",
                                "repetition"]
    assert sum(line.endswith(" *") for line in lines) == 1
    assert "(over budget)" in err and "less repetition" in err
    assert "crowd plan: candidates" in err
    from matplotlib.image import imread               # a PNG decoder of its own
    img = (imread(png)[..., :3] * 255).astype(np.uint8)
    assert img.shape[0] > 400 and img.shape[1] > 700
    red = (img[..., 0] > 180) & (img[..., 1] < 60) & (img[..., 2] < 90)   # the star
    assert red.sum() > 50
    assert len(np.unique(img.reshape(-1, img.shape[-1]), axis=0)) > 50


def test_plan_prints_the_memory_of_the_speed_streams_resampled_keys(tmp_path, capsys):
    """Streams at another speed than 1 sample clips resampled at sub-frames
    (core.anim.sub_keys): ``crowd plan`` says how much CPU memory that takes, the
    bytes the crowd itself allocates."""
    from crowd_addon.core import Crowd
    from crowd_addon.core.variety.timing import Timing
    cfg = config(Timing(0.8, 1.2, 2, 3))
    save_config(cfg, tmp_path / "speeds.json")
    assert main(["plan", "--config", str(tmp_path / "speeds.json"), "--no-plot",
                 "--json"]) == 0
    out, err = capsys.readouterr()
    made = Crowd(cfg, skinning="gpu").bank.sub_keys.nbytes
    assert json.loads(out)["sub_key_bytes"] == made > 0
    assert f"resampled at 1/8 frame, {made / 1e6:,.1f} MB of CPU memory" in err


def test_no_plot_and_options(crowd_json, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["plan", "--config", str(crowd_json), "--no-plot", "--neighbours", "3",
                 "--width", "640", "--height", "640", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["plot"] is None and result["k"] == 3
    assert not (tmp_path / "plan.png").exists()


def test_motion_only_leaves_looks_out(crowd_json, tmp_path, capsys):
    """``--motion-only`` measures agents in step whatever their bodies and colours: the
    default repeats more than with looks compared (agents here in random colours), and
    the JSON says so."""
    cfg = config()
    cfg.agent_color = np.random.default_rng(2).uniform(0, 1, cfg.agent_color.shape)
    save_config(cfg, tmp_path / "colours.json")
    args = ["plan", "--config", str(tmp_path / "colours.json"), "--no-plot", "--json"]
    assert main(args) == 0
    full = json.loads(capsys.readouterr().out)
    assert main(args + ["--motion-only"]) == 0
    out, err = capsys.readouterr()
    motion = json.loads(out)
    assert full["appearance"] is True and motion["appearance"] is False
    assert motion["repetition_default"] > full["repetition_default"]
    assert motion["repetition_planned"] < motion["repetition_default"]
    assert "; motion only" in err


def test_bad_input_is_named(crowd_json, tmp_path, capsys):
    assert main(["plan", "--config", str(crowd_json), "--budget-mb", "0.001",
                 "--no-plot"]) == 2
    assert "crowd plan: error: plan: no candidate fits 1,000 B" in capsys.readouterr().err
    assert main(["plan", "--config", str(crowd_json), "--scene", "x", "--no-plot"]) == 2
    assert "--scene needs --blend" in capsys.readouterr().err
    assert main(["plan", "--config", str(crowd_json),
                 "--plot", str(tmp_path / "missing" / "p.png")]) == 2
    assert "cannot write the plot" in capsys.readouterr().err


@pytest.mark.parametrize("plot, message", [
    ("plan.txt", "--plot {}: '.txt' is no plot format; use .png, .svg, .pdf"),
    ("adir", "--plot {}: is a folder"),
])
def test_a_plot_name_it_cannot_write_is_refused_before_the_work(crowd_json, tmp_path, capsys,
                                                                plot, message):
    """Regression: --plot plan.txt ended, after the planning, in matplotlib's ValueError
    traceback (exit 1); --plot DIR wrote DIR.png."""
    (tmp_path / "adir").mkdir()
    target = str(tmp_path / plot)
    assert main(["plan", "--config", str(crowd_json), "--plot", target]) == 2
    (line,) = capsys.readouterr().err.splitlines()        # no "candidates" progress
    assert line.startswith(f"crowd plan: error: {message.format(target)}")
    assert os.listdir(tmp_path) == ["adir"]
    assert not os.listdir(tmp_path / "adir")


def test_a_plot_without_extension_is_a_png_reported_by_its_name(crowd_json, tmp_path,
                                                                 capsys):
    """Regression: --plot myplot wrote myplot.png but printed "plot: myplot" (and
    "plot": "myplot" in the JSON)."""
    assert main(["plan", "--config", str(crowd_json), "--plot", str(tmp_path / "myplot"),
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["plot"] == str(tmp_path / "myplot.png")
    assert os.listdir(tmp_path) == ["myplot.png"]
    assert (tmp_path / "myplot.png").read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    assert main(["plan", "--config", str(crowd_json), "--plot", str(tmp_path / "p.SVG")]) == 0
    assert f"  plot: {tmp_path / 'p.SVG'}" in capsys.readouterr().out
    assert (tmp_path / "p.SVG").read_bytes().lstrip().startswith(b"<?xml")


def test_a_plot_that_fails_part_way_leaves_the_earlier_one_whole(crowd_json, tmp_path):
    """Regression: the plot was written in place, so a write that failed part way (here
    the 16 KiB file size limit of `ulimit -f 16`, as a full disk does) left plan.png
    truncated. Now the earlier plot stays as it was and no temporary is left."""
    import resource
    import subprocess

    png = tmp_path / "plan.png"
    assert main(["plan", "--config", str(crowd_json), "--plot", str(png)]) == 0
    earlier = png.read_bytes()
    assert len(earlier) > 16 * 1024

    def small_files():
        resource.setrlimit(resource.RLIMIT_FSIZE, (16 * 1024, resource.RLIM_INFINITY))
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "plan", "--config",
                          str(crowd_json), "--plot", str(png), "--budget-mb", "4"],
                         capture_output=True, text=True, timeout=300, preexec_fn=small_files,
                         cwd=root)
    assert run.returncode == 2, run.stderr[-2000:]
    assert f"crowd plan: error: {png}: cannot write the plot: File too large" in run.stderr
    assert png.read_bytes() == earlier and os.listdir(tmp_path) == ["plan.png"]
