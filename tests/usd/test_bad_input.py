"""Bad input and failures: a clear CrowdError naming the thing at fault, no partial
file, and a previous export left exactly as it was."""

import os

import pytest

from crowd_addon.core import Crowd
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.shots.recorder import record
from crowd_addon.usd import check_export, export_crowd, export_steps
from crowd_addon.usd import files as files_module

from .conftest import FIRST, make_config, recording, simulate

FRAMES = (FIRST, 6)


def export(path, agents=None, config=None, frames=FRAMES, before_step=None):
    """Record ``config`` (default the conftest's) over ``frames`` and export it."""
    return export_crowd(recording(config, frames, before_step), path, agents=agents)


def snapshot(directory):
    """Every file below ``directory`` with its bytes."""
    out = {}
    for root, _, names in os.walk(directory):
        for n in names:
            p = os.path.join(root, n)
            with open(p, "rb") as f:
                out[os.path.relpath(p, directory)] = f.read()
    return out


@pytest.fixture
def previous(tmp_path):
    """A finished export in ``tmp_path`` and a snapshot of it."""
    export(tmp_path / "shot.usdc", agents=4)
    return tmp_path / "shot.usdc", snapshot(tmp_path)


def unwritable_directory(tmp_path):
    if os.geteuid() == 0:              # root writes anywhere on disk, but not in /proc
        return "/proc"
    ro = tmp_path / "read_only"
    ro.mkdir()
    ro.chmod(0o555)
    return str(ro)


def test_unwritable_directory(tmp_path):
    target = os.path.join(unwritable_directory(tmp_path), "shot.usdc")
    with pytest.raises(CrowdError, match="cannot write in"):
        export(target)
    with pytest.raises(CrowdError, match="cannot write in"):
        check_export(make_config(), target)
    assert not os.path.exists(target)


@pytest.mark.parametrize("path, message", [
    ("missing/shot.usdc", "does not exist"),
    ("shot.abc", "ending in .usdc, .usd, .usda"),
    ("shot", "no extension"),
])
def test_bad_output_path(tmp_path, path, message):
    with pytest.raises(CrowdError, match=message):
        export(tmp_path / path)
    with pytest.raises(CrowdError, match=message):
        check_export(make_config(), tmp_path / path)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("frames, message", [
    ((6, 2), "is empty"),
    ((-3, 4), "before the crowd's start frame 0"),
    ((1.5, 4), "whole numbers"),
])
def test_bad_frame_range(previous, frames, message):
    path, before = previous
    with pytest.raises(CrowdError, match=message):
        export(path, frames=frames)
    assert snapshot(path.parent) == before


@pytest.mark.parametrize("agents, message", [
    (1000, "1000 agents requested but the crowd has 46"),
    (0, "count >= 1"),
])
def test_bad_agent_count(previous, agents, message):
    path, before = previous
    with pytest.raises(CrowdError, match=message):
        export(path, agents=agents)
    with pytest.raises(CrowdError, match=message):
        check_export(make_config(), path, agents=agents)
    assert snapshot(path.parent) == before


def test_skeleton_without_mesh(previous):
    path, before = previous
    cfg = make_config()
    del cfg.meshes["kid"]
    with pytest.raises(CrowdError, match="skeleton 'kid' has no proxy mesh"):
        export(path, config=cfg)
    with pytest.raises(CrowdError, match="skeleton 'kid' has no proxy mesh"):
        check_export(cfg, path)
    assert snapshot(path.parent) == before
    check_export(cfg, path, agents=6)
    export(path, config=cfg, agents=6)              # the fan agents alone need no kid


def test_not_a_recording(tmp_path):
    with pytest.raises(CrowdError, match="expected a Recording .*, got CrowdConfig"):
        export_crowd(make_config(), tmp_path / "shot.usdc")


def test_failing_simulation_writes_nothing(previous):
    path, before = previous

    def broken(crowd, frame):
        simulate(crowd, frame)
        if frame == 5:
            crowd.transition_to_streamed([0], "no such stream", 3)

    with pytest.raises(CrowdError, match="before_step callback failed at frame 5: .*"
                                         "unknown stream 'no such stream'"):
        export(path, before_step=broken)
    assert snapshot(path.parent) == before


def test_failure_while_writing_layers_writes_nothing(previous, monkeypatch):
    path, before = previous
    calls = []
    save = files_module.ExportFiles.save

    def fails_on_third_layer(self, layer, name=None):
        calls.append(name)
        if len(calls) == 3:
            raise CrowdError("disk full (simulated)")
        return save(self, layer, name)

    monkeypatch.setattr(files_module.ExportFiles, "save", fails_on_third_layer)
    with pytest.raises(CrowdError, match="disk full"):
        export(path, before_step=simulate)
    assert len(calls) == 3
    assert snapshot(path.parent) == before


def test_failed_rename_restores_the_previous_export(previous, monkeypatch):
    """The swap itself fails at its last step (the main layer's rename): the folder of
    layers already swapped in is swapped back."""
    path, before = previous

    def refuse(src, dst):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(files_module.os, "replace", refuse)
    with pytest.raises(CrowdError, match="cannot move the export into place"):
        export(path, before_step=simulate)
    assert snapshot(path.parent) == before


def test_an_export_cancelled_midway_writes_nothing(previous):
    """Closing export_steps (a cancel) after layers were written leaves no temporary
    folder and the previous export as it was."""
    path, before = previous
    steps = export_steps(recording(before_step=simulate), path)
    assert next(steps)[0] == "characters"
    assert [p for p in os.listdir(path.parent) if p.startswith(".shot.usdc.")]
    steps.close()
    assert snapshot(path.parent) == before


def test_built_crowd_past_the_shot_is_reset(tmp_path):
    """A Crowd already past the first frame is reset to its start and re-run: the
    files are the same as from a fresh configuration."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    crowd = Crowd(make_config(), skinning="gpu")
    crowd.advance_to(10)
    export_crowd(record(crowd, *FRAMES), tmp_path / "a" / "shot.usda")
    assert crowd.view.frame == FRAMES[1]
    export(tmp_path / "b" / "shot.usda")
    assert snapshot(tmp_path / "a") == snapshot(tmp_path / "b")


def test_check_export_names_an_agent_stream_out_of_range(previous):
    # before: IndexError from check_export on a configuration nobody had validated
    path, before = previous
    cfg = make_config()
    cfg.agent_stream[2] = 99
    with pytest.raises(CrowdError, match=r"agent 2|stream"):
        check_export(cfg, path)
    assert snapshot(path.parent) == before
