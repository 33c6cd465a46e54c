"""Scene properties (``scene.crowd``) -> a core :class:`~crowd_addon.core.CrowdConfig`.

The armature becomes the skeleton and the proxy mesh its ``ProxyMesh``
(:mod:`.armature`), every action a node tree uses is baked into a clip named after
the action (:mod:`.bake`), node trees become controller trees, and the agent
sources become agents (:mod:`.agents`). Errors are :class:`CrowdError` messages that
name the stream, node, action or object at fault; nothing in the scene changes.

:func:`config_steps` does the work as a generator, one action per step, so a modal
operator can report progress and cancel between steps; :func:`config_from_scene` runs
it to the end (batch export, scripts, tests).
"""

from __future__ import annotations

from ..core.config import CrowdConfig
from ..core.controllers import (Blend2, BlendSpace2D, ClipPlayer, Layer, StateMachine,
                                StateTransition)
from ..core.errors import CrowdError
from ..core.mesh import CARD

__all__ = ["config_from_scene", "config_steps", "scene_fps", "used_actions", "build_tree"]


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
def _mask(node, skeleton, armature_data, what):
    if node.mask_source == "ALL":
        return None
    if node.mask_source == "BONES":
        names = [n.strip() for n in node.mask_bones.split(",") if n.strip()]
        if not names:
            raise CrowdError(f"{what}: the bone mask lists no bones")
    else:
        coll = armature_data.collections_all.get(node.mask_collection)
        if coll is None:
            raise CrowdError(f"{what}: armature {armature_data.name!r} has no bone collection "
                             f"{node.mask_collection!r}")
        names = [b.name for b in coll.bones]
        if not names:
            raise CrowdError(f"{what}: bone collection {node.mask_collection!r} is empty")
    missing = [n for n in names if n not in skeleton.bone_names]
    if missing:
        raise CrowdError(f"{what}: skeleton {skeleton.name!r} has no bone {missing[0]!r}")
    return {n: 1.0 for n in names}


def _weight(node):
    return node.weight_parameter if node.weight_parameter else node.weight


def build_tree(anim, pool, skeleton, armature_data, frame_start=0):
    """The controller tree of one ``CROWD_PG_animation``; raises CrowdError naming the
    stream/unique, node and input at fault.

    Time: an action node shows clip frame ``start + speed * (F - frame_start)`` at
    scene frame ``F`` (clip frame 0 is the action's first frame, so with speed 1 and
    start 0 the crowd shows what the armature playing the action shows when the
    action begins at the scene start); inside a state machine ``F - frame_start`` is
    replaced by the frames since the state was entered.
    """
    label = f"{pool} {anim.name!r}"
    if len(anim.nodes) == 0:
        raise CrowdError(f"{label}: has no nodes (add an action)")
    nodes = {}
    for n in anim.nodes:
        if n.name in nodes:
            raise CrowdError(f"{label}: two nodes are named {n.name!r}")
        nodes[n.name] = n
    for n in anim.nodes:
        for k, inp in enumerate(n.inputs):
            if inp.node not in nodes:
                raise CrowdError(f"{label}: node {n.name!r}: input {k} ({inp.name!r}) names "
                                 f"unknown node {inp.node!r}")
    root = anim.root or anim.nodes[0].name
    if root not in nodes:
        raise CrowdError(f"{label}: root node {root!r} does not exist")

    def build(name, path, origin):
        node = nodes[name]
        what = f"{label}: node {name!r}"
        if name in path:
            raise CrowdError(f"{what}: cycle " + " -> ".join(path + (name,)))
        kids = []
        if node.kind != "CLIP":
            inner = 0.0 if node.kind == "STATE_MACHINE" else origin
            kids = [build(inp.node, path + (name,), inner) for inp in node.inputs]
        try:
            return _controller(node, kids, skeleton, armature_data, what, origin)
        except CrowdError as e:
            msg = str(e)
            raise CrowdError(msg if msg.startswith(label) else f"{what}: {msg}") from None

    return build(root, (), float(frame_start))


def _need_inputs(node, kids, lo, hi, what):
    if not lo <= len(kids) <= hi:
        want = str(lo) if lo == hi else f"{lo} or more"
        raise CrowdError(f"{what}: a {node.kind.lower().replace('_', ' ')} needs {want} "
                         f"inputs, it has {len(kids)}")


def _controller(node, kids, skeleton, armature_data, what, origin):
    if node.kind == "CLIP":
        if node.action is None:
            raise CrowdError(f"{what}: no action chosen")
        return ClipPlayer(node.action.name, node.speed, node.start - node.speed * origin)
    if node.kind == "BLEND2":
        _need_inputs(node, kids, 2, 2, what)
        return Blend2(kids[0], kids[1], _weight(node))
    if node.kind == "LAYER":
        _need_inputs(node, kids, 2, 2, what)
        mode = node.layer_mode.lower()
        ref = None
        if mode == "additive" and node.reference_action is not None:
            ref = (node.reference_action.name, node.reference_frame)
        return Layer(kids[0], kids[1], mode, _mask(node, skeleton, armature_data, what),
                     _weight(node), ref)
    if node.kind == "BLEND_SPACE":
        _need_inputs(node, kids, 1, 1 << 30, what)
        if not node.x_parameter or not node.y_parameter:
            raise CrowdError(f"{what}: a blend space needs x and y parameter names")
        return BlendSpace2D(kids, [(i.x, i.y) for i in node.inputs], node.x_parameter,
                            node.y_parameter)
    _need_inputs(node, kids, 1, 1 << 30, what)
    states = {}
    for inp, kid in zip(node.inputs, kids):
        if not inp.name or inp.name in states:
            raise CrowdError(f"{what}: state names must be unique and not empty "
                             f"({inp.name!r})")
        states[inp.name] = kid
    transitions = [StateTransition(
        t.source or "*", t.target, t.duration, t.trigger or None,
        (t.condition_parameter, t.condition_op, t.condition_value)
        if t.condition_parameter else None) for t in node.transitions]
    return StateMachine(states, transitions, node.initial_state or None)


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


def _bake_action(scene, armature_obj, action, skeleton, fps):
    from . import bake
    return bake.bake_actions(armature_obj, [action], fps, scene=scene,
                             skeleton=skeleton).clips[0]


def config_steps(scene, depsgraph=None):
    """Generator building the scene's crowd: yields ``(done, total, message)`` before
    each unit of work (one per action, then the mesh, then the agents) and returns the
    :class:`CrowdConfig` (``StopIteration.value``). Raises CrowdError on bad input."""
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
    # stream time is the scene frame; a unique's time starts at 0 when it is started
    trees = {pool: [(a.name, build_tree(a, pool, skeleton, arm.data,
                                        scene.frame_start if pool == "stream" else 0))
                    for a in anims] for pool, anims in _pools(s)}
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
            cfg.add_clip(_bake_action(scene, arm, act, skeleton, fps))
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


def config_from_scene(scene, progress=None, depsgraph=None) -> CrowdConfig:
    """Build the scene's :class:`CrowdConfig`; ``progress(done, total, message)`` is
    called before each step."""
    steps = config_steps(scene, depsgraph)
    while True:
        try:
            done, total, message = next(steps)
        except StopIteration as stop:
            return stop.value
        if progress is not None:
            progress(done, total, message)
