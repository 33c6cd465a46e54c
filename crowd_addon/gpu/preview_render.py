"""Offline preview: a saved crowd rendered headless to a PNG sequence and an MP4.

:func:`render_preview` steps a core ``Crowd`` frame by frame, draws it with one of
the two headless backends (:func:`~.backends.make_renderer`: moderngl on EGL, or
Blender's ``gpu`` module) through a fixed camera that frames the
whole crowd (:func:`~.camera.frame_crowd`), writes ``frame_<F>.png`` per frame
(``F`` the crowd frame, at least four digits) and, when asked, ``preview.mp4``
(H.264 through ``imageio-ffmpeg``, at the crowd's fps). The ``crowd preview``
command (:mod:`crowd_addon.commands.preview`) is a thin wrapper around it.
"""

from __future__ import annotations

import dataclasses
import os
import re
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.shots.crowd import Crowd
from ..core.shots.driver import FrameDriver
from ..core.base.errors import CrowdError
from ..core.base.files import output_dir, remove_stale_staging, staging, writable_dir
from ..core.variety.repetition import RepetitionSettings, combine, crowd_repetition, measure_frames
from .backends import BACKENDS, make_renderer
from ..core.base.camera import frame_crowd
from .png import write_png

__all__ = ["PreviewResult", "render_preview", "BACKENDS", "MAX_SIZE"]

#: Largest image side accepted, in pixels (the usual GL_MAX_TEXTURE_SIZE).
MAX_SIZE = 16384
_PNG_LEVEL = 3                       # zlib level: near level 6 in size, much faster


@dataclass
class PreviewResult:
    """What :func:`render_preview` wrote.

    ``frames``: (first, last) crowd frames; ``pngs``: paths in order; ``mp4``: path
    or None; ``size``: (width, height) in pixels; ``device``: the renderer the GL
    reports; ``seconds``: wall time per stage (``simulate``, ``sync``, ``render``,
    ``write``, ``total``; ``write`` is what the run waited for the frames' encoding,
    which runs in a thread beside the next frame's drawing, and ``write_beside`` that
    thread's wall time, waits for the GIL included); ``upload_bytes``: pose and instance bytes sent per frame
    (median); ``repetition``: the repetition metric through the camera at the frames'
    size (:meth:`~crowd_addon.core.variety.repetition.Repetition.as_dict`; None when not
    measured).
    """

    frames: tuple
    pngs: list
    mp4: str | None
    size: tuple
    agents: int
    backend: str
    device: str
    upload_bytes: int = 0
    seconds: dict = field(default_factory=dict)
    repetition: dict | None = None


def check_size(size, mp4: bool) -> None:
    """A CrowdError unless ``size`` (w, h) can be drawn, and encoded when ``mp4``."""
    w, h = size
    if not (1 <= w <= MAX_SIZE and 1 <= h <= MAX_SIZE):
        raise CrowdError(f"image size {w} x {h} must be 1..{MAX_SIZE} pixels a side")
    if mp4 and (w % 2 or h % 2):
        raise CrowdError(f"an MP4 (H.264, yuv420p) needs an even width and height, got "
                         f"{w} x {h}")


def _check(config, out_dir, frames, size, mp4, backend) -> Path:
    if backend not in BACKENDS:
        raise CrowdError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
    if frames < 1:
        raise CrowdError(f"frames must be at least 1, got {frames}")
    check_size(size, mp4)
    if config.agent_count == 0:
        raise CrowdError("the crowd has no agents to draw")
    if not config.meshes:
        raise CrowdError("the crowd has no proxy mesh to draw its agents with "
                         "(CrowdConfig.add_mesh)")
    return writable_dir(out_dir)


#: the frames a run writes into its folder (``frame_<F>.png``): a later run replaces them
FRAME_NAME = re.compile(r"frame_-?\d+\.png")


def replace_frames(out: Path, staged: Path) -> None:
    """Move the files of a finished run (its frames, its MP4) from ``staged`` into
    ``out``, then remove the frames of the run before that this one did not write (a
    folder holds one run's sequence). Other files of ``out`` stay, an earlier MP4 too
    when this run made none."""
    names = sorted(os.listdir(staged))
    for name in names:
        os.replace(staged / name, out / name)
    staged.rmdir()
    for name in set(os.listdir(out)) - set(names):
        if FRAME_NAME.fullmatch(name) and (out / name).is_file():
            (out / name).unlink()


def _missing_folders(path: Path) -> list:
    """The folders of ``path`` that do not exist yet, deepest first."""
    missing = []
    while not path.exists() and path.parent != path:
        missing.append(path)
        path = path.parent
    return missing


def _mp4_writer(path, size, fps):
    try:
        import imageio_ffmpeg
    except ImportError:
        raise CrowdError("--mp4 needs the imageio-ffmpeg package (pip install "
                         "imageio-ffmpeg)") from None
    writer = imageio_ffmpeg.write_frames(str(path), size, fps=fps, codec="libx264",
                                         pix_fmt_out="yuv420p", macro_block_size=2,
                                         ffmpeg_log_level="error")
    writer.send(None)
    return writer


def render_preview(config, out_dir, frames: int, start: int | None = None,
                   size=(960, 540), mp4: bool = False, backend: str = "moderngl",
                   progress=None, before_step=None, camera=None, scene=None,
                   light=None, samples: int = 4, on_image=None,
                   shadows: bool | None = None,
                   repetition=RepetitionSettings(), lod: bool = True) -> PreviewResult:
    """Render ``frames`` frames of ``config`` (a ``CrowdConfig``) from ``start``
    (default: its start frame; frame ``start`` of the shot, the crowd run from its
    start frame, or from its nearest kept snapshot, through everything the show did
    before it) into ``out_dir``; ``progress(done, total)`` is called
    after each frame. Raises ``CrowdError`` on bad input before writing anything.

    ``config`` may also be a built ``Crowd`` (rendered from where it is, e.g. with GPU
    transitions); ``before_step(crowd, frame)`` is called before each step with the
    frame about to be evaluated (the simulation driving the crowd); ``camera``
    replaces the framing camera. ``scene``: a :class:`~.scene_geometry.SceneGeometry`
    drawn around the crowd with the same camera, light and depth; ``light``: the
    renderers' ``(x, y, z, ambient)`` (None: their default); ``samples``: anti-aliasing
    of the moderngl backend, samples a pixel (a k x k supersampling grid; 0: none); ``on_image(frame, image)`` is
    given each frame's ``(H, W, 3)`` uint8 image (e.g. a contact sheet); ``shadows``:
    the sun's shadows (None: with a scene); ``repetition``: the repetition metric's
    settings (their ``frames`` spread over the run, measured as they are shown; the
    size is the frames'), None not to measure it; ``lod``: False draws every agent
    with its full mesh (``--lod off``, the judge of the levels)."""
    w, h = (int(v) for v in size)
    crowd = config if isinstance(config, Crowd) else None
    config = crowd.view.config if crowd is not None else config
    out = _check(config, out_dir, int(frames), (w, h), mp4, backend)
    t0 = time.perf_counter()
    seconds = dict.fromkeys(("simulate", "sync", "render", "write"), 0.0)
    if start is not None and int(start) < config.start_frame:
        raise CrowdError(f"start frame {int(start)} is before the shot's first frame "
                         f"{config.start_frame}")
    crowd = crowd or Crowd(config, skinning="gpu")
    driver = FrameDriver(crowd, before_step)
    if start is not None:           # frame F of the shot: run through the cues before it
        driver.seek(int(start))
    seconds["simulate"] += time.perf_counter() - t0
    options = {} if light is None else {"light": light}
    options["shadows"] = scene is not None if shadows is None else bool(shadows)
    options["lod"] = bool(lod)
    if backend == "moderngl":
        options["samples"] = int(samples)
    renderer = make_renderer(crowd.view, backend, (w, h), **options)
    device = renderer.device
    camera = camera or frame_crowd(crowd, aspect=w / h)
    if repetition is not None:
        repetition = dataclasses.replace(repetition, width=w, height=h)
        measure = set(measure_frames(crowd.view.frame, crowd.view.frame + int(frames) - 1,
                                     repetition.frames))
        measured = []
    mp4_path = out / "preview.mp4" if mp4 else None
    # the frames and the MP4 go to a folder of their own until the run is done, so a
    # run that fails leaves the files of the run before as they were
    staged = staging(out, "frames.partial")
    partial = staged / ".preview.partial.mp4"
    made = _missing_folders(out)
    pngs, uploads, first, writer, done = [], [], crowd.view.frame, None, False
    # a frame's PNG, MP4 frame and on_image run in a thread while the next frame is
    # simulated and drawn (zlib, file and pipe writes release the GIL): one frame in
    # flight, in order. The run waited ~0.06 s a frame for them, now ~0.02-0.04 (65k
    # stadium, llvmpipe: moderngl holds the GIL through its calls, so the thread runs
    # mostly in the main thread's Python between them)
    pool, pending = ThreadPoolExecutor(1, thread_name_prefix="crowd-encode"), None
    seconds["write_beside"] = 0.0

    def encode(frame, image):
        t = time.perf_counter()
        path = str(write_png(staged / f"frame_{frame:04d}.png", image, _PNG_LEVEL))
        if writer is not None:
            writer.send(image)
        if on_image is not None:
            on_image(frame, image)
        return path, time.perf_counter() - t

    def collect():
        path, dt = pending.result()                 # waits; re-raises its error
        pngs.append(path)
        seconds["write_beside"] += dt
    try:
        renderer.set_scene(scene)
        output_dir(out)
        remove_stale_staging(out, "frames.partial")     # runs killed outright
        staged.mkdir()
        writer = _mp4_writer(partial, (w, h), config.fps) if mp4 else None
        for i in range(int(frames)):
            t = time.perf_counter()
            if i:
                driver.step()
            if repetition is not None and crowd.view.frame in measure:
                measured.append(crowd_repetition(crowd.view, camera.view_projection,
                                                 settings=repetition))
            t1 = time.perf_counter()
            uploads.append(renderer.sync().upload_bytes)
            t2 = time.perf_counter()
            renderer.render(camera)
            image = np.ascontiguousarray(renderer.read_image()[..., :3])
            t3 = time.perf_counter()
            if pending is not None:
                collect()
            pending = pool.submit(encode, crowd.view.frame, image)
            t4 = time.perf_counter()
            for k, dt in zip(("simulate", "sync", "render", "write"),
                             (t1 - t, t2 - t1, t3 - t2, t4 - t3)):
                seconds[k] += dt
            if progress is not None:
                progress(i + 1, int(frames))
        t = time.perf_counter()
        if pending is not None:
            collect()
            pending = None
        seconds["write"] += time.perf_counter() - t
        if writer is not None:
            t = time.perf_counter()
            writer.close()
            writer = None
            os.replace(partial, staged / mp4_path.name)
            seconds["write"] += time.perf_counter() - t
        replace_frames(out, staged)
        pngs = [str(out / os.path.basename(p)) for p in pngs]
        done = True
    except OSError as e:
        raise CrowdError(f"output folder {out}: cannot write "
                         f"{os.path.basename(e.filename or '') or 'a frame'}: "
                         f"{e.strerror or e}") from None
    finally:
        if pending is not None:           # the frame in flight: done before cleaning up
            try:
                collect()
            except Exception:             # noqa: BLE001 - the error in hand is reported
                pass
        pool.shutdown(wait=True)
        if writer is not None:
            writer.close()
        renderer.release()
        if not done:                  # nothing half-written: this run's frames go
            shutil.rmtree(staged, ignore_errors=True)
            for folder in made:
                try:
                    folder.rmdir()
                except OSError:
                    break
    seconds["total"] = time.perf_counter() - t0
    return PreviewResult((first, crowd.view.frame), pngs, None if mp4_path is None else
                         str(mp4_path), (w, h), crowd.view.agent_count, backend, device,
                         int(np.median(uploads)), seconds,
                         None if repetition is None else combine(measured).as_dict())
