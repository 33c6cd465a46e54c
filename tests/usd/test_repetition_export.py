"""The repetition metric an export reports (``ExportResult.repetition``, the main
layer's ``customLayerData.crowd.repetition``, ``crowd export``'s summary): measured on
the exported agents at frames spread over the shot, through the camera given or one
framing the agents. The oracle is the running crowd's own metric at those frames."""

import json

import numpy as np
import pytest
from pxr import Usd

from crowd_addon.cli import main
from crowd_addon.core import Crowd
from crowd_addon.core.authoring.config_io import save_config
from crowd_addon.core.variety.repetition import RepetitionSettings, crowd_repetition
from crowd_addon.core.base.camera import Camera
from crowd_addon.usd import export_crowd

from .conftest import FIRST, LAST, make_config, recording, simulate

CAMERA = Camera((0.0, -30.0, 25.0), (0.0, 0.0, 0.0), aspect=4 / 3)


def live_metric(frames, agents, settings):
    """The crowd stepped through the shot, measured at ``frames`` on ``agents``."""
    crowd = Crowd(make_config())
    out = []
    while crowd.frame < max(frames):
        simulate(crowd, crowd.frame + 1)
        crowd.step()
        if crowd.frame in frames:
            a, v = crowd.view.agents, crowd.view
            sub = type("View", (), {})()
            sub.frame, sub.config = crowd.frame, v.config
            sub.agent_body = v.agent_body[agents]
            sub.agents = type("A", (), {k: getattr(a, k)[agents] for k in (
                "position", "kind", "ref", "offset", "color")})()
            out.append(crowd_repetition(sub, CAMERA.view_projection,
                                        settings=settings).value)
    return out


def test_the_export_measures_what_the_crowd_shows(tmp_path):
    settings = RepetitionSettings(k=3, offset_tolerance=1, color_tolerance=1.0, frames=5,
                                  width=800, height=600)
    res = export_crowd(recording(), tmp_path / "shot.usdc", agents=30, camera=CAMERA,
                       repetition=settings)
    rep = res.repetition
    assert rep["frames"] == [2, 6, 9, 12, 16] and rep["k"] == 3
    want = live_metric(rep["frames"], np.arange(30), settings)
    assert rep["per_frame"] == pytest.approx(want, abs=1e-6)
    assert rep["value"] == pytest.approx(np.mean(want), abs=1e-6)
    assert 0 < rep["value"] < 1
    stage = Usd.Stage.Open(str(res.path))
    crowd = stage.GetRootLayer().customLayerData["crowd"]
    assert crowd["repetition"] == pytest.approx(rep["value"], abs=1e-6)
    assert crowd["repetitionK"] == 3


def test_progress_has_a_repetition_stage_and_none_skips_it(tmp_path):
    seen = []
    res = export_crowd(recording(), tmp_path / "a.usdc",
                       progress=lambda stage, d, n: seen.append((stage, d, n)))
    assert [s for s in seen if s[0] == "repetition"] == [("repetition", d, 8)
                                                        for d in range(1, 9)]
    assert len(res.repetition["frames"]) == 8 and res.repetition["k"] == 6
    off = export_crowd(recording(), tmp_path / "b.usdc", repetition=None)
    assert off.repetition is None
    stage = Usd.Stage.Open(str(off.path))
    assert "repetition" not in stage.GetRootLayer().customLayerData["crowd"]


def test_crowd_export_prints_and_reports_it(tmp_path, capsys):
    cfg = tmp_path / "crowd.json"
    save_config(make_config(), cfg)
    out = tmp_path / "shot.usdc"
    assert main(["export", "--config", str(cfg), "--out", str(out), "--frames",
                 f"{FIRST}-{LAST}", "--neighbours", "4", "--repetition-frames", "3"]) == 0
    text = capsys.readouterr().out
    assert "  repetition 0." in text and "k=4" in text and "3 frames" in text
    assert main(["export", "--config", str(cfg), "--out", str(out), "--frames",
                 f"{FIRST}-{LAST}", "--neighbours", "4", "--repetition-frames", "3",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["repetition"]["frames"] == [FIRST, (FIRST + LAST) // 2, LAST]
    assert summary["repetition"]["k"] == 4
    assert main(["export", "--config", str(cfg), "--out", str(out), "--frames",
                 f"{FIRST}-{LAST}", "--repetition-frames", "0", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["repetition"] is None
