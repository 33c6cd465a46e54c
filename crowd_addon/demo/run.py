"""``crowd demo``: the main job, end to end.

1. build the stadium scene (``sample_scenes/build_stadium.py``, in a child process
   because it resets Blender's session) with ``--agents`` seats;
2. open it, author its crowd settings and bake its actions through the extension's
   own code (:mod:`crowd_addon.blender.stadium`), save the .blend and the crowd
   configuration next to it: both hold everything the demo runs, the two characters
   with its show (goal, Mexican wave, hits: scene data, ``scene.crowd.show``) and the
   camera the frames are rendered through, the scene's frame range set to the run;
3. run the crowd built from that configuration (it runs its show itself: no Python in
   the loop) and record it (:mod:`crowd_addon.core.shots.recording`), then
4. export that recording to ``stadium.usdc`` (UsdSkel) in a process of its own (the
   same show, not simulated again; its repetition metric, docs/variety.md, measured
   through the demo's camera) while this process runs the crowd again and renders
   preview frames headless with the GPU path as it runs (the claps are the clap
   action's event tags, counted by the crowd), in the stadium's own geometry and sun
   (PNG, MP4 when imageio-ffmpeg is there, and ``contact_sheet.png``: six frames, the
   show's beats among them). llvmpipe draws a crowd's vertices on one thread, so the
   export takes the other core's idle time rather than following the frames;
5. print a summary and write it as ``summary.json`` (``repetition``: the metric).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from importlib import resources
from pathlib import Path

from ..core.authoring.config_io import save_config
from ..core.base.errors import CrowdError
from ..core.base.files import (folders_made, remove_stale_staging, staging, writable_dir,
                                write_atomic)
from ..core.variety.repetition import RepetitionSettings, recording_repetition
from .usd_beside import UsdExport, usd_summary

__all__ = ["run_demo", "show_summary", "SHEET_FRAMES"]

#: frames on the demo's contact sheet (``contact_sheet.png``), spread over the run
SHEET_FRAMES = 6

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


def _build_scene(path: Path, seats: int, log, final: Path):
    """The sample stadium with ``seats`` seats saved in ``path`` (to be ``final``)."""
    if SAMPLE_BUILDER is None or not SAMPLE_BUILDER.is_file():
        raise CrowdError(f"the stadium builder {SAMPLE_BUILDER or 'sample_scenes'} is missing")
    log(f"building the stadium with {seats:,} seats -> {final}")
    run = subprocess.run([sys.executable, str(SAMPLE_BUILDER), "--out", str(path),
                          "--seats", str(seats), "--quiet"], capture_output=True, text=True)
    if run.returncode != 0:
        raise CrowdError(f"building the stadium failed:\n{run.stderr.strip()[-2000:]}")


def show_summary(crowd) -> dict:
    """What the show did, from the crowd's own counts: the cues' requests
    (``crowd.show.stats``), the transitions served (``crowd.stats``) and the events
    fired (``crowd.events``); ``cues``: per cue its frame, the agents it selects and
    what became of its requests."""
    from ..blender.stadium import CUES

    stats = crowd.show.stats if crowd.show is not None else {}
    cues = crowd.show.describe() if crowd.show is not None else []

    def total(key, prefix=""):
        return int(sum(s[key] for name, s in stats.items() if name.startswith(prefix)))

    switched = total("switched")
    requested, queued, cut = total("agents") - switched, total("queued"), total("cut")
    fired, calls = crowd.events.fired, crowd.events.calls
    return {"switched_with_streams": switched, "streams_switched": total("streams"),
            "transitions_requested": requested, "started_at_once": requested - queued - cut,
            "queued": queued, "cut": cut, "skipped": total("skipped"),
            "transitions_served": int(crowd.stats["transitions_served"]),
            "cheering": total("agents", CUES["goal_home"]),
            "wave_agents": total("agents", CUES["wave"]),
            "hits": total("agents", CUES["hit"] + " "),
            "clap_agent_events": int(fired["clap"]), "clap_calls": int(calls["clap"]),
            "events_fired": int(sum(fired.values())),
            "cues": [{"name": c["name"], "frame": c["frame"], "action": c["action"],
                      "target": c["target"], "selected": c["agents"], **stats[c["name"]]}
                     for c in cues]}


def _beat_frames(crowd, first: int, last: int) -> dict:
    """The contact sheet's frames and their captions: the first, the wave in two
    places (as it starts at the camera's stand, and just before the goal), the goal's
    cheer once every fan has followed its stream (M frames after the cue, within its
    hold), the hits and the last (beats after the run left out), topped up with frames
    spread over the run (no caption) to :data:`SHEET_FRAMES`."""
    from ..blender.stadium import CUES
    from ..gpu.contact_sheet import sheet_frames

    at = {c["name"]: c["frame"] for c in crowd.show.describe()} if crowd.show else {}
    goal = CUES["goal_home"]
    rippled = crowd.config.max_offset
    if goal in at:
        rippled = min(rippled, max(12, crowd.config.show.cue(goal).action.hold - 6))
    before_goal = at[goal] - at[CUES["wave"]] - 1 if goal in at and CUES["wave"] in at \
        else 24
    beats = [(CUES["wave"], 8, "the wave"),
             (CUES["wave"], max(before_goal, 16), "the wave, before the goal"),
             (goal, rippled, f"goal +{rippled}: the home fans up"),
             (f"{CUES['hit']} 1", 12, "fans hit by the ball")]
    picked = {first: "start", last: "end"}
    picked.update({at[name] + k: label for name, k, label in beats
                   if name in at and first <= at[name] + k <= last})
    for f in sheet_frames(first, last, SHEET_FRAMES):
        if len(picked) >= SHEET_FRAMES:
            break
        picked.setdefault(f, "")
    return picked


def run_demo(out_dir, agents: int = 2000, frames: int = 240, size=(960, 540),
             mp4: bool = True, usd: bool = True, log=None, layout: str = "instanced") -> dict:
    """Run the stadium demo into ``out_dir``; returns the summary dict. ``layout``: of
    ``stadium.usdc`` (``"blender"``: the stage Blender's own USD importer plays,
    docs/usd_export.md)."""
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    if agents < 10:
        raise CrowdError(f"--agents must be at least 10, got {agents}")
    if frames < 1:
        raise CrowdError(f"--frames must be at least 1, got {frames}")
    from ..core.authoring.config import USD_LAYOUTS
    if layout not in USD_LAYOUTS:
        raise CrowdError(f"--layout must be one of {', '.join(USD_LAYOUTS)}, got {layout!r}")
    from ..gpu.preview_render import check_size
    check_size(size, mp4)                  # before the stadium is built, not after
    out = writable_dir(out_dir)             # checked here, made below
    check_folder_is_the_demos(out)
    if not usd and (out / "stadium.usdc").exists():
        log(f"--no-usd: {out / 'stadium.usdc'} is left as the earlier run wrote it")
    with folders_made(out):                 # a folder made for a run that fails goes
        return _run_into(out, agents, frames, size, mp4, usd, log, layout)


def _run_into(out, agents, frames, size, mp4, usd, log, layout) -> dict:
    """:func:`run_demo` into the folder ``out``, checked to be the demo's."""
    blend = out / "stadium.blend"
    # the new .blend, frames and contact sheet are made under other names, the stage is
    # written but not committed: they take the old ones' places (and the configuration
    # is saved) only when the run is done, so a run that fails leaves the earlier
    # run's as they were
    names = {"stadium.blend": ("stadium.partial", ".blend"), "frames": ("frames.run", ""),
             "contact_sheet.png": ("contact_sheet.partial", ".png")}
    for stem, suffix in names.values():             # left by runs killed outright
        remove_stale_staging(out, stem, suffix)
    staged = {name: staging(out, stem, suffix) for name, (stem, suffix) in names.items()}
    export = []                 # the USD export, once started: stopped if the run fails
    try:
        summary, cfg = _run(out, staged, agents, frames, size, mp4, usd, log, layout, export)
        summary["blend"] = str(blend)
        summary["blend_sha256"] = _sha256(staged["stadium.blend"])
        # the configuration too only once the run is done (written atomically, with
        # its arrays), then the stage, then the staged files take their places and the
        # summary comes last
        save_config(cfg, out / "stadium_crowd.json")
        if export:
            usd_summary(summary, export[0].commit(), layout)
        os.replace(staged["stadium.blend"], blend)
        os.replace(staged["contact_sheet.png"], out / "contact_sheet.png")
        from ..gpu.preview_render import replace_frames
        (out / "frames").mkdir(exist_ok=True)
        replace_frames(out / "frames", staged["frames"])     # the user's files there stay
    except BaseException:       # Ctrl-C and SIGTERM too: the export does not run on
        if export:
            export[0].stop()
        raise
    finally:
        for path in staged.values():
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
    text = json.dumps(summary, indent=2).encode("utf-8")
    write_atomic(out / "summary.json", lambda f: f.write(text), "the demo's summary")
    return summary


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


#: what a demo run leaves in its folder (``frames/`` holds its frames and MP4 among any
#: files of the user's): a re-run replaces these and nothing else
DEMO_OUTPUTS = ("stadium.blend", "summary.json", "contact_sheet.png", "frames", "stadium.usdc",
                "stadium.layers", "stadium_crowd.json", "stadium_crowd.npz")


def check_folder_is_the_demos(out: Path) -> None:
    """A CrowdError, before anything is written, when ``out`` holds files the demo
    would replace that the last demo run into ``out`` did not leave as they are:
    names of :data:`DEMO_OUTPUTS` without the ``summary.json`` of a demo run (someone's
    own folder, or a run of an older version), or a ``stadium.blend`` other than the
    one that run left (its summary keeps its SHA-256: saved from Blender since). The
    demo would replace them, and the work would be lost."""
    present = [n for n in DEMO_OUTPUTS if (out / n).exists()]
    if not present:
        return
    try:
        with open(out / "summary.json", encoding="utf-8") as f:
            recorded = json.load(f).get("blend_sha256")
    except (OSError, ValueError, AttributeError):
        recorded = None
    blend = out / "stadium.blend"
    if blend.exists() and recorded != _sha256(blend):
        raise CrowdError(f"{blend} is not the file the last demo run left there (saved "
                         f"from Blender since, or not the demo's): the demo would replace "
                         f"it with a new stadium. Move it away or run the demo with another "
                         f"--out; to render it as it is, use crowd preview --blend {blend}")
    if recorded is None:
        raise CrowdError(f"{out} holds {', '.join(present)}, which no demo run left there "
                         f"(there is no demo summary.json beside them): the demo would "
                         f"replace them. Run it with another --out")


def _run(out, staged, agents, frames, size, mp4, usd, log, layout, export) -> tuple:
    """The demo's work into ``out``, its stadium built and authored, its frames and
    contact sheet written at the ``staged`` paths of ``stadium.blend``, ``frames`` and
    ``contact_sheet.png``, its USD export (appended to ``export``) written and waiting
    to commit; returns the summary (naming the final paths, without the .blend's digest
    and the stage's figures, which the caller adds) and the crowd's configuration
    (which the caller saves once the run is done)."""
    blend = staged["stadium.blend"]
    t0 = time.perf_counter()
    seconds = {}
    _build_scene(blend, agents, log, out / "stadium.blend")
    seconds["build_scene"] = time.perf_counter() - t0

    t = time.perf_counter()
    from ..blender.stadium import author_stadium
    log("authoring the crowd and its show, baking its actions")
    stadium = author_stadium(blend, frames, size,
                             progress=lambda d, n, m: _bar(d + 1, n, "bake"))
    cfg = stadium.config
    seconds["bake"] = time.perf_counter() - t
    if stadium.muted:
        log(f"beats after the last of {frames} frames, muted: {', '.join(stadium.muted)}")

    from ..core.shots.crowd import Crowd
    from ..core.shots.recorder import record
    from ..gpu.contact_sheet import ContactSheet
    from ..gpu.png import write_png
    from ..gpu.preview_render import render_preview

    # the frames the preview shows, recorded first: the USD export reads the recording
    t = time.perf_counter()
    first = Crowd(cfg)                           # it runs its show (cfg.show) itself
    shot = record(first, first.frame, first.frame + frames - 1)
    del first
    seconds["record"] = time.perf_counter() - t
    # the repetition metric through the demo's camera, at the frames' size
    measure = RepetitionSettings(width=size[0], height=size[1])
    if usd:
        export.append(UsdExport(shot, out / "stadium.usdc", stadium.camera, measure, layout))
    log(f"simulating and rendering {frames} frames of {cfg.agent_count:,} agents"
        + (", exporting USD beside them" if usd else ""))
    t = time.perf_counter()
    crowd = Crowd(cfg, skinning="gpu")      # the same show, run again to be drawn
    # the frames at their own size: at 65,000 fans a fan is ~10 px tall, and halved
    # the goal's standing home end read as a change of texture
    beats = _beat_frames(crowd, crowd.frame, crowd.frame + frames - 1)
    sheet = ContactSheet(sorted(beats), scale=1, labels=beats)
    preview = render_preview(crowd, staged["frames"], frames, size=size, mp4=mp4,
                             camera=stadium.camera, scene=stadium.scene,
                             light=stadium.light, repetition=None,   # measured below
                             progress=lambda d, n: _bar(d, n, "render"),
                             on_image=sheet.offer)
    write_png(staged["contact_sheet.png"], sheet.image())
    seconds["simulate_render"] = time.perf_counter() - t
    for stage, key in (("simulate", "simulate"), ("sync", "upload"), ("render", "draw"),
                       ("write", "encode")):
        seconds[key] = preview.seconds.get(stage, 0.0)
    step_ms = crowd.stats["ms_total"] / max(crowd.stats["steps"], 1)
    summary = {"agents": cfg.agent_count, "streams": len(cfg.streams),
               "uniques": len(cfg.uniques), "characters": len(cfg.skeletons),
               "frames": frames, "ms_per_step": round(step_ms, 3),
               "upload_bytes_per_frame": preview.upload_bytes,
               "renderer": preview.device, **show_summary(crowd),
               "muted_cues": list(stadium.muted),
               "pngs": len(preview.pngs),
               "mp4": preview.mp4 and str(out / "frames" / os.path.basename(preview.mp4)),
               "contact_sheet": str(out / "contact_sheet.png"),
               "contact_sheet_frames": sorted(sheet.frames),
               "contact_sheet_labels": {str(f): sheet.labels[f]
                                        for f in sorted(sheet.frames)}}
    t = time.perf_counter()
    if export:
        log("waiting for the USD export" if export[0].running else "the USD export is done")
        export[0].written()
        seconds["usd"] = time.perf_counter() - t          # what the frames did not hide
    else:
        summary["repetition"] = recording_repetition(
            shot, stadium.camera.view_projection, settings=measure).as_dict()
        seconds["repetition"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    summary["seconds"] = {k: round(v, 2) for k, v in seconds.items()}
    return summary, cfg
