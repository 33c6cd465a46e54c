"""``scene.crowd.show`` -> a core :class:`~crowd_addon.core.authoring.show.Show`.

Selections are resolved here, once, against the agent sources the crowd was placed
from (:class:`.agents.PlacedSource`: which agent ids each source made and from which
vertices): a source, a point attribute or vertex group of its mesh, an object's
bounding box, a random fraction. Animated parameters are sampled over the scene's
frame range from their F-curves (``FCurve.evaluate``, Blender's own evaluation) or,
when a driver sets them, by stepping the scene through the frames. Every error names
the cue, reaction or parameter and changes nothing in the scene.
"""

from __future__ import annotations

import numpy as np

from ..core.base.errors import CrowdError
from ..core.authoring.selections import select_fraction, select_inside, select_value
from ..core.authoring.show import Action, Cue, Reaction, Show, Sweep, Track
from .action_data import action_fcurves
from .agents import _attribute, _group_members
from .compat import action_slots, assigned_slot

__all__ = ["show_from_scene", "selected_agents", "parameter_values", "show_fingerprint",
           "look_targets_from_scene", "object_positions"]

_SELECT_KINDS = ("FLOAT", "INT", "INT8")


def show_from_scene(scene, depsgraph, cfg, placed) -> Show:
    """The scene's show for the crowd ``cfg`` placed from ``placed`` sources."""
    show = scene.crowd.show
    first, last = scene.frame_start, scene.frame_end
    cues = tuple(_cue(c, scene, depsgraph, cfg, placed, first, last) for c in show.cues)
    reactions = tuple(_reaction(r) for r in show.reactions)
    tracks = tuple(_track(p, scene) for p in show.parameters)
    try:
        return Show(cues, reactions, tracks)
    except CrowdError as e:
        raise CrowdError(f"scene {scene.name!r} show: {e}") from None


# ------------------------------------------------------------------------- cues
def _cue(c, scene, depsgraph, cfg, placed, first, last) -> Cue:
    what = f"cue {c.name!r}"
    if not c.name.strip():
        raise CrowdError("a cue has no name (Crowd > Show > Cues)")
    if c.action == "LOOK" and not c.mute and c.target not in scene.crowd.show.look_targets:
        raise CrowdError(f"{what}: unknown look target {c.target!r} (look targets: "
                         f"{[t.name for t in scene.crowd.show.look_targets]}; Crowd > Show > "
                         "Look Targets)")
    if c.timeline and not c.mute and not first < c.frame <= last:
        raise CrowdError(f"{what}: frame {c.frame} is outside the scene's frames "
                         f"{first + 1}..{last} (the crowd starts at frame {first}; a cue "
                         "starts from the next)")
    try:
        action = Action(
            c.action.lower(), c.target, duration=c.duration,
            offset={"KEEP": "keep", "RANDOM": "random"}.get(c.offset_mode, c.offset),
            when_full=None if c.when_full == "DEFAULT" else c.when_full.lower(),
            hold=c.hold, name=c.parameter, value=c.set_value,
            **({"trigger": c.switch_trigger, "release": c.release_trigger}
               if c.action in ("STREAM", "UNIQUE") else {}))
        agents = selected_agents(c, depsgraph, cfg, placed) if action.selects_agents else None
        sweep = None
        if c.timing == "SWEEP":
            centre = (0.0, 0.0, 0.0) if c.sweep_centre is None else \
                tuple(c.sweep_centre.matrix_world.translation)
            sweep = Sweep(centre, c.sweep_mode.lower(), c.sweep_speed, c.sweep_start,
                          c.sweep_laps)
        return Cue(c.name, c.frame, action, agents,
                   spread=c.spread if c.timing == "SPREAD" else 0, sweep=sweep, seed=c.seed,
                   interrupt=c.interrupt, muted=c.mute, timeline=c.timeline)
    except CrowdError as e:
        msg = str(e)
        raise CrowdError(msg if msg.startswith(what) else f"{what}: {msg}") from None


def selected_agents(c, depsgraph, cfg, placed):
    """Agent ids a cue selects (None: every agent), or a CrowdError naming why not."""
    if not c.source and c.select == "ALL" and c.fraction >= 1.0:
        return None
    sources = [p for p in placed if not c.source or p.name == c.source]
    if c.source and not sources:
        raise CrowdError(f"no enabled agent source is named {c.source!r} (sources: "
                         f"{[p.name for p in placed]})")
    picked = []
    for p in sources:
        ids = np.arange(p.first, p.first + p.count, dtype=np.int64)
        if c.select in ("ATTRIBUTE", "GROUP"):
            ids = ids[_on_points(c, p, depsgraph)]
        elif c.select == "INSIDE":
            if c.bounds is None:
                raise CrowdError("select 'Inside Object' needs an object")
            box = np.array([tuple(v) for v in c.bounds.bound_box], np.float64)
            inv = np.array(c.bounds.matrix_world.inverted(), np.float64)
            ids = ids[select_inside(cfg.agent_position[ids], inv, box.min(0), box.max(0))]
        picked.append(ids)
    ids = np.concatenate(picked) if picked else np.zeros(0, np.int64)
    if c.fraction < 1.0:
        ids = select_fraction(ids, c.fraction, c.seed)
    if ids.size == 0:
        raise CrowdError("the selection is empty (no agent to move)")
    return ids


def _on_points(c, p, depsgraph) -> np.ndarray:
    """(count,) bool: the source's agents whose vertex the attribute or group selects."""
    import bpy
    obj = bpy.data.objects.get(p.object_name)
    if obj is None or p.rows is None:
        raise CrowdError(f"agent source {p.name!r}: attributes and vertex groups are read "
                         "from mesh vertices ('Vertices' or 'Vertex Group' sources)")
    mesh = obj.evaluated_get(depsgraph).data
    what = f"agent source {p.name!r}"
    if c.select == "GROUP":
        return np.isin(p.rows, _group_members(obj, mesh, c.vertex_group, what))
    values = _attribute(mesh, c.attribute, _SELECT_KINDS, what, obj)
    return np.isin(p.rows, select_value(values, c.op, c.compare))


# ----------------------------------------------------------------- look targets
def look_targets_from_scene(scene) -> dict:
    """``{name: LookTarget}`` of the show's look targets: each object's world position
    at every frame ``frame_start .. frame_end`` (one sample when nothing animates it),
    all targets sampled in one pass over the frames (:func:`object_positions`)."""
    from ..core.runtime.look_at import LookTarget
    items = list(scene.crowd.show.look_targets)
    seen = set()
    for t in items:
        what = f"look target {t.name!r}"
        if not t.name.strip():
            raise CrowdError("a look target has no name (Crowd > Show > Look Targets)")
        if t.name in seen:
            raise CrowdError(f"two look targets are named {t.name!r}")
        seen.add(t.name)
        if t.object is None:
            raise CrowdError(f"{what}: no object chosen (Crowd > Show > Look Targets)")
    paths = object_positions(scene, [t.object for t in items])
    out = {}
    for t, path in zip(items, paths):
        try:
            out[t.name] = LookTarget(t.name, scene.frame_start, path, t.smoothing)
        except CrowdError as e:
            raise CrowdError(str(e)) from None
    return out


def _animated(obj) -> bool:
    """Whether anything may move ``obj`` over time: an action, drivers or NLA tracks on
    it or on a parent, or a constraint (whose target may move)."""
    while obj is not None:
        ad = obj.animation_data
        if ad is not None and (ad.action is not None or len(ad.drivers) or
                               len(ad.nla_tracks)):
            return True
        if len(obj.constraints):
            return True
        obj = obj.parent
    return False


def object_positions(scene, objects) -> list:
    """Per object a (T, 3) array of its world position (``matrix_world.translation``)
    at the scene's frames ``frame_start .. frame_end``, evaluated by Blender
    (``scene.frame_set``: parents, constraints, drivers), or (1, 3) for an object
    nothing animates. One pass over the frames serves every animated object; the
    scene's frame is restored after."""
    out = [np.array([tuple(o.matrix_world.translation)], np.float64) for o in objects]
    moving = [i for i, o in enumerate(objects) if _animated(o)]
    if not moving:
        return out
    frames = range(scene.frame_start, scene.frame_end + 1)
    paths = np.empty((len(moving), len(frames), 3), np.float64)
    keep = scene.frame_current, scene.frame_subframe
    try:
        for k, f in enumerate(frames):
            scene.frame_set(f)
            for j, i in enumerate(moving):
                paths[j, k] = tuple(objects[i].matrix_world.translation)
    finally:
        scene.frame_set(keep[0], subframe=keep[1])
    for j, i in enumerate(moving):
        out[i] = paths[j]
    return out


def _object_keys(obj) -> tuple:
    """Every keyframe and driver of ``obj`` and its parents (what a look target's sampled
    path depends on besides the settings), with the parents' names."""
    out = []
    while obj is not None:
        ad = obj.animation_data
        keys = ()
        slot = None if ad is None else assigned_slot(ad)
        if ad is not None and ad.action is not None and (
                slot is not None or action_slots(ad.action) is None):
            keys = tuple((fc.data_path, fc.array_index, tuple(
                (tuple(k.co), tuple(k.handle_left), tuple(k.handle_right), k.interpolation)
                for k in fc.keyframe_points))
                for fc in action_fcurves(ad.action, slot))
        drivers = () if ad is None else tuple(
            (d.data_path, d.driver.expression) for d in ad.drivers)
        out.append((obj.name, keys, drivers, len(obj.constraints)))
        obj = obj.parent
    return tuple(out)


# -------------------------------------------------------------------- reactions
def _reaction(r) -> Reaction:
    if not r.name.strip():
        raise CrowdError("a reaction has no name (Crowd > Show > Reactions)")
    try:
        return Reaction(r.name, r.event, r.cue, r.source, r.radius, r.mute)
    except CrowdError as e:
        raise CrowdError(str(e)) from None


# ------------------------------------------------------------------- parameters
def _track(p, scene) -> Track:
    what = f"{p.kind.lower()} {p.name!r} of {p.target!r}"
    if not p.name.strip() or not p.target.strip():
        raise CrowdError(f"an animated parameter needs a name and a target animation "
                         f"({what})")
    values = parameter_values(p, scene)
    try:
        return Track(p.target, p.name, scene.frame_start, values, p.kind.lower())
    except CrowdError as e:
        raise CrowdError(f"{what}: {e}") from None


def _fcurve(scene, path):
    ad = scene.animation_data
    if ad is None or ad.action is None:
        return None
    slot = assigned_slot(ad)
    if slot is None and action_slots(ad.action) is not None:
        return None
    for fc in action_fcurves(ad.action, slot):
        if fc.data_path == path and not fc.mute:
            return fc
    return None


def parameter_values(p, scene) -> np.ndarray:
    """(F,) values of parameter ``p`` at the scene's frames ``frame_start ..
    frame_end``: its F-curve evaluated, its driver run frame by frame, or its value."""
    path = p.path_from_id("value")
    frames = np.arange(scene.frame_start, scene.frame_end + 1)
    ad = scene.animation_data
    if ad is not None and ad.drivers.find(path) is not None:
        keep = scene.frame_current, scene.frame_subframe
        values = []
        try:
            for f in frames.tolist():
                scene.frame_set(f)
                values.append(p.value)
        finally:
            scene.frame_set(keep[0], subframe=keep[1])
        return np.array(values, np.float64)
    fc = _fcurve(scene, path)
    if fc is None:
        return np.array([p.value], np.float64)
    return np.array([fc.evaluate(f) for f in frames.tolist()], np.float64)


def show_fingerprint(scene) -> tuple:
    """What the sampled parameters depend on besides the settings: every keyframe of
    their F-curves and every driver expression (so editing them rebuilds the crowd)."""
    out = []
    ad = scene.animation_data
    for p in scene.crowd.show.parameters:
        path = p.path_from_id("value")
        fc = _fcurve(scene, path)
        keys = () if fc is None else tuple(
            (tuple(k.co), tuple(k.handle_left), tuple(k.handle_right), k.interpolation)
            for k in fc.keyframe_points)
        drv = ad.drivers.find(path) if ad is not None else None
        out.append((path, keys, None if drv is None else
                    (drv.driver.type, drv.driver.expression)))
    for t in scene.crowd.show.look_targets:          # the targets' sampled paths
        out.append((t.name, None if t.object is None else _object_keys(t.object)))
    return tuple(out)
