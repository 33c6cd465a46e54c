"""Scene properties (``scene.crowd``) -> a core :class:`~crowd_addon.core.CrowdConfig`.

The armature becomes the skeleton and the proxy mesh its ``ProxyMesh``
(:mod:`.armature`), every action a node tree uses is baked into a clip named after
the action (:mod:`.bake`), node lists are read into plain
:class:`~crowd_addon.core.controller_graph.NodeSpec` values that core validates and
builds into controller trees (:func:`crowd_addon.core.controller_graph.build_tree`),
and the agent sources become agents (:mod:`.agents`). Errors are :class:`CrowdError` messages that
name the stream, node, action or object at fault; nothing in the scene changes.

:func:`config_steps` does the work as a generator, one action per step, so a modal
operator can report progress and cancel between steps; :func:`config_from_scene` runs
it to the end (batch export, scripts, tests).
"""

from __future__ import annotations

from ..core.config import CrowdConfig
from ..core.controller_graph import InputSpec, NodeSpec, TransitionSpec, build_tree
from ..core.errors import CrowdError
from ..core.mesh import CARD

__all__ = ["config_from_scene", "config_steps", "scene_fps", "used_actions", "node_specs",
           "bone_collections", "lod_distances"]


def scene_fps(scene) -> float:
    """The scene's frame rate (``render.fps / render.fps_base``), the crowd fps."""
    return scene.render.fps / scene.render.fps_base


def _pools(settings):
    return (("stream", settings.streams), ("unique", settings.uniques))


def used_actions(settings) -> list:
    """Actions referenced by any node (clips and additive references), first use
    first, each once."""
    seen = {}
    for _pool, anims in _pools(settings):
        for anim in anims:
            for node in anim.nodes:
                for act in (node.action if node.kind == "CLIP" else None,
                            node.reference_action
                            if node.kind == "LAYER" and node.layer_mode == "ADDITIVE" else None):
                    if act is not None:
                        seen.setdefault(act.name, act)
    return list(seen.values())


# ------------------------------------------------------------------ controller trees
def _name(id_block):
    return None if id_block is None else id_block.name


def node_specs(anim) -> tuple:
    """The nodes of one ``CROWD_PG_animation`` as plain
    :class:`~crowd_addon.core.controller_graph.NodeSpec` values (actions by name)."""
    return tuple(NodeSpec(
        name=n.name, kind=n.kind,
        inputs=tuple(InputSpec(i.node, i.name, i.x, i.y) for i in n.inputs),
        action=_name(n.action), speed=n.speed, start=n.start, weight=n.weight,
        weight_parameter=n.weight_parameter, layer_mode=n.layer_mode,
        mask_source=n.mask_source, mask_bones=n.mask_bones,
        mask_collection=n.mask_collection, reference_action=_name(n.reference_action),
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
    names = ["lod_near", "lod_far"] + (["lod_card"] if settings.lod_cards else [])
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


def config_steps(scene, depsgraph=None, notes=None):
    """Generator building the scene's crowd: yields ``(done, total, message)`` before
    each unit of work (one per action, then the mesh, then the agents) and returns the
    :class:`CrowdConfig` (``StopIteration.value``). Raises CrowdError on bad input.

    Actions are baked at the scene's fps times *Samples per Frame*; the bake's remarks
    (``BakeResult.notes``) are appended to the list ``notes`` when one is given."""
    from . import agents as agent_mod
    from .armature import proxy_mesh_from_object, skeleton_from_armature

    s = _settings(scene)
    arm = s.armature
    if arm is None:
        raise CrowdError(f"scene {scene.name!r}: no armature chosen (Crowd panel > Armature)")
    if arm.type != "ARMATURE":
        raise CrowdError(f"scene {scene.name!r}: object {arm.name!r} is not an armature")
    if len(s.streams) == 0 and len(s.uniques) == 0:
        raise CrowdError(f"scene {scene.name!r}: no streams or unique animations to build")
    for pool, anims in _pools(s):
        names = [a.name for a in anims]
        for a in anims:
            if not a.name or names.count(a.name) > 1:
                raise CrowdError(f"{pool} names must be unique and not empty ({a.name!r})")
    skeleton = skeleton_from_armature(arm)
    collections = bone_collections(arm.data)

    def tree(pool, anim):       # stream time is the scene frame; a unique's starts at 0
        return build_tree(f"{pool} {anim.name!r}", node_specs(anim), anim.root, skeleton,
                          scene.frame_start if pool == "stream" else 0,
                          bone_collections=collections, armature=arm.data.name)

    trees = {pool: [(a.name, tree(pool, a)) for a in anims] for pool, anims in _pools(s)}
    actions = used_actions(s)
    fps = scene_fps(scene)
    total = len(actions) + 2
    cfg = CrowdConfig(max_offset=s.max_offset, transition_slots=s.transition_slots, fps=fps,
                      seed=s.seed, when_full=s.when_full.lower(),
                      start_frame=scene.frame_start,
                      lod_distances=lod_distances(s))
    cfg.add_skeleton(skeleton)
    for i, act in enumerate(actions):
        yield i, total, f"baking action {act.name!r}"
        try:
            cfg.add_clip(_bake_action(scene, arm, act, skeleton, fps, s.samples_per_frame,
                                      [] if notes is None else notes))
        except CrowdError as e:
            msg = str(e)
            raise CrowdError(msg if act.name in msg else f"action {act.name!r}: {msg}") \
                from None
    for name, root in trees["stream"]:
        cfg.add_stream(name, skeleton.name, root)
    for name, root in trees["unique"]:
        cfg.add_unique(name, skeleton.name, root)
    yield len(actions), total, "reading the proxy mesh"
    if s.proxy_mesh is not None:
        cfg.add_mesh(proxy_mesh_from_object(s.proxy_mesh, arm, skeleton),
                     lods=(0.25, 0.06, CARD) if s.lod_cards else (0.25, 0.06))
    yield len(actions) + 1, total, "placing agents"
    dg = depsgraph if depsgraph is not None else _depsgraph(scene)
    agents = agent_mod.agents_from_scene(scene, dg, [a.name for a in s.streams],
                                         [a.weight for a in s.streams])
    if agents.count:
        cfg.add_agents(agents.count, streams=agents.streams, offsets=agents.offsets,
                       positions=agents.positions, headings=agents.headings,
                       colors=agents.colors)
    return cfg


def _depsgraph(scene):
    """The evaluated depsgraph of ``scene`` (its first view layer unless it is the
    context's scene)."""
    import bpy
    if bpy.context.scene == scene:
        return bpy.context.evaluated_depsgraph_get()
    dg = scene.view_layers[0].depsgraph
    dg.update()
    return dg


def config_from_scene(scene, progress=None, depsgraph=None, notes=None) -> CrowdConfig:
    """Build the scene's :class:`CrowdConfig`; ``progress(done, total, message)`` is
    called before each step; the bake's remarks go to the list ``notes`` if given."""
    steps = config_steps(scene, depsgraph, notes)
    while True:
        try:
            done, total, message = next(steps)
        except StopIteration as stop:
            return stop.value
        if progress is not None:
            progress(done, total, message)
