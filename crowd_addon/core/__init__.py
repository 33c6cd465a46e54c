"""The crowd animation core: pure numpy; imports no bpy, gpu, moderngl or pxr and
nothing else of this project (docs/architecture.md maps the paper's terms to modules).

Sub-packages, each importing only those before it (tests/test_layering.py):
:mod:`.base` (errors, bounds, quaternions, poses, skeletons, skinning maths, cameras),
:mod:`.anim` (clips, controllers, the tree evaluator and dependency graph),
:mod:`.bake` (actions and armatures as numpy), :mod:`.meshes` (proxies, LODs, bodies),
:mod:`.runtime` (agents, pools, slots, events, pose texture, skinning modes, look-at),
:mod:`.variety` (repetition, timing variation), :mod:`.authoring` (configs, files,
shows, placement, seats), :mod:`.planning` (memory model, variety planner) and
:mod:`.shots` (the Crowd facade, show runner, snapshots, recordings).
"""

from .runtime.agents import STREAM, TRANSITION, UNIQUE, assign_offsets, assign_streams
from .anim.clip import Clip, ClipBank
from .authoring.config import AnimationDef, CrowdConfig, validate_config
from .anim.blends import Blend2, BlendMask, BlendSpace2D, Layer, blend_space_weights
from .anim.controllers import ClipPlayer, Controller
from .anim.state_machine import StateMachine, StateTransition
from .shots.crowd import Crowd
from .shots.frame import StepReport
from .runtime.frame_view import FrameView
from .base.errors import CrowdError
from .runtime.events import EventDispatcher
from .anim.graph import DependencyGraph, TreeEvaluator
from .base.pose import identity_pose, make_pose
from .runtime.pose_storage import PoseStorage, TextureRegion
from .base.skeleton import Skeleton
from .base.skinning import SkinningPlan, model_matrices, skin_vertices, skinning_matrices
from .runtime.skinning_modes import CpuSkinning, GpuSkinning, SkinningBatch
from .runtime.transitions import TransitionResult

__all__ = [
    "STREAM", "UNIQUE", "TRANSITION", "assign_offsets", "assign_streams", "Clip", "ClipBank",
    "AnimationDef", "CrowdConfig", "Controller", "ClipPlayer", "Blend2", "BlendMask",
    "Layer", "BlendSpace2D", "StateMachine", "StateTransition", "blend_space_weights",
    "Crowd", "StepReport", "CrowdError", "EventDispatcher", "DependencyGraph",
    "TreeEvaluator", "identity_pose", "make_pose", "PoseStorage", "TextureRegion",
    "Skeleton", "SkinningPlan", "model_matrices", "skinning_matrices", "skin_vertices",
    "TransitionResult", "validate_config", "FrameView", "CpuSkinning", "GpuSkinning",
    "SkinningBatch",
]
