"""The crowd animation core: pure numpy, no bpy/gpu/pxr (DESIGN.md s.2).

Paper terms -> modules: StreamPool, pose history, UniquePool, agents ->
:mod:`.crowd`; controllers -> :mod:`.controllers`; transition slots ->
:mod:`.transitions`; dependency graph -> :mod:`.graph`; pose texture ->
:mod:`.pose_storage`; skinning -> :mod:`.skinning`; memory model -> :mod:`.budget`.
"""

from .agents import STREAM, TRANSITION, UNIQUE, assign_offsets, assign_streams
from .clip import Clip, ClipBank
from .config import AnimationDef, CrowdConfig
from .controllers import (Blend2, BlendMask, BlendSpace2D, ClipPlayer, Controller, Layer,
                          StateMachine, StateTransition, blend_space_weights)
from .crowd import Crowd, StepReport
from .errors import CrowdError
from .events import EventDispatcher
from .graph import DependencyGraph, TreeEvaluator
from .pose import identity_pose, make_pose
from .pose_storage import PoseStorage, UploadRegion
from .skeleton import Skeleton
from .skinning import SkinningPlan, model_matrices, skin_vertices, skinning_matrices
from .transitions import TransitionResult

__all__ = [
    "STREAM", "UNIQUE", "TRANSITION", "assign_offsets", "assign_streams", "Clip", "ClipBank",
    "AnimationDef", "CrowdConfig", "Controller", "ClipPlayer", "Blend2", "BlendMask",
    "Layer", "BlendSpace2D", "StateMachine", "StateTransition", "blend_space_weights",
    "Crowd", "StepReport", "CrowdError", "EventDispatcher", "DependencyGraph",
    "TreeEvaluator", "identity_pose", "make_pose", "PoseStorage", "UploadRegion",
    "Skeleton", "SkinningPlan", "model_matrices", "skinning_matrices", "skin_vertices",
    "TransitionResult",
]
