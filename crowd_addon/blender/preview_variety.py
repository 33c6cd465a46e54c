"""The previewed crowd's variety: its repetition metric and the variety planner.

:func:`measure_repetition` measures the running preview's crowd at its frame
(docs/variety.md) through the scene camera at the render size or, when the scene has
none, through the viewport; :func:`plan_variety` runs the variety planner on its
configuration seen the same way, and :func:`apply_plan` authors the plan in the
Crowd settings (it takes effect at the next bake). The results are kept on the
scene's :class:`.preview.Preview` for the panel.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..core.base.errors import CrowdError
from .preview import running

__all__ = ["measure_repetition", "plan_variety", "apply_plan"]


def _metric_view(scene, region_data, region):
    """``(view_projection, settings, what it is seen through)`` of the repetition
    metric: the scene camera at the render size (:func:`.cameras.metric_view`), or
    the viewport ``region_data``/``region`` when the scene has no camera the renderer
    can draw."""
    from ..core.variety.repetition import RepetitionSettings
    from .cameras import metric_view
    settings = RepetitionSettings(k=scene.crowd.repetition_neighbours)
    camera, settings = metric_view(scene, settings)
    if camera is not None:
        return camera.view_projection, settings, f"scene camera {scene.camera.name!r}"
    if region_data is not None and region is not None:
        vp = np.array(region_data.window_matrix, np.float64) @ np.array(
            region_data.view_matrix, np.float64)
        return vp, dataclasses.replace(settings, width=max(region.width, 1),
                                       height=max(region.height, 1)), "the viewport"
    raise CrowdError("the scene has no camera: measure from a 3D viewport's sidebar")


def measure_repetition(scene, region_data=None, region=None):
    """Measure the previewed crowd's repetition metric at its frame (docs/variety.md)
    through the scene camera or the viewport (:func:`_metric_view`); kept in
    :attr:`.preview.Preview.repetition` for the panel."""
    from ..core.variety.repetition import crowd_repetition
    pv = running(scene)
    vp, settings, seen = _metric_view(scene, region_data, region)
    pv.repetition = crowd_repetition(pv.crowd.view, vp, settings=settings)
    pv.repetition_seen = seen
    return pv.repetition


def plan_variety(scene, region_data=None, region=None, progress=None):
    """Run the variety planner (:mod:`crowd_addon.core.planning.variety_plan`) on the previewed
    crowd's configuration, seen as :func:`measure_repetition` sees it, within the
    settings' *Budget* and *Max Streams* (and *Motion Only*: motion compared alone);
    kept in :attr:`.preview.Preview.plan`.
    ``progress(done, total)`` after each candidate."""
    from ..core.planning.variety_plan import plan_input
    from ..core.planning.variety_plan import plan_variety as plan
    pv = running(scene)
    vp, settings, seen = _metric_view(scene, region_data, region)
    s = scene.crowd
    settings = dataclasses.replace(settings, appearance=not s.plan_motion_only)
    pv.plan = plan(plan_input(pv.crowd.config), vp, s.plan_budget_mb * 1e6, settings,
                   s.plan_max_streams, progress=progress)
    pv.repetition_seen = seen
    return pv.plan


def apply_plan(scene):
    """Author the previewed plan in the scene: its M, each stream's copies and (for a
    Spread plan) Spread offsets on every agent source drawing offsets at random. Takes
    effect at the next bake. Returns a function that puts back what it changed (Apply
    Plan calls it when that bake fails)."""
    pv = running(scene)
    if pv.plan is None:
        raise CrowdError("no plan to apply: Plan Variety first")
    p, s = pv.plan.planned, scene.crowd
    copies = dict(zip(pv.plan.templates, p.template_copies))
    changed = []                                    # (owner, property, value before)

    def put(owner, name, value):
        changed.append((owner, name, getattr(owner, name)))
        setattr(owner, name, value)

    put(s, "max_offset", p.max_offset)
    for c in s.characters:
        for anim in c.streams:
            if anim.name in copies:
                put(anim, "copies", copies[anim.name])
    if p.offset_mode == "SPREAD":
        for src in s.agent_sources:
            if src.offset_mode in ("UNIFORM", "NORMAL"):
                put(src, "offset_mode", "SPREAD")

    def undo():
        for owner, name, value in reversed(changed):
            setattr(owner, name, value)
    return undo
