"""Node lists -> controller trees (crowd_addon.core.authoring.controller_graph): what each node
kind builds, the time origin, and the errors that name the animation, node and input
at fault. (The scene side, Blender properties -> node specs, is in
tests/blender/test_scene_config.py.)"""

import numpy as np
import pytest

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.authoring.controller_graph import (NODE_KINDS, InputSpec, NodeSpec,
                                                         TransitionSpec, build_tree)
from crowd_addon.core.anim.blends import Blend2, BlendSpace2D, Layer
from crowd_addon.core.anim.controllers import ClipPlayer
from crowd_addon.core.anim.state_machine import StateMachine
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.base.skeleton import Skeleton

BONES = ("root", "spine", "arm.L", "arm.R")
SKELETON = Skeleton.from_parent_names("Rig", BONES, [None, "root", "spine", "spine"],
                                      sqt.identity_pose(4))
COLLECTIONS = {"Arms": ("arm.L", "arm.R"), "Empty": ()}


def clip(name, action="walk", **kw):
    return NodeSpec(name, "CLIP", action=action, **kw)


def node(name, kind, inputs, **kw):
    """A node whose inputs are node names, (state name, node) pairs or InputSpecs."""
    ins = tuple(InputSpec(i) if isinstance(i, str) else
                i if isinstance(i, InputSpec) else InputSpec(i[1], i[0]) for i in inputs)
    return NodeSpec(name, kind, inputs=ins, **kw)


def build(nodes, root="", frame_start=0.0):
    return build_tree("stream 'w'", nodes, root, SKELETON, frame_start,
                      bone_collections=COLLECTIONS, armature="Rig")


def test_every_kind_builds_its_controller():
    assert NODE_KINDS == ("CLIP", "BLEND2", "LAYER", "BLEND_SPACE", "STATE_MACHINE")
    a, b = clip("a", "walk", speed=2.0, start=3.0), clip("b", "wave")
    tree = build([node("mix", "BLEND2", ["a", "b"], weight_parameter="speed"), a, b])
    assert isinstance(tree, Blend2) and isinstance(tree.a, ClipPlayer)
    assert (tree.a.clip, tree.a.speed, tree.a.start, tree.b.clip) == ("walk", 2.0, 3.0, "wave")
    layer = build([a, b, node("l", "LAYER", ["a", "b"], layer_mode="ADDITIVE",
                                mask_source="COLLECTION", mask_collection="Arms",
                                reference_action="idle", reference_frame=4.0)], root="l")
    assert isinstance(layer, Layer) and layer.mode == "additive"
    assert layer.bone_weights == {"arm.L": 1.0, "arm.R": 1.0}
    assert layer.reference == ("idle", 4.0)
    space = build([node("s", "BLEND_SPACE", [InputSpec("a", x=0, y=1),
                                             InputSpec("b", x=1, y=0)]), a, b])
    assert isinstance(space, BlendSpace2D) and np.array_equal(space.points, [[0, 1], [1, 0]])
    moves = (TransitionSpec("calm", "cheer", 4.0, "goal"),
             TransitionSpec("", "calm", 0.0, "", "x", "<", 0.5))
    sm = build([node("sm", "STATE_MACHINE", [("calm", "a"), ("cheer", "b")],
                     initial_state="cheer", transitions=moves), a, b])
    assert isinstance(sm, StateMachine) and sm.state_names == ("calm", "cheer")
    assert sm.initial == "cheer"
    assert [(t.source, t.target, t.trigger, t.condition) for t in sm.transitions] == [
        ("calm", "cheer", "goal", None), ("*", "calm", None, ("x", "<", 0.5))]


def test_time_origin_is_the_frame_start_except_inside_state_machines():
    a, b = clip("a", speed=2.0, start=3.0), clip("b")
    assert build([a], frame_start=10.0).start == 3.0 - 2.0 * 10.0
    tree = build([node("mix", "BLEND2", ["a", "sm"]), a, b,
                  node("sm", "STATE_MACHINE", [("s", "b")])], frame_start=10.0)
    assert tree.a.start == -17.0 and tree.b.states[0].start == 0.0


@pytest.mark.parametrize("nodes, root, message", [
    ([], "", r"stream 'w': has no nodes"),
    ([clip("a"), clip("a")], "", r"stream 'w': two nodes are named 'a'"),
    ([clip("clip"), node("mix", "BLEND2", ["clip", "nope"])], "",
     r"stream 'w': node 'mix': input 1 \(''\) names unknown node 'nope'"),
    ([clip("clip")], "out", r"stream 'w': root node 'out' does not exist"),
    ([clip("clip"), node("mix", "BLEND2", ["clip"])], "mix",
     r"stream 'w': node 'mix': a blend2 needs 2 inputs, it has 1"),
    ([clip("clip"), node("loop", "BLEND2", ["clip", "loop"])], "loop",
     r"stream 'w': node 'loop': cycle loop -> loop"),
    ([clip("clip"), node("l", "LAYER", ["clip", "clip"], mask_source="BONES",
                         mask_bones="arm.L, tail")], "l",
     r"stream 'w': node 'l': skeleton 'Rig' has no bone 'tail'"),
    ([clip("clip"), node("l", "LAYER", ["clip", "clip"], mask_source="BONES",
                         mask_bones=" , ")], "l", r"node 'l': the bone mask lists no bones"),
    ([clip("clip"), node("l", "LAYER", ["clip", "clip"], mask_source="COLLECTION",
                         mask_collection="Legs")], "l",
     r"node 'l': armature 'Rig' has no bone collection 'Legs'"),
    ([clip("clip"), node("l", "LAYER", ["clip", "clip"], mask_source="COLLECTION",
                         mask_collection="Empty")], "l",
     r"node 'l': bone collection 'Empty' is empty"),
    ([clip("clip"), node("sm", "STATE_MACHINE", [("a", "clip"), ("a", "clip")])], "sm",
     r"stream 'w': node 'sm': state names must be unique"),
    ([clip("clip"), node("s", "BLEND_SPACE", ["clip"], x_parameter="")], "s",
     r"node 's': a blend space needs x and y parameter names"),
    ([clip("clip", action=None)], "", r"stream 'w': node 'clip': no action chosen"),
    ([clip("clip"), node("odd", "WARP", ["clip"])], "odd",
     r"node 'odd': unknown node kind 'WARP'"),
])
def test_bad_graphs_name_what_is_at_fault(nodes, root, message):
    with pytest.raises(CrowdError, match=message):
        build(nodes, root)


def test_nodes_not_reached_from_the_root_are_not_built():
    """Only the root's tree is built: an unused node with a bad mask is no error."""
    stray = node("l", "LAYER", ["clip", "clip"], mask_source="COLLECTION",
                 mask_collection="Legs")
    assert isinstance(build([clip("clip"), stray]), ClipPlayer)
