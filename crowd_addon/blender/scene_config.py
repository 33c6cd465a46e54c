"""Scene properties (``scene.crowd``) -> a core :class:`~crowd_addon.core.CrowdConfig`.

Each character (``scene.crowd.characters``) becomes a skeleton named after it, from
its armature, and its body (with its LOD meshes when given) that skeleton's
``ProxyMesh`` levels (:mod:`.armature`); every action a character's node trees use is
baked on that character's armature into a clip (:mod:`.bake`) named after the action,
or ``"<character>/<action>"`` when several characters use the action (each bakes its
own); node lists are read into plain
:class:`~crowd_addon.core.authoring.controller_graph.NodeSpec` values that core validates and
builds into controller trees (:func:`crowd_addon.core.authoring.controller_graph.build_tree`);
the streams and uniques of all characters go into the one config, character after
character; and the agent sources become agents (:mod:`.agents`), each on a stream of
its character, so an agent's character is its stream's skeleton. Errors are
:class:`CrowdError` messages that name the character, stream, node, action or object
at fault; nothing in the scene changes. A character's meshes and palettes are read by
:mod:`.character_meshes`.

:func:`config_steps` does the work as a generator, one action per step, so a modal
operator can report progress and cancel between steps; :func:`config_from_scene` runs
it to the end (batch export, scripts, tests).
"""

from __future__ import annotations

import dataclasses

from ..core.bake.bake_report import WARNING, BakeReport
from ..core.authoring.config import CrowdConfig
from ..core.authoring.controller_graph import InputSpec, NodeSpec, TransitionSpec, build_tree
from ..core.base.errors import CrowdError
from ..core.variety.timing import expand
from .character_meshes import add_mesh, add_palettes

__all__ = ["config_from_scene", "config_steps", "scene_fps", "used_actions", "node_specs",
           "bone_collections", "lod_distances", "clip_names", "scene_actions", "look_rig"]


def scene_fps(scene) -> float:
    """The scene's frame rate (``render.fps / render.fps_base``), the crowd fps."""
    return scene.render.fps / scene.render.fps_base


def _pools(character):
    return (("stream", character.streams), ("unique", character.uniques))


def used_actions(character) -> list:
    """Actions referenced by any node of a character's streams and uniques (clips and
    additive references), first use first, each once."""
    seen = {}
    for _pool, anims in _pools(character):
        for anim in anims:
            for node in anim.nodes:
                for act in (node.action if node.kind == "CLIP" else None,
                            node.reference_action
                            if node.kind == "LAYER" and node.layer_mode == "ADDITIVE" else None):
                    if act is not None:
                        seen.setdefault(act.name, act)
    return list(seen.values())


def scene_actions(settings) -> list:
    """Every action the scene's characters use, each once (first use first)."""
    seen = {}
    for c in settings.characters:
        for act in used_actions(c):
            seen.setdefault(act.name, act)
    return list(seen.values())


def clip_names(characters) -> dict:
    """``{(character name, action name): clip name}`` for every action the characters
    use: the action's name when one character uses it, else ``"<character>/<action>"``
    (each character bakes it on its own armature)."""
    users = {}
    for c in characters:
        for act in used_actions(c):
            users.setdefault(act.name, []).append(c.name)
    return {(c, a): a if len(names) == 1 else f"{c}/{a}"
            for a, names in users.items() for c in names}


# ------------------------------------------------------------------ controller trees
def node_specs(anim, clips=None) -> tuple:
    """The nodes of one ``CROWD_PG_animation`` as plain
    :class:`~crowd_addon.core.authoring.controller_graph.NodeSpec` values; actions by their clip
    name, ``clips`` (action name -> clip name; default: the action's name)."""
    clips = clips or {}

    def clip(action):
        return None if action is None else clips.get(action.name, action.name)

    return tuple(NodeSpec(
        name=n.name, kind=n.kind,
        inputs=tuple(InputSpec(i.node, i.name, i.x, i.y) for i in n.inputs),
        action=clip(n.action), speed=n.speed, start=n.start, weight=n.weight,
        weight_parameter=n.weight_parameter, layer_mode=n.layer_mode,
        mask_source=n.mask_source, mask_bones=n.mask_bones,
        mask_collection=n.mask_collection, reference_action=clip(n.reference_action),
        reference_frame=n.reference_frame, x_parameter=n.x_parameter,
        y_parameter=n.y_parameter, initial_state=n.initial_state,
        transitions=tuple(TransitionSpec(t.source, t.target, t.duration, t.trigger,
                                         t.condition_parameter, t.condition_op,
                                         t.condition_value) for t in n.transitions))
        for n in anim.nodes)


def bone_collections(armature_data) -> dict:
    """Bone collection name -> names of its bones, of an armature (data block)."""
    return {c.name: tuple(b.name for b in c.bones) for c in armature_data.collections_all}


# --------------------------------------------------------------------------- config
def _settings(scene):
    s = getattr(scene, "crowd", None)
    if s is None:
        raise CrowdError("the crowd extension is not registered (scene.crowd is missing)")
    return s


def lod_distances(settings) -> tuple:
    """The LOD switch distances of the Crowd settings (with the card's when on); a
    clear error when they do not increase."""
    names = ["lod_near", "lod_far"] + (["lod_card", "lod_joined"] if settings.lod_cards
                                       else [])
    values = [float(getattr(settings, n)) for n in names]
    for (a, va), (b, vb) in zip(zip(names, values), zip(names[1:], values[1:])):
        if vb <= va:
            label = {n: settings.bl_rna.properties[n].name for n in names}
            raise CrowdError(f"Crowd settings: {label[b]} ({vb:g} m) must be farther than "
                             f"{label[a]} ({va:g} m)")
    return tuple(values)


def _bake_action(scene, armature_obj, action, skeleton, fps, samples_per_frame, notes):
    from . import bake
    result = bake.bake_actions(armature_obj, [action], fps, scene=scene, skeleton=skeleton,
                               samples_per_frame=samples_per_frame)
    notes.extend(result.notes)
    return result.clips[0]


def _characters(scene, s) -> list:
    """The scene's characters, checked: named, each once, each with an armature, and
    between them at least one stream or unique animation."""
    chars = list(s.characters)
    if not chars:
        raise CrowdError(f"scene {scene.name!r}: no characters (Crowd panel > Characters > "
                         "+)")
    seen = set()
    for c in chars:
        if not c.name.strip():
            raise CrowdError(f"scene {scene.name!r}: a character has no name")
        if c.name in seen:
            raise CrowdError(f"scene {scene.name!r}: two characters are named {c.name!r}")
        seen.add(c.name)
        what = f"character {c.name!r}"
        if c.armature is None:
            raise CrowdError(f"{what}: no armature chosen (Crowd panel > Characters)")
        if c.armature.type != "ARMATURE":
            raise CrowdError(f"{what}: object {c.armature.name!r} is not an armature")
    if not any(len(c.streams) or len(c.uniques) for c in chars):
        raise CrowdError(f"scene {scene.name!r}: no streams or unique animations to build")
    _check_names(chars)
    return chars


def _check_names(chars):
    """Stream and unique names: not empty, and each once in the whole scene (the crowd
    plays them all by name)."""
    seen = {}
    for c in chars:
        for pool, anims in _pools(c):
            for a in anims:
                other = seen.get(a.name)
                if not a.name.strip() or other == (c.name, pool):
                    raise CrowdError(f"character {c.name!r}: {pool} names must be unique "
                                     f"and not empty ({a.name!r})")
                if other is not None:
                    raise CrowdError(f"{pool} {a.name!r} of character {c.name!r} has the "
                                     f"name of {other[1]} {a.name!r} of character "
                                     f"{other[0]!r}; stream and unique names must be unique "
                                     "in the scene")
                seen[a.name] = (c.name, pool)


def _trees(scene, c, skeleton, clips) -> dict:
    """``{"stream": [(name, root)], "unique": [...]}`` of character ``c``."""
    collections = bone_collections(c.armature.data)
    mine = {a: clip for (who, a), clip in clips.items() if who == c.name}

    def tree(pool, anim):       # stream time is the scene frame; a unique's starts at 0
        return build_tree(f"{pool} {anim.name!r}", node_specs(anim, mine), anim.root,
                          skeleton, scene.frame_start if pool == "stream" else 0,
                          bone_collections=collections, armature=c.armature.data.name)

    return {pool: [(a.name, tree(pool, a)) for a in anims] for pool, anims in _pools(c)}


def config_steps(scene, depsgraph=None, notes=None):
    """Generator building the scene's crowd: yields ``(done, total, message)`` before
    each unit of work (one per action a character uses, then one per character for its
    meshes, then the agents) and returns the :class:`CrowdConfig`
    (``StopIteration.value``). Raises CrowdError on bad input.

    Actions are baked at the scene's fps times *Samples per Frame*. The bake report
    (:class:`~crowd_addon.core.bake.bake_report.BakeReport`, carried as
    ``config.bake_report``) holds the bake's remarks (``BakeResult.notes``: poses
    between frames that miss the action's, frame_set sampling, resampling), the proxy
    meshes' (``ProxyMesh.notes``: vertices that had more than eight bone influences,
    kind ``"mesh"``) and the LOD levels the silhouette check refused (kind ``"lod"``);
    its notes are also appended to the list ``notes`` when one is given."""
    from . import agents as agent_mod
    from .armature import skeleton_from_armature
    from .show_data import look_targets_from_scene, show_from_scene

    s = _settings(scene)
    chars = _characters(scene, s)
    found = []                          # the bake's and the meshes' remarks, in order
    skeletons = {c.name: skeleton_from_armature(c.armature, name=c.name) for c in chars}
    clips = clip_names(chars)
    trees = {c.name: _trees(scene, c, skeletons[c.name], clips) for c in chars}
    jobs = [(c, act) for c in chars for act in used_actions(c)]
    several = len(chars) > 1
    fps = scene_fps(scene)
    total = len(jobs) + len(chars) + 1
    cfg = CrowdConfig(max_offset=s.max_offset, transition_slots=s.transition_slots, fps=fps,
                      seed=s.seed, when_full=s.when_full.lower(),
                      start_frame=scene.frame_start,
                      lod_distances=lod_distances(s))
    for c in chars:
        cfg.add_skeleton(skeletons[c.name])
    for i, (c, act) in enumerate(jobs):
        yield i, total, f"baking action {act.name!r}" + (
            f" for character {c.name!r}" if several else "")
        try:
            clip = _bake_action(scene, c.armature, act, skeletons[c.name], fps,
                                s.samples_per_frame, found)
            name = clips[c.name, act.name]
            cfg.add_clip(clip if clip.name == name else dataclasses.replace(clip, name=name))
        except CrowdError as e:
            msg = str(e)
            msg = msg if act.name in msg else f"action {act.name!r}: {msg}"
            raise CrowdError(f"character {c.name!r}: {msg}" if several else msg) from None
    for c in chars:
        for (name, root), anim in zip(trees[c.name]["stream"], c.streams):
            timing = agent_mod.stream_timing(anim).check(f"character {c.name!r}: stream "
                                                         f"{name!r}")
            for label, speed, phase in expand(name, timing, s.max_offset, scene.frame_start):
                cfg.add_stream(label, c.name, root, speed, phase,
                               "" if timing.count == 1 else name)
        for name, root in trees[c.name]["unique"]:
            cfg.add_unique(name, c.name, root)
    for k, c in enumerate(chars):
        yield len(jobs) + k, total, "reading the proxy mesh" + (
            f" of character {c.name!r}" if several else "")
        add_mesh(cfg, c, skeletons[c.name], s.lod_cards, found)
        add_palettes(cfg, c)
    yield total - 1, total, "placing agents"
    dg = depsgraph if depsgraph is not None else _depsgraph(scene)
    agents, placed = agent_mod.agents_from_scene(scene, dg)
    if agents.count:
        agents.add_to(cfg)
    cfg.look_rigs = {c.name: rig for c in chars
                     if (rig := look_rig(c, skeletons[c.name], s.forward_axis)) is not None}
    cfg.look_targets = look_targets_from_scene(scene)
    cfg.look_lag, cfg.look_max_lag = s.show.look_lag.lower(), s.show.look_max_lag
    cfg.show = show_from_scene(scene, dg, cfg, placed)
    report = BakeReport()
    report.extend(found, "mesh", WARNING)       # Notes keep their own kind
    report.extend(cfg.lod_notes, "lod", WARNING)    # levels the silhouette check refused
    cfg.bake_report = report
    if notes is not None:
        notes.extend(n for n in report if n not in notes)
    return cfg


def _names(text) -> list:
    return [t.strip() for t in text.split(",") if t.strip()]


def look_rig(c, skeleton, forward_axis="NEG_Y"):
    """Character ``c``'s :class:`~crowd_addon.core.runtime.look_at.LookRig` (None when it has no
    look bones), checked against its skeleton; the forward axis is the scene's
    *Forward* setting, the one agents are turned by."""
    from ..core.runtime.look_at import LookChain, LookRig
    from ..core.authoring.placement import FORWARD
    bones = _names(c.look_bones)
    if not bones:
        return None
    what = f"character {c.name!r}: look bones"
    try:
        shares = tuple(float(v) for v in _names(c.look_shares))
    except ValueError:
        raise CrowdError(f"{what}: shares must be numbers separated by commas, got "
                         f"{c.look_shares!r}") from None
    fx, fy = FORWARD[forward_axis]
    try:
        rig = LookRig(tuple(bones), shares, c.look_yaw_limit, c.look_pitch_limit, (fx, fy, 0.0))
        LookChain(rig, skeleton)
    except CrowdError as e:
        msg = str(e).split(": ", 1)[-1] if str(e).startswith("look rig") else str(e)
        raise CrowdError(f"{what}: {msg} (armature {c.armature.name!r}; Crowd > Characters "
                         "> Look At)") from None
    return rig


def _depsgraph(scene):
    """The evaluated depsgraph of ``scene`` (its first view layer unless it is the
    context's scene)."""
    import bpy
    if bpy.context.scene == scene:
        return bpy.context.evaluated_depsgraph_get()
    dg = scene.view_layers[0].depsgraph
    dg.update()
    return dg


def build_crowd(scene, config, skinning="gpu", substeps=1, trust_script=False,
                ignore_script=False):
    """The :class:`~crowd_addon.core.shots.crowd.Crowd` of ``config`` (built from ``scene``)
    with the scene's crowd script run on it: ``(crowd, note)``, ``note`` saying why the
    script did not run ("" when it ran or there is none). The preview and the exports
    build their crowds here, so both run the same script. ``substeps``: samples kept per
    frame (an export's sub-frame samples); ``trust_script``: run the script for this
    call even where it is not trusted; ``ignore_script``: leave it out, trusted or not
    (:func:`.crowd_script.run_script`)."""
    from ..core.shots.crowd import Crowd
    from .crowd_script import run_script
    crowd = Crowd(config, skinning=skinning, substeps=substeps)
    return crowd, run_script(scene, crowd, trusted=trust_script, ignore=ignore_script)


def config_from_scene(scene, progress=None, depsgraph=None, notes=None) -> CrowdConfig:
    """Build the scene's :class:`CrowdConfig`; ``progress(done, total, message)`` is
    called before each step. Its bake report is ``config.bake_report``
    (:func:`config_steps`); its notes also go to the list ``notes`` if given."""
    steps = config_steps(scene, depsgraph, notes)
    while True:
        try:
            done, total, message = next(steps)
        except StopIteration as stop:
            return stop.value
        if progress is not None:
            progress(done, total, message)
