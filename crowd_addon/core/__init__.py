"""The crowd animation core: pure numpy; imports no bpy, gpu, moderngl or pxr and
nothing else of this project (docs/architecture.md maps the paper's terms to modules).

Paper terms -> modules: StreamPool, pose history, UniquePool -> :mod:`.pools`; agents
-> :mod:`.agents`; transition slots and their request policy -> :mod:`.transitions`;
event tags -> :mod:`.events`; controllers -> :mod:`.controllers`; dependency graph ->
:mod:`.graph`; pose texture -> :mod:`.pose_storage`; skinning -> :mod:`.skinning` and
:mod:`.skinning_modes`; the runtime facade -> :mod:`.crowd`, read through
:mod:`.frame_view`; memory model -> :mod:`.budget`.
"""

from .agents import STREAM, TRANSITION, UNIQUE, assign_offsets, assign_streams
from .clip import Clip, ClipBank
from .config import AnimationDef, CrowdConfig, validate_config
from .controllers import (Blend2, BlendMask, BlendSpace2D, ClipPlayer, Controller, Layer,
                          StateMachine, StateTransition, blend_space_weights)
from .crowd import Crowd, StepReport
from .frame_view import FrameView
from .errors import CrowdError
from .events import EventDispatcher
from .graph import DependencyGraph, TreeEvaluator
from .pose import identity_pose, make_pose
from .pose_storage import PoseStorage, TextureRegion
from .skeleton import Skeleton
from .skinning import SkinningPlan, model_matrices, skin_vertices, skinning_matrices
from .skinning_modes import CpuSkinning, GpuSkinning, SkinningBatch
from .transitions import TransitionResult

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
