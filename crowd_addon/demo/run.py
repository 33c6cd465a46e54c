"""``crowd demo``: the main job, end to end.

1. build the stadium scene (``sample_scenes/build_stadium.py``, in a child process
   because it resets Blender's session) with ``--agents`` seats;
2. open it, author its crowd settings and bake its actions through the extension's
   own code (:mod:`.stadium`), and save the crowd configuration next to it;
3. run the stadium show (:mod:`.show`: goal, Mexican wave, hits, claps) once, render
   preview frames headless with the GPU path as it runs (PNG, and MP4 when
   imageio-ffmpeg is there) and record it (:mod:`crowd_addon.core.recording`);
4. export that recording to ``stadium.usdc`` (UsdSkel): the same show, not simulated
   again;
5. print a summary and write it as ``summary.json``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from importlib import resources
from pathlib import Path

from ..core.errors import CrowdError

__all__ = ["run_demo"]

try:    # the sample_scenes resource package beside crowd_addon (repository, wheel)
    SAMPLE_BUILDER = resources.files(".".join(__name__.split(".")[:-3] + ["sample_scenes"])) \
        / "build_stadium.py"
except ModuleNotFoundError:     # not shipped (the Blender extension)
    SAMPLE_BUILDER = None


def _bar(done, total, what, stream=sys.stderr, width=30):
    """A progress bar: redrawn in place on a terminal, every 10% otherwise."""
    k = int(width * done / max(total, 1))
    tty = stream.isatty()
    if not tty and done < total and (10 * done) // max(total, 1) == \
            (10 * (done - 1)) // max(total, 1):
        return
    line = f"  {what:<10} [{'#' * k}{'.' * (width - k)}] {done}/{total}"
    stream.write(("\r" + line) if tty else line + "\n")
    if tty and done >= total:
        stream.write("\n")
    stream.flush()


def _build_scene(path: Path, seats: int, log):
    if SAMPLE_BUILDER is None or not SAMPLE_BUILDER.is_file():
        raise CrowdError(f"the stadium builder {SAMPLE_BUILDER or 'sample_scenes'} is missing")
    log(f"building the stadium with {seats:,} seats -> {path}")
    run = subprocess.run([sys.executable, str(SAMPLE_BUILDER), "--out", str(path),
                          "--seats", str(seats), "--quiet"], capture_output=True, text=True)
    if run.returncode != 0:
        raise CrowdError(f"building the stadium failed:\n{run.stderr.strip()[-2000:]}")


def section_camera(stadium, aspect, span=16.0):
    """A camera on the pitch looking up at the home stand where the wave passes first:
    close enough that ``span`` metres of seats fill the frame."""
    import numpy as np

    from ..gpu.camera import Camera
    pos = stadium.config.agent_position.astype(np.float64)
    centre = 0.5 * (pos.min(0) + pos.max(0))
    # seats near angle -pi/2 (the near long side), home first
    near = np.abs(np.angle(np.exp(1j * (stadium.seat_angle + np.pi / 2)))) < 0.35
    pick = pos[near & stadium.home] if (near & stadium.home).any() else pos
    target = pick.mean(0) + np.array([0.0, 0.0, 0.9])
    inward = centre[:2] - target[:2]
    inward /= max(np.linalg.norm(inward), 1e-6)
    fov = np.radians(50.0)
    dist = span / 2 / np.tan(fov * aspect / 2) if aspect < 1 else span / 2 / np.tan(fov / 2)
    eye = target + np.r_[inward * dist, 0.35 * dist]
    return Camera(eye, target, fov, aspect, 0.5, 4 * dist + np.ptp(pos, 0).max())


def run_demo(out_dir, agents: int = 2000, frames: int = 240, size=(960, 540),
             mp4: bool = True, usd: bool = True, log=None) -> dict:
    """Run the stadium demo into ``out_dir``; returns the summary dict."""
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    if agents < 10:
        raise CrowdError(f"--agents must be at least 10, got {agents}")
    if frames < 1:
        raise CrowdError(f"--frames must be at least 1, got {frames}")
    from ..gpu.preview_render import output_dir
    out = output_dir(out_dir)
    t0 = time.perf_counter()
    seconds = {}
    blend = out / "stadium.blend"
    _build_scene(blend, agents, log)
    seconds["build_scene"] = time.perf_counter() - t0

    t = time.perf_counter()
    from ..blender.stadium import author_stadium
    from ..core.config_io import save_config
    log("authoring the crowd and baking its actions")
    stadium = author_stadium(blend, progress=lambda d, n, m: _bar(d + 1, n, "bake"))
    cfg = stadium.config
    save_config(cfg, out / "stadium_crowd.json")
    seconds["bake"] = time.perf_counter() - t

    import numpy as np

    from ..core.crowd import Crowd
    from ..core.recorder import Recorder
    from ..gpu.preview_render import render_preview
    from .show import ShowPlan, StadiumShow

    log(f"simulating and rendering {frames} frames of {cfg.agent_count:,} agents")
    t = time.perf_counter()
    crowd = Crowd(cfg, skinning="gpu")
    # the wave starts just before the stand the camera looks at, so it passes early
    show = StadiumShow(crowd, stadium.seat_angle, stadium.home, cheer="cheer", wave="wave",
                       hits=stadium.hits, hit_frames=stadium.hit_frames,
                       away_reaction="groan", actors=stadium.fan,
                       plan=ShowPlan(wave_start_angle=-np.pi / 2 - 0.4))
    # the frames the preview shows, recorded as they are rendered
    recorder = Recorder(crowd, crowd.frame, crowd.frame + frames - 1) if usd else None

    def before_step(crowd, frame):
        if recorder is not None:
            recorder.capture()                   # the frame just rendered
        show.before_step(crowd, frame)

    camera = section_camera(stadium, aspect=size[0] / size[1])
    preview = render_preview(crowd, out / "frames", frames, size=size, mp4=mp4,
                             before_step=before_step, camera=camera,
                             progress=lambda d, n: _bar(d, n, "render"))
    seconds["simulate_render"] = time.perf_counter() - t
    step_ms = crowd.stats["ms_total"] / max(crowd.stats["steps"], 1)
    summary = {"agents": cfg.agent_count, "streams": len(cfg.streams),
               "uniques": len(cfg.uniques), "characters": len(cfg.skeletons),
               "frames": frames, "ms_per_step": round(step_ms, 3),
               "upload_bytes_per_frame": preview.upload_bytes,
               "renderer": preview.device, **show.summary(),
               "pngs": len(preview.pngs), "mp4": preview.mp4}

    if usd:
        from ..usd.export import export_crowd
        recorder.capture()                       # the last frame
        log("exporting the show to USD")
        t = time.perf_counter()
        res = export_crowd(recorder.finish(), out / "stadium.usdc",
                           progress=lambda stage, d, n: _bar(d, n, stage))
        seconds["usd"] = time.perf_counter() - t
        summary.update(usd=str(res.path), usd_bytes=int(sum(res.files.values())),
                       usd_baked_agents=res.baked_agents)
    seconds["total"] = time.perf_counter() - t0
    summary["seconds"] = {k: round(v, 2) for k, v in seconds.items()}
    with open(out / "summary.json", "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=2)
    return summary
