"""``crowd preview``: a saved crowd rendered headless to PNG frames and an MP4.

Oracles: ffmpeg (through imageio-ffmpeg) decodes the PNGs and the MP4 and counts
the MP4's frames, independently of our PNG writer; the Blender backend's frame
from a subprocess is compared with the moderngl one.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from crowd_addon.cli import main
from crowd_addon.core.authoring.config_io import save_config

imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def decode(path):
    """Every frame of an image or video file as (n, H, W, 3) uint8, decoded by ffmpeg."""
    reader = imageio_ffmpeg.read_frames(str(path))
    w, h = next(reader)["size"]
    return np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader])


@pytest.fixture
def config_path(h, tmp_path):
    path = tmp_path / "crowd.json"
    save_config(h.make_config(M=8, agents=16, spacing=0.9), path)
    return path


def run(capsys, *argv):
    code = main(["preview", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_frames_and_mp4_are_written_visible_and_moving(config_path, tmp_path, capsys):
    out_dir = tmp_path / "shot"
    code, out, err = run(capsys, "--config", config_path, "--out", out_dir, "--frames", 5,
                         "--start", 3, "--width", 96, "--height", 64, "--mp4", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["frames"] == [3, 7] and "frame 5/5" in err
    pngs = [out_dir / f"frame_{f:04d}.png" for f in range(3, 8)]
    assert summary["pngs"] == [str(p) for p in pngs]
    frames = np.concatenate([decode(p) for p in pngs])
    assert frames.shape == (5, 64, 96, 3)
    background = frames[0, 0, 0]
    assert ((frames != background).any(-1).mean((1, 2)) > 0.03).all()     # agents show
    assert (frames[0] != frames[4]).any(-1).mean() > 0.005                # and move
    video = out_dir / "preview.mp4"
    assert summary["mp4"] == str(video)
    assert imageio_ffmpeg.count_frames_and_secs(str(video))[0] == 5
    movie = decode(video)
    assert movie.shape == (5, 64, 96, 3)
    # lossy H.264, but the same pictures in the same order
    err_same = np.abs(movie.astype(int) - frames.astype(int)).mean((1, 2, 3))
    err_shifted = np.abs(movie[1:].astype(int) - frames[:-1].astype(int)).mean((1, 2, 3))
    assert err_same.max() < 6 and (err_same[1:] < err_shifted).all()
    assert [p.name for p in out_dir.iterdir() if p.name.startswith(".")] == []


def test_the_repetition_metric_of_the_frames_shown(config_path, tmp_path, capsys, h):
    """``--neighbours 3 --repetition-frames 3``: measured through the preview's camera
    at the frames' size on the frames shown; the oracle is the crowd stepped alone and
    measured at the same frames through the same camera."""
    from crowd_addon.core.authoring.config_io import load_config
    from crowd_addon.core.variety.repetition import RepetitionSettings, crowd_repetition
    from crowd_addon.core.base.camera import frame_crowd
    code, out, err = run(capsys, "--config", config_path, "--out", tmp_path / "r",
                         "--frames", 7, "--width", 96, "--height", 64, "--neighbours", 3,
                         "--repetition-frames", 3, "--json")
    assert code == 0, err
    rep = json.loads(out)["repetition"]
    assert rep["frames"] == [0, 3, 6] and rep["k"] == 3 and rep["screen"] == [96, 64]
    crowd = h.Crowd(load_config(config_path))
    camera = frame_crowd(crowd, aspect=96 / 64)
    want = []
    for f in range(7):
        if f:
            crowd.step()
        if f in (0, 3, 6):
            want.append(crowd_repetition(crowd.view, camera.view_projection, settings=
                                         RepetitionSettings(k=3, width=96, height=64)).value)
    assert rep["per_frame"] == pytest.approx(want, abs=1e-6)
    code, out, _ = run(capsys, "--config", config_path, "--out", tmp_path / "r2", "--frames",
                       2, "--width", 64, "--height", 48)
    assert "  repetition " in out and "k=6" in out


def test_text_summary(config_path, tmp_path, capsys):
    code, out, _ = run(capsys, "--config", config_path, "--out", tmp_path / "s", "--frames", 2,
                       "--width", 64, "--height", 48)
    assert code == 0
    assert out.startswith("wrote 2 frames (0-1)") and "16 agents" in out
    assert sorted(os.listdir(tmp_path / "s")) == ["frame_0000.png", "frame_0001.png"]


@pytest.mark.parametrize("args, message", [
    (["--frames", 0], "argument --frames: must be >= 1"),
    (["--frames", 2, "--width", 95, "--mp4"], "even width and height"),
    (["--frames", 2, "--width", 20000], "1..16384 pixels"),
])
def test_bad_input_exits_2_and_writes_nothing(config_path, tmp_path, capsys, args, message):
    out_dir = tmp_path / "shot"
    code, _, err = run(capsys, "--config", config_path, "--out", out_dir, *args)
    assert code == 2
    assert "crowd preview: error:" in err
    assert message in err
    assert not out_dir.exists()


@pytest.mark.parametrize("args, message", [
    # before: --start beyond a C long raised OverflowError, a NUL in --out a bare
    # ValueError (tracebacks), and --out "" wrote the frames into the current folder
    # (found by tests/test_fuzz.py)
    (["--start", "99999999999999999999"], "argument --start: must be an integer of "
                                          "magnitude at most 2147483647"),
    (["--out", "a\x00b"], "argument --out: must not contain a NUL character"),
    (["--out", ""], "argument --out: must not be empty"),
])
def test_bad_paths_and_frames_are_named(config_path, tmp_path, capsys, monkeypatch, args,
                                        message):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    code, _, err = run(capsys, "--config", config_path, "--out", work / "shot", "--frames",
                       1, "--width", 16, "--height", 16, *args)
    assert code == 2
    assert err.splitlines()[-1].startswith("crowd preview: error: ") and message in err
    assert os.listdir(work) == []


def test_a_crowd_refused_after_the_arguments_creates_no_folder(h, tmp_path, capsys):
    # created before: the folder was made before the crowd was built (and refused)
    path = tmp_path / "narrow.json"
    save_config(h.make_config(M=8, agents=16, max_texture_size=32), path)
    out_dir = tmp_path / "shot"
    code, _, err = run(capsys, "--config", path, "--out", out_dir / "deep", "--frames", 1)
    assert code == 2 and "crowd preview: error:" in err and "32" in err
    assert not out_dir.exists()


def fail_the_third_png(monkeypatch):
    """Make the preview's third PNG write fail as a full disk does."""
    from crowd_addon.gpu import preview_render
    real, calls = preview_render.write_png, []

    def failing(path, *a, **k):
        calls.append(path)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return real(path, *a, **k)

    monkeypatch.setattr(preview_render, "write_png", failing)


def test_a_failed_render_removes_its_frames(config_path, tmp_path, capsys, monkeypatch):
    out_dir = tmp_path / "shot"
    out_dir.mkdir()
    (out_dir / "notes.txt").write_text("mine")
    fail_the_third_png(monkeypatch)
    code, _, err = run(capsys, "--config", config_path, "--out", out_dir, "--frames", 4,
                       "--width", 32, "--height", 32)
    assert code == 2 and "No space left on device" in err
    assert sorted(os.listdir(out_dir)) == ["notes.txt"]


def _frames(folder):
    return {name: (folder / name).read_bytes() for name in sorted(os.listdir(folder))
            if name.startswith("frame_")}


def test_a_failed_rerun_keeps_the_frames_of_the_run_before(config_path, tmp_path, capsys,
                                                           monkeypatch):
    """Before: the re-run wrote over the earlier frames one by one, then its clean-up
    removed the ones it had written, so the earlier run lost frames 0 and 1."""
    out_dir = tmp_path / "shot"
    size = ("--width", 32, "--height", 32)
    assert run(capsys, "--config", config_path, "--out", out_dir, "--frames", 4, *size)[0] == 0
    before = _frames(out_dir)
    assert len(before) == 4
    fail_the_third_png(monkeypatch)
    code, _, err = run(capsys, "--config", config_path, "--out", out_dir, "--frames", 4,
                       "--samples", 0, *size)
    assert code == 2 and "No space left on device" in err
    assert _frames(out_dir) == before
    assert sorted(os.listdir(out_dir)) == sorted(before)          # no partial folder left


def test_a_rerun_replaces_the_frames_of_the_run_before(config_path, tmp_path, capsys):
    """The folder holds one run's frames: a shorter re-run leaves none of the longer
    run's later frames beside its own (a sequence of two runs), and the user's own
    files stay."""
    out_dir = tmp_path / "shot"
    size = ("--width", 32, "--height", 32)
    assert run(capsys, "--config", config_path, "--out", out_dir, "--frames", 4, *size)[0] == 0
    (out_dir / "notes.txt").write_text("mine")
    assert run(capsys, "--config", config_path, "--out", out_dir, "--frames", 2,
               "--samples", 0, *size)[0] == 0
    assert sorted(os.listdir(out_dir)) == ["frame_0000.png", "frame_0001.png", "notes.txt"]
    again = tmp_path / "again"
    assert run(capsys, "--config", config_path, "--out", again, "--frames", 2,
               "--samples", 0, *size)[0] == 0
    assert _frames(out_dir) == _frames(again)                      # this run's frames


@pytest.mark.parametrize("signal_", ["SIGTERM", "SIGINT"])
def test_a_run_stopped_by_a_signal_keeps_the_frames_of_the_run_before(config_path, tmp_path,
                                                                      capsys, signal_):
    """A farm queue or ``kill`` ends a job with SIGTERM, Ctrl-C sends SIGINT. Before,
    SIGTERM ended the process on the spot: its staging folder stayed, and Ctrl-C
    printed a traceback. Now both unwind as a failure does: exit 143 or 130, one line
    on stderr, the earlier run's frames as they were, nothing of this run left."""
    import signal
    import time
    out_dir = tmp_path / "shot"
    size = ("--width", 32, "--height", 32)
    assert run(capsys, "--config", config_path, "--out", out_dir, "--frames", 4, *size)[0] == 0
    before = _frames(out_dir)
    proc = subprocess.Popen([sys.executable, "-m", "crowd_addon", "preview", "--config",
                             str(config_path), "--out", str(out_dir), "--frames", "100000",
                             "--samples", "0", *map(str, size)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(
            (out_dir / n).is_dir() and len(os.listdir(out_dir / n)) > 2
            for n in os.listdir(out_dir) if n.startswith(".frames.partial")):
        time.sleep(0.05)                          # until it has drawn a few frames
    proc.send_signal(getattr(signal, signal_))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == {"SIGTERM": 143, "SIGINT": 130}[signal_], err[-2000:]
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == (
        f"crowd preview: {'stopped by SIGTERM' if signal_ == 'SIGTERM' else 'interrupted'}; "
        "earlier outputs are as they were")
    assert _frames(out_dir) == before
    assert sorted(os.listdir(out_dir)) == sorted(before)          # no partial folder left


def test_a_rerun_removes_what_a_run_killed_outright_left(config_path, tmp_path, capsys):
    """SIGKILL leaves no chance to clean up: before, its staging folder stayed in the
    output folder for good."""
    from crowd_addon.core.base.files import staging
    out_dir = tmp_path / "shot"
    size = ("--width", 32, "--height", 32)
    assert run(capsys, "--config", config_path, "--out", out_dir, "--frames", 2, *size)[0] == 0
    killed = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    left = out_dir / staging(out_dir, "frames.partial").name.replace(
        f"-{os.getpid()}", f"-{killed.pid}")
    left.mkdir()
    (left / "frame_0000.png").write_bytes(b"half")
    killed.kill()
    killed.wait()
    assert run(capsys, "--config", config_path, "--out", out_dir, "--frames", 2, *size)[0] == 0
    assert sorted(os.listdir(out_dir)) == ["frame_0000.png", "frame_0001.png"]


def test_an_output_name_too_long_is_named(config_path, tmp_path, capsys):
    # before: OSError (File name too long) from the folder check (fuzz seed 1711)
    code, _, err = run(capsys, "--config", config_path, "--out", tmp_path / ("x" * 300),
                       "--frames", 1)
    assert code == 2 and "crowd preview: error: output folder" in err
    assert "File name too long" in err and "Traceback" not in err


def test_missing_config_and_unwritable_output(config_path, tmp_path, capsys):
    code, _, err = run(capsys, "--config", tmp_path / "nope.json", "--out", tmp_path / "o",
                       "--frames", 1)
    assert code == 2 and err.startswith("crowd preview: error:") and "nope.json" in err
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = run(capsys, "--config", config_path, "--out", blocker / "sub", "--frames", 1)
    assert code == 2 and err.startswith("crowd preview: error: output folder")


def test_blender_backend_renders_the_same_frames(config_path, tmp_path, capsys):
    if subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True).returncode:
        pytest.skip("needs the bpy module")
    args = ["--config", config_path, "--frames", 2, "--width", 96, "--height", 64]
    # the same pixels: without the anti-aliasing only the moderngl backend has
    assert run(capsys, *args, "--out", tmp_path / "mgl", "--samples", 0)[0] == 0
    proc = subprocess.run([sys.executable, "-m", "crowd_addon", "preview", *map(str, args),
                           "--out", str(tmp_path / "bl"), "--backend", "blender"],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "blender on" in proc.stdout
    for name in ("frame_0000.png", "frame_0001.png"):
        a, b = decode(tmp_path / "mgl" / name), decode(tmp_path / "bl" / name)
        assert (np.abs(a.astype(int) - b.astype(int)).max(-1) <= 2).mean() >= 0.995


def test_start_shows_that_frame_of_the_shot(h, tmp_path, capsys):
    """``--start F`` draws frame F as a run from the start shows it: a cue before F
    (agents sent to another stream, some still blending at F) has happened."""
    from crowd_addon.core.authoring.show import Action, Cue, Show
    cfg = h.make_config(M=8, agents=16, spacing=0.9, NT=16)
    first = cfg.start_frame
    cfg.show = Show((Cue("go", first + 2, Action("stream", "s1", duration=6, offset=0),
                         agents=np.arange(0, 16, 2)),))
    path = tmp_path / "crowd.json"
    save_config(cfg, path)
    size = ("--width", 96, "--height", 64)
    code, _, err = run(capsys, "--config", path, "--out", tmp_path / "full", "--frames", 9,
                       *size)
    assert code == 0, err
    code, _, err = run(capsys, "--config", path, "--out", tmp_path / "late", "--frames", 4,
                       "--start", first + 5, *size)
    assert code == 0, err
    late = sorted((tmp_path / "late").glob("frame_*.png"))
    assert [p.name for p in late] == [f"frame_{f:04d}.png" for f in range(first + 5,
                                                                            first + 9)]
    for p in late:
        assert np.array_equal(decode(p), decode(tmp_path / "full" / p.name)), p.name
    # without the cue the frame differs: the test sees the cue
    cfg.show = Show()
    save_config(cfg, path)
    code, _, err = run(capsys, "--config", path, "--out", tmp_path / "quiet", "--frames", 1,
                       "--start", first + 5, *size)
    assert code == 0, err
    assert not np.array_equal(decode(tmp_path / "quiet" / late[0].name), decode(late[0]))
    code, _, err = run(capsys, "--config", path, "--out", tmp_path / "early", "--frames", 1,
                       "--start", first - 1, *size)
    assert code == 2 and "before the shot's first frame" in err
