"""Controller trees written as flat lists of named nodes -> core controllers.

A stream (or unique animation) is authored as named nodes whose inputs name other
nodes of the same animation, and a root node (the Crowd panel's lists,
``crowd_addon.blender.props``). :func:`build_tree` validates such a graph (unique
names, known inputs, an existing root, no cycles, the inputs each kind needs, bone
masks of existing bones) and builds the :mod:`.controllers` tree, raising a
:class:`CrowdError` that names the animation, node and input at fault. The nodes
come as plain :class:`NodeSpec` values; nothing here reads Blender data.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..anim.blends import Blend2, BlendSpace2D, Layer
from ..anim.controllers import ClipPlayer
from ..anim.state_machine import StateMachine, StateTransition
from ..base.errors import CrowdError
from ..base.skeleton import Skeleton

__all__ = ["NODE_KINDS", "InputSpec", "TransitionSpec", "NodeSpec", "build_tree"]

#: node kinds, each building one controller class
NODE_KINDS = ("CLIP", "BLEND2", "LAYER", "BLEND_SPACE", "STATE_MACHINE")


@dataclass(frozen=True)
class InputSpec:
    """An input of a node: the node it reads, its label (the state name in a state
    machine) and its blend space point (x, y)."""

    node: str
    name: str = ""
    x: float = 0.0
    y: float = 0.0


@dataclass(frozen=True)
class TransitionSpec:
    """A state machine transition from ``source`` (``"*"`` or empty: any state) to
    ``target`` over ``duration`` frames, fired by ``trigger`` and/or while
    ``condition_parameter condition_op condition_value`` holds (empty: none)."""

    source: str
    target: str
    duration: float = 8.0
    trigger: str = ""
    condition_parameter: str = ""
    condition_op: str = ">"
    condition_value: float = 0.0


@dataclass(frozen=True)
class NodeSpec:
    """One node of an animation graph (the fields its ``kind`` reads).

    kind : one of :data:`NODE_KINDS`.
    CLIP: ``action`` (clip name, None when not chosen) played at ``speed`` (1: its own
    speed) from ``start`` frames after its first frame.
    BLEND2 / LAYER: ``weight`` 0..1, or the stream parameter ``weight_parameter``.
    LAYER: ``layer_mode`` ``"OVERRIDE"`` or ``"ADDITIVE"``; ``mask_source``
    ``"ALL"``, ``"BONES"`` (comma-separated ``mask_bones``) or ``"COLLECTION"``
    (bone collection ``mask_collection``); additive layers subtract the pose of
    ``reference_action`` at ``reference_frame`` (None: the rest pose).
    BLEND_SPACE: parameters ``x_parameter``, ``y_parameter``; inputs' points.
    STATE_MACHINE: inputs are the states (their names), ``transitions``,
    ``initial_state`` (empty: the first input).
    """

    name: str
    kind: str = "CLIP"
    inputs: tuple = ()
    action: str | None = None
    speed: float = 1.0
    start: float = 0.0
    weight: float = 0.5
    weight_parameter: str = ""
    layer_mode: str = "OVERRIDE"
    mask_source: str = "ALL"
    mask_bones: str = ""
    mask_collection: str = ""
    reference_action: str | None = None
    reference_frame: float = 0.0
    x_parameter: str = "x"
    y_parameter: str = "y"
    transitions: tuple = ()
    initial_state: str = ""


def build_tree(label: str, nodes, root: str, skeleton: Skeleton, frame_start: float = 0.0,
               *, bone_collections=None, armature: str = ""):
    """The controller tree of an animation's nodes.

    Parameters
    ----------
    label : the animation in error messages, e.g. ``"stream 'walk'"``.
    nodes : sequence of :class:`NodeSpec`; root : the output node's name (empty: the
        first node).
    skeleton : the skeleton the masks' bones must belong to.
    frame_start : scene frame at which an action node shows its action ``start`` frames
        in.
    bone_collections : dict bone collection name -> bone names, for masks by
        collection; armature : the armature's name in their error messages.

    Time: an action node shows its action ``start + speed * (F - frame_start)`` scene
    (crowd) frames after the action's first frame at scene frame ``F``, whatever the
    samples per frame its clip was baked with (a clip plays at its own rate), so with
    speed 1 and start 0 the crowd shows what the armature playing the action shows
    when the action begins at the scene start; inside a state machine ``F -
    frame_start`` is replaced by the frames since the state was entered. Raises
    CrowdError naming the animation, node and input at fault.
    """
    if len(nodes) == 0:
        raise CrowdError(f"{label}: has no nodes (add an action)")
    by_name = {}
    for n in nodes:
        if n.name in by_name:
            raise CrowdError(f"{label}: two nodes are named {n.name!r}")
        by_name[n.name] = n
    for n in nodes:
        for k, inp in enumerate(n.inputs):
            if inp.node not in by_name:
                raise CrowdError(f"{label}: node {n.name!r}: input {k} ({inp.name!r}) names "
                                 f"unknown node {inp.node!r}")
    root = root or nodes[0].name
    if root not in by_name:
        raise CrowdError(f"{label}: root node {root!r} does not exist")
    rig = (skeleton, bone_collections or {}, armature)

    def build(name, path, origin):
        node = by_name[name]
        what = f"{label}: node {name!r}"
        if name in path:
            raise CrowdError(f"{what}: cycle " + " -> ".join(path + (name,)))
        kids = []
        if node.kind != "CLIP":
            inner = 0.0 if node.kind == "STATE_MACHINE" else origin
            kids = [build(inp.node, path + (name,), inner) for inp in node.inputs]
        try:
            return _controller(node, kids, rig, what, origin)
        except CrowdError as e:
            msg = str(e)
            raise CrowdError(msg if msg.startswith(label) else f"{what}: {msg}") from None

    return build(root, (), float(frame_start))


def _mask(node, rig, what):
    """Layer weights per bone name of a node's mask (None: every bone)."""
    skeleton, collections, armature = rig
    if node.mask_source == "ALL":
        return None
    if node.mask_source == "BONES":
        names = [n.strip() for n in node.mask_bones.split(",") if n.strip()]
        if not names:
            raise CrowdError(f"{what}: the bone mask lists no bones")
    elif node.mask_source == "COLLECTION":
        names = collections.get(node.mask_collection)
        if names is None:
            raise CrowdError(f"{what}: armature {armature!r} has no bone collection "
                             f"{node.mask_collection!r}")
        if not names:
            raise CrowdError(f"{what}: bone collection {node.mask_collection!r} is empty")
    else:
        raise CrowdError(f"{what}: unknown mask source {node.mask_source!r} "
                         "(ALL, BONES, COLLECTION)")
    missing = [n for n in names if n not in skeleton.bone_names]
    if missing:
        raise CrowdError(f"{what}: skeleton {skeleton.name!r} has no bone {missing[0]!r}")
    return {n: 1.0 for n in names}


def _weight(node):
    return node.weight_parameter if node.weight_parameter else node.weight


def _need_inputs(node, kids, lo, hi, what):
    if not lo <= len(kids) <= hi:
        want = str(lo) if lo == hi else f"{lo} or more"
        raise CrowdError(f"{what}: a {node.kind.lower().replace('_', ' ')} needs {want} "
                         f"inputs, it has {len(kids)}")


def _controller(node, kids, rig, what, origin):
    if node.kind == "CLIP":
        if node.action is None:
            raise CrowdError(f"{what}: no action chosen")
        return ClipPlayer(node.action, node.speed, node.start - node.speed * origin)
    if node.kind == "BLEND2":
        _need_inputs(node, kids, 2, 2, what)
        return Blend2(kids[0], kids[1], _weight(node))
    if node.kind == "LAYER":
        _need_inputs(node, kids, 2, 2, what)
        mode = node.layer_mode.lower()
        ref = None
        if mode == "additive" and node.reference_action is not None:
            ref = (node.reference_action, node.reference_frame)
        return Layer(kids[0], kids[1], mode, _mask(node, rig, what), _weight(node), ref)
    if node.kind == "BLEND_SPACE":
        _need_inputs(node, kids, 1, 1 << 30, what)
        if not node.x_parameter or not node.y_parameter:
            raise CrowdError(f"{what}: a blend space needs x and y parameter names")
        return BlendSpace2D(kids, [(i.x, i.y) for i in node.inputs], node.x_parameter,
                            node.y_parameter)
    if node.kind != "STATE_MACHINE":
        raise CrowdError(f"{what}: unknown node kind {node.kind!r} ({', '.join(NODE_KINDS)})")
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
