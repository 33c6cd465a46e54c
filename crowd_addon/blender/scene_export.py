"""A scene's crowd written to USD: the bake-record-write steps every export shares.

:func:`export_steps` is the export, one unit of work per step, all on the caller's
thread: it checks the output and the frame range against the scene, bakes the
scene's Crowd settings (:func:`.scene_config.config_steps`, one action per step),
records the shot once (:class:`crowd_addon.core.shots.recorder.Recorder`, one frame per
step, a crowd that skins nothing) and writes the recording
(:func:`crowd_addon.usd.export_steps`, a layer or a batch of agents per step; all or
nothing: a failure or a cancel leaves no new file and a previous export as it was).
:func:`export_scene` runs it to the end in one call (``crowd export --blend``, the
operator run from a script); the *Export Crowd USD* operator run from the UI
(:mod:`.export`) steps it on a timer and Esc cancels it. The USD modules (``pxr``)
are imported only when an export runs.
"""

from numbers import Integral

from ..core.base.errors import CrowdError
from ..core.variety.repetition import RepetitionSettings
from . import preview, scene_config
from .cameras import metric_view

__all__ = ["check_export", "export_scene", "export_steps"]


def check_export(scene, path, frames) -> tuple:
    """Validate an export of ``scene`` before any baking; returns ``(first, last)``.

    ``path`` must end in .usdc/.usd/.usda in an existing folder this process can
    write (probed with a temporary folder that is removed again); ``frames`` is
    ``(first, last)``, whole numbers, ``scene.frame_start <= first <= last`` (the
    crowd starts at the scene's start frame). Raises CrowdError naming the fault.
    """
    from ..usd.files import ExportFiles

    try:
        first, last = frames
    except (TypeError, ValueError):
        raise CrowdError(f"export: frames must be (first, last), got {frames!r}") from None
    if any(isinstance(f, bool) or not isinstance(f, Integral) for f in (first, last)):
        raise CrowdError(f"export: frames must be whole numbers, got {frames!r}")
    if last < first:
        raise CrowdError(f"export: frame range {first}-{last} is empty (last < first)")
    if first < scene.frame_start:
        raise CrowdError(f"export: frame range {first}-{last} starts before scene "
                         f"{scene.name!r}'s start frame {scene.frame_start}, where the "
                         "crowd starts")
    with ExportFiles(path):             # extension, folder, and a writable folder
        pass
    return int(first), int(last)


def export_scene(scene, path, frames, agents=None, progress=None, on_bake=None,
                 depsgraph=None, layout="instanced", substeps=1, snapshots=None,
                 repetition=RepetitionSettings(), trust_script=False,
                 ignore_script=False, strict=False):
    """Bake ``scene``'s Crowd settings and export the shot to ``path`` in one call
    (:func:`export_steps` run to the end).

    Parameters
    ----------
    scene : a scene with Crowd settings (``scene.crowd``, the extension registered).
    path, agents, layout : as :func:`crowd_addon.usd.export_crowd`; frames : ``(first, last)``
        (:func:`check_export`).
    substeps : samples written per frame (1..16; more than 1 adds sub-frame samples
        for motion blur: ``Crowd(..., substeps=N)``).
    snapshots : optional snapshot folder (``crowd export --snapshots``): the crowd
        starts from its latest snapshot there before ``first`` and leaves one at
        ``last`` (:class:`crowd_addon.core.shots.snapshot_store.ShotSnapshots`).
    progress : optional ``progress(stage, done, total)`` after each recorded frame
        (``"simulate"``) and each step of the writing.
    on_bake : optional ``on_bake(done, total, message)`` before each bake step
        (:func:`.scene_config.config_steps`), then with each note of the bake report
        (``config.bake_report``) as ``warning: ...`` or ``note: ...``.
    strict : the bake report's warnings stop the export before anything is written
        (:class:`~crowd_addon.core.bake.bake_report.BakeWarnings`, ``--strict``).
    depsgraph : evaluated depsgraph for the agent sources (default: the scene's).
    repetition : the repetition metric's settings (None: not measured), measured
        through the scene camera at the scene's render size when it has one
        (:func:`.cameras.metric_view`).
    trust_script : run the scene's crowd script in this export even where it is not
        trusted (``crowd export --trust-scripts``); it trusts nothing after the call.
    ignore_script : leave the scene's crowd script out of this export, trusted or not
        (``crowd export --ignore-scripts``).

    Returns
    -------
    ``(config, result)``: the baked :class:`~crowd_addon.core.authoring.config.CrowdConfig` and
    the :class:`~crowd_addon.usd.export.ExportResult`. Raises CrowdError (nothing
    written then); the scene is not changed. An exception raised by a callback stops
    the export the same way.
    """
    steps = export_steps(scene, path, frames, agents, depsgraph, layout, substeps, snapshots,
                         repetition, trust_script, ignore_script, strict)
    try:
        while True:
            try:
                stage, done, total, message = next(steps)
            except StopIteration as stop:
                return stop.value
            if stage == "bake":
                if on_bake is not None:
                    on_bake(done, total, message)
            elif progress is not None:
                progress(stage, done, total)
    finally:
        steps.close()                   # a raising callback: the export is dropped


def export_steps(scene, path, frames, agents=None, depsgraph=None, layout="instanced",
                 substeps=1, snapshots=None, repetition=RepetitionSettings(),
                 trust_script=False, ignore_script=False, strict=False):
    """The export of :func:`export_scene` as a generator, one unit of work per
    ``next()``: returns ``(config, result)`` (``StopIteration.value``).

    Yields ``(stage, done, total, message)``: stage ``"bake"`` before each bake step
    (``message`` as :func:`.scene_config.config_steps`), ``"simulate"`` after each
    recorded frame, then each step of :func:`crowd_addon.usd.export_steps`; after the
    bake, stage ``"bake"`` once per note of its report (``message``: the note's
    ``line``; ``strict``: then a report with warnings stops it, nothing written)
    (``message`` is the stage). The output and the frame range are checked when it is
    called (CrowdError); a fault found later (the agent count, a missing proxy mesh:
    checked once baked, before recording) is raised by ``next()``.

    Closing the generator before it is done (``close()``, or dropping it) cancels the
    export: close returns once its temporary files are removed; nothing is written, a
    previous export at ``path`` is left as it was, the scene is unchanged.
    """
    from ..core.shots.crowd import check_substeps
    from ..usd.export import check_layout
    frames = check_export(scene, path, frames)
    check_layout(layout)
    return _export_steps(scene, path, frames, agents, depsgraph, layout,
                         check_substeps(substeps), snapshots, repetition, trust_script,
                         ignore_script, strict)


def _export_steps(scene, path, frames, agents, depsgraph, layout, substeps, snapshots,
                  repetition, trust_script, ignore_script=False, strict=False):
    import dataclasses

    from ..core.bake.bake_report import report_of
    from ..core.shots.snapshot_store import ShotSnapshots
    from ..core.shots.driver import FrameDriver
    from ..core.shots.recorder import Recorder
    from ..usd.export import check_export as check_output
    from ..usd.export import export_steps as write_steps

    bake = scene_config.config_steps(scene, depsgraph)
    try:
        while True:
            with preview.suspended():   # the bake's frame_set must not drive a preview
                try:
                    done, total, message = next(bake)
                except StopIteration as stop:
                    config = stop.value
                    break
            yield "bake", done, total, message
    finally:
        bake.close()
    report = report_of(config)          # the bake's, meshes' and LOD levels' notes
    for note in report:
        yield "bake", 1, 1, note.line
    report.check_strict(strict)
    check_output(config, path, agents, layout)
    crowd, note = scene_config.build_crowd(scene, config, substeps=substeps,
                                           trust_script=trust_script,
                                           ignore_script=ignore_script)
    if note:
        yield "bake", 1, 1, note
    snaps = ShotSnapshots(snapshots, crowd, frames[0]) if snapshots else None
    recorder = Recorder(crowd, *frames)
    driver = FrameDriver(crowd, consumers=[recorder.capture])
    total = recorder.last - crowd.frame
    for done in range(1, total + 1):
        driver.step()
        yield "simulate", done, total, "simulate"
    if snaps is not None:
        snaps.recorded()
    camera, repetition = metric_view(scene, repetition)
    writing = write_steps(recorder.finish(driver.seconds), path, agents, layout, camera,
                          repetition)
    try:
        while True:
            try:
                stage, done, total = next(writing)
            except StopIteration as stop:
                if snaps is None:
                    return config, stop.value
                return config, dataclasses.replace(stop.value, started_from=snaps.started_from,
                                                   snapshot=snaps.keep())
            yield stage, done, total, stage
    finally:
        writing.close()                 # a cancel: its temporary files are removed
