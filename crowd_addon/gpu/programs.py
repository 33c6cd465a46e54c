"""What each crowd shader program declares: the one description both backends use.

The GLSL in ``gpu_shaders/`` holds only functions and ``main``; every input,
output, push constant, sampler and image is declared here, in the vocabulary of
Blender's ``gpu.types.GPUShaderCreateInfo`` (types ``"VEC3"``, sampler types
``"FLOAT_2D"``, image formats ``"RGBA32F"``). :mod:`.assembler` turns a
:class:`ProgramSpec` into ``#version`` + declarations + sources for moderngl, or
into the create-info calls for Blender's ``gpu`` module.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from importlib import resources

__all__ = ["SHADER_DIR", "Interface", "ProgramSpec", "CROWD_DRAW", "SCENE_DRAW", "SKIN_ROWS",
           "ROW_UPLOAD", "LOOK_TURNS", "AGENT_TEXELS", "LOOK_TURN_TEXELS", "SKIN_GROUP",
           "UPLOAD_GROUP", "LOOK_GROUP", "WIDE_INPUTS", "for_influences", "AGENT_GATHER",
           "AGENT_INPUTS", "AGENT_RECORD_TEXELS", "GATHER_GROUP", "with_agent_attributes"]

#: gpu_shaders/ (importlib.resources): the resource package beside crowd_addon, at the
#: top of the repository, of a wheel and of the Blender extension (there it is
#: ``bl_ext.<repo>.crowd_animation.gpu_shaders``, as crowd_addon is ``...crowd_addon``).
SHADER_DIR = resources.files(".".join(__name__.split(".")[:-3] + ["gpu_shaders"]))

#: RGBA32F texels per agent in the instance texture (gpu_shaders/agents.glsl).
AGENT_TEXELS = 3
#: Batch entries (rows) per compute work group of the skinning-rows shader.
SKIN_GROUP = 64
#: Texels per compute work group (along a row) of the row upload shader.
UPLOAD_GROUP = 64
#: RGBA32F texels per agent in the look turns texture: three ([R | t] rows) per chain
#: depth, for up to eight chain bones (gpu_shaders/looks.glsl, LOOK_TURN_TEXELS).
LOOK_TURN_TEXELS = 24
#: Agents per compute work group of the look turns shader.
LOOK_GROUP = 64
#: vec4 per draw list entry in the gathered agent records (agent_gather_comp.glsl):
#: the three agent texels and the look state texel (the agent id goes to an int
#: buffer of its own).
AGENT_RECORD_TEXELS = 4
#: Draw list entries per compute work group of the agent gather shader.
GATHER_GROUP = 64


@dataclass(frozen=True)
class Interface:
    """A vertex -> fragment interface block (``gpu.types.GPUStageInterfaceInfo``).

    ``members``: ``(qualifier, type, name)`` with qualifier ``"smooth"``, ``"flat"``
    or ``"no_perspective"``; the block has no instance name, so GLSL uses the
    member names directly.
    """

    name: str
    members: tuple


@dataclass(frozen=True)
class ProgramSpec:
    """One shader program: its stages' source files and its declarations.

    Stages are tuples of file names in ``gpu_shaders/``, libraries first, the file
    with ``main`` last. ``vertex_in``/``fragment_out``: ``(slot, type, name)``;
    ``push_constants``: ``(type, name)``; ``samplers``: ``(slot, sampler type,
    name)``; ``images``: ``(slot, format, image type, name, qualifiers)``;
    ``storage_buffers``: ``(slot, element type, name, qualifiers)``, an unsized array
    of that type (OpenGL only: Blender's ``gpu`` module declares none);
    ``defines``: names the caller must give values for (e.g. ``MAX_BONES``).
    """

    name: str
    vertex: tuple = ()
    fragment: tuple = ()
    compute: tuple = ()
    vertex_in: tuple = ()
    interfaces: tuple = ()
    push_constants: tuple = ()
    samplers: tuple = ()
    images: tuple = ()
    storage_buffers: tuple = ()
    fragment_out: tuple = ()
    local_group_size: tuple = ()
    defines: tuple = ()

    def stages(self) -> dict:
        """``{stage: source files}`` of the stages this program has."""
        return {k: v for k, v in (("vertex", self.vertex), ("fragment", self.fragment),
                                  ("compute", self.compute)) if v}


#: Instanced skinning of one (skeleton, LOD) draw and its lit shading.
CROWD_DRAW = ProgramSpec(
    name="crowd_draw",
    vertex=("block_layout.glsl", "pose_layout.glsl", "pose_rows.glsl", "agents.glsl",
            "skinning.glsl", "looks.glsl", "look_at.glsl", "crowd_vertex.glsl",
            "sun_coords.glsl", "crowd_vert.glsl"),
    fragment=("crowd_frag.glsl",),
    vertex_in=((0, "VEC3", "pos"), (1, "VEC3", "nor"), (2, "UVEC4", "bone_idx"),
               (3, "VEC4", "bone_w"), (6, "VEC4", "col"), (7, "UINT", "look_depth")),
    interfaces=(Interface("crowd_iface", (("smooth", "VEC3", "v_world"),
                                          ("smooth", "VEC3", "v_shadow"),
                                          ("smooth", "VEC3", "v_normal"),
                                          ("flat", "VEC3", "v_color"))),),
    push_constants=(("MAT4", "u_view_proj"), ("IVEC4", "u_pose_layout"),
                    ("IVEC4", "u_pose_regions"), ("IVEC4", "u_draw"),
                    ("VEC4", "u_light")),
    samplers=((0, "FLOAT_2D", "pose_tex"), (1, "FLOAT_2D", "agent_tex"),
              (2, "INT_2D", "agent_list_tex"), (3, "FLOAT_2D", "shadow_tex"),
              (4, "FLOAT_2D", "shadow_view_tex"), (5, "FLOAT_2D", "look_tex"),
              (6, "FLOAT_2D", "look_turn_tex")),
    fragment_out=((0, "VEC4", "frag_color"),),
    defines=("INFLUENCES", "SHADOWS", "ENCODE_SRGB"),
)

#: The scene around the crowd (:class:`~.scene_geometry.SceneGeometry`): plain
#: world-space triangles, lit by the crowd's own fragment stage.
SCENE_DRAW = ProgramSpec(
    name="scene_draw",
    vertex=("sun_coords.glsl", "scene_vert.glsl"),
    fragment=CROWD_DRAW.fragment,
    vertex_in=((0, "VEC3", "pos"), (1, "VEC3", "nor"), (2, "VEC3", "col")),
    interfaces=CROWD_DRAW.interfaces,
    push_constants=(("MAT4", "u_view_proj"), ("VEC4", "u_light")),
    samplers=((3, "FLOAT_2D", "shadow_tex"), (4, "FLOAT_2D", "shadow_view_tex")),
    fragment_out=CROWD_DRAW.fragment_out,
    defines=("SHADOWS", "ENCODE_SRGB"),
)

#: The vertex inputs a skinning program adds for meshes of five to eight influences a
#: vertex: influences 5..8 (``gpu_shaders/crowd_vertex.glsl`` reads them only when
#: ``INFLUENCES > 4``).
WIDE_INPUTS = ((4, "UVEC4", "bone_idx2"), (5, "VEC4", "bone_w2"))


def for_influences(spec: ProgramSpec, influences: int) -> ProgramSpec:
    """``spec`` (a program with the crowd vertex: :data:`CROWD_DRAW` or a capture
    program) for meshes of ``influences`` bones a vertex: itself up to four, else
    (one object per spec) with :data:`WIDE_INPUTS` declared and ``_wide`` added to its
    name."""
    return spec if int(influences) <= 4 else _wide(spec)


@lru_cache(maxsize=None)
def _wide(spec: ProgramSpec) -> ProgramSpec:
    return replace(spec, name=f"{spec.name}_wide", vertex_in=spec.vertex_in + WIDE_INPUTS)


#: The per-instance inputs of a draw program fed its agents as vertex attributes
#: (``AGENT_ATTRIBUTES`` 1, gpu_shaders/crowd_vertex.glsl): the records
#: :data:`AGENT_GATHER` writes, :data:`AGENT_RECORD_TEXELS` vec4 an instance, then the
#: agent's id from the ids buffer.
AGENT_INPUTS = ((8, "VEC4", "agent_in0"), (9, "VEC4", "agent_in1"), (10, "VEC4", "agent_in2"),
                (11, "VEC4", "agent_in3"), (12, "INT", "agent_in_id"))


@lru_cache(maxsize=None)
def with_agent_attributes(spec: ProgramSpec) -> ProgramSpec:
    """``spec`` (a draw program, :func:`for_influences` applied) reading each
    instance's agent from :data:`AGENT_INPUTS`: ``_attr`` added to its name; compile it
    with ``AGENT_ATTRIBUTES`` 1."""
    return replace(spec, name=f"{spec.name}_attr", vertex_in=spec.vertex_in + AGENT_INPUTS)


#: Local poses made skinning rows on the GPU, transition slots blended on the way
#: (paper s.4.5).
SKIN_ROWS = ProgramSpec(
    name="skin_rows",
    compute=("block_layout.glsl", "pose_layout.glsl", "sqt.glsl", "skin_rows_comp.glsl"),
    push_constants=(("IVEC4", "u_pose_layout"), ("INT", "u_batch_count")),
    samplers=((0, "FLOAT_2D", "local_tex"), (1, "FLOAT_2D", "skeleton_tex"),
              (2, "FLOAT_2D", "batch_tex")),
    images=((0, "RGBA32F", "FLOAT_2D", "pose_img", ("WRITE",)),),
    local_group_size=(SKIN_GROUP,),
    defines=("MAX_BONES",),
)

#: Staged rows written into a block-laid texture (pose, local pose or agent texture)
#: by backends without partial texture updates (Blender's gpu module).
ROW_UPLOAD = ProgramSpec(
    name="row_upload",
    compute=("block_layout.glsl", "row_upload_comp.glsl"),
    push_constants=(("IVEC4", "u_upload"),),
    samplers=((0, "FLOAT_2D", "staging_tex"), (1, "INT_2D", "row_index_tex")),
    images=((0, "RGBA32F", "FLOAT_2D", "dest_img", ("WRITE",)),),
    local_group_size=(UPLOAD_GROUP, 1),
)

#: The look's turns of every looking agent, once a frame, for the draws' vertex stage
#: (gpu_shaders/look_turns_comp.glsl): the chain's head direction, clamped yaw and
#: pitch and shared turn per agent, not per vertex.
LOOK_TURNS = ProgramSpec(
    name="look_turns",
    compute=("block_layout.glsl", "pose_layout.glsl", "pose_rows.glsl", "agents.glsl",
             "looks.glsl", "look_turns.glsl", "look_turns_comp.glsl"),
    push_constants=(("IVEC4", "u_pose_layout"), ("IVEC4", "u_pose_regions"),
                    ("IVEC4", "u_draw"), ("IVEC4", "u_looks")),
    samplers=((0, "FLOAT_2D", "pose_tex"), (1, "FLOAT_2D", "agent_tex"),
              (2, "INT_2D", "agent_list_tex"), (5, "FLOAT_2D", "look_tex"),
              (6, "FLOAT_2D", "look_target_tex"), (7, "FLOAT_2D", "look_chain_tex")),
    images=((0, "RGBA32F", "FLOAT_2D", "look_turn_img", ("WRITE",)),),
    local_group_size=(LOOK_GROUP,),
)

#: The draw lists' agent records gathered for the per-instance attribute feed
#: (moderngl, :func:`with_agent_attributes`): ``u_draw = (0, entries, 0, 0)``.
AGENT_GATHER = ProgramSpec(
    name="agent_gather",
    compute=("block_layout.glsl", "agents.glsl", "agent_gather_comp.glsl"),
    push_constants=(("IVEC4", "u_draw"),),
    samplers=((1, "FLOAT_2D", "agent_tex"), (2, "INT_2D", "agent_list_tex"),
              (5, "FLOAT_2D", "look_tex")),
    storage_buffers=((0, "VEC4", "records", ("WRITE",)),
                     (1, "INT", "record_ids", ("WRITE",))),
    local_group_size=(GATHER_GROUP,),
)
