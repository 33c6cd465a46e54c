"""The crowd as scene data: PropertyGroups saved in the .blend (``scene.crowd``).

A stream (or unique animation) is a controller tree written as a flat list of named
nodes; a node's inputs name other nodes of the same animation, and the root is the
node named by ``root`` (default: the first node); core validates and builds it
(:mod:`crowd_addon.core.authoring.controller_graph`). Node kinds mirror the core controllers
(``crowd_addon.core.anim.controllers``, ``.blends`` and ``.state_machine``): an action
clip, a 2-way blend, a layer (override or additive, masked by bone names or a bone
collection), a 2-D blend space (inputs placed at (x, y) points) and a state machine
(inputs are its states; transitions fire on triggers and parameter conditions with a fade).

A scene has a list of characters (``scene.crowd.characters``): each an armature, the
body mesh skinned to it, optional LOD meshes, and its own streams and unique
animations (stream and unique names are unique across the scene, since the crowd
plays them all). Agents come from agent sources (mesh vertices, a vertex group or
instanced points, see :mod:`.agents`), which choose a character per agent and then
one of that character's streams. Nothing here holds runtime state except
``preview_enabled``, which :mod:`.preview` reads after a file load, an undo and
registration to restart the preview.
"""

import math

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       FloatVectorProperty, IntProperty, PointerProperty, StringProperty)
from bpy.types import PropertyGroup

from ..core.authoring import controller_graph
from . import show_props
from ..core.bake.clip_sampling import MAX_SAMPLES_PER_FRAME

__all__ = ["CLASSES", "NODE_KINDS", "settings_fingerprint", "CROWD_PG_character"]

_NODE_LABELS = {
    "CLIP": ("Action", "Play an action (baked into a clip) at a speed from a start frame"),
    "BLEND2": ("Blend", "Blend two inputs by a weight or a parameter"),
    "LAYER": ("Layer", "Override or add a second input on top of the first, on masked bones"),
    "BLEND_SPACE": ("Blend Space", "Inputs at (x, y) points weighted by two parameters"),
    "STATE_MACHINE": ("State Machine", "Inputs are states; triggers and conditions switch "
                                       "between them with a fade"),
}
#: enum items of a node's kind, one per core node kind
NODE_KINDS = tuple((kind, *_NODE_LABELS[kind]) for kind in controller_graph.NODE_KINDS)
_OPS = tuple((op, op, f"parameter {op} value") for op in ("<", "<=", ">", ">=", "==", "!="))


def _is_armature(_self, obj):
    return obj.type == "ARMATURE"


def _is_mesh(_self, obj):
    return obj.type == "MESH"


class CROWD_PG_input(PropertyGroup):
    """An input of a node: another node of the same animation (``name`` is the label,
    or the state name in a state machine)."""

    node: StringProperty(name="Node", description="Name of the node this input reads")
    x: FloatProperty(name="X", description="Blend space sample position, x")
    y: FloatProperty(name="Y", description="Blend space sample position, y")


class CROWD_PG_state_transition(PropertyGroup):
    source: StringProperty(name="From", default="*",
                           description="State the transition leaves ('*': any state)")
    target: StringProperty(name="To", description="State the transition enters")
    duration: FloatProperty(name="Fade", default=8.0, min=0.0,
                            description="Cross-fade length in frames (0 cuts)")
    trigger: StringProperty(name="Trigger",
                            description="Fires when this trigger is set on the stream")
    condition_parameter: StringProperty(
        name="Parameter", description="Fires while 'parameter op value' holds (empty: no "
                                      "condition)")
    condition_op: EnumProperty(name="Op", items=_OPS, default=">")
    condition_value: FloatProperty(name="Value")


class CROWD_PG_node(PropertyGroup):
    kind: EnumProperty(name="Kind", items=NODE_KINDS, default="CLIP")
    # CLIP
    action: PointerProperty(name="Action", type=bpy.types.Action)
    speed: FloatProperty(name="Speed", default=1.0,
                         description="Playback speed (1: the action's own speed)")
    start: FloatProperty(name="Start", default=0.0,
                         description="Frame of the action (from its first frame) shown at "
                                     "time 0")
    # inputs of BLEND2 / LAYER / BLEND_SPACE / STATE_MACHINE
    inputs: CollectionProperty(type=CROWD_PG_input)
    active_input_index: IntProperty()
    # BLEND2 / LAYER
    weight: FloatProperty(name="Weight", default=0.5, min=0.0, max=1.0)
    weight_parameter: StringProperty(
        name="Weight Parameter", description="When set, the weight is this stream "
                                             "parameter (crowd_addon.api.set_parameter)")
    # LAYER
    layer_mode: EnumProperty(name="Mode", default="OVERRIDE", items=(
        ("OVERRIDE", "Override", "Blend toward the layer pose on the masked bones"),
        ("ADDITIVE", "Additive", "Add the layer's difference to its reference pose")))
    mask_source: EnumProperty(name="Mask", default="ALL", items=(
        ("ALL", "All Bones", "The layer covers every bone"),
        ("BONES", "Bone Names", "Comma-separated bone names"),
        ("COLLECTION", "Bone Collection", "The bones of an armature bone collection")))
    mask_bones: StringProperty(name="Bones", description="Comma-separated bone names")
    mask_collection: StringProperty(name="Bone Collection")
    reference_action: PointerProperty(
        name="Reference", type=bpy.types.Action,
        description="Additive layers: the action whose pose is the zero of the difference "
                    "(empty: the rest pose)")
    reference_frame: FloatProperty(name="Reference Frame", default=0.0, min=0.0)
    # BLEND_SPACE
    x_parameter: StringProperty(name="X Parameter", default="x")
    y_parameter: StringProperty(name="Y Parameter", default="y")
    # STATE_MACHINE
    transitions: CollectionProperty(type=CROWD_PG_state_transition)
    active_transition_index: IntProperty()
    initial_state: StringProperty(name="Initial State",
                                  description="Empty: the first input")


class CROWD_PG_animation(PropertyGroup):
    """A stream (shared, with pose history) or a unique animation."""

    nodes: CollectionProperty(type=CROWD_PG_node)
    active_node_index: IntProperty()
    root: StringProperty(name="Root", description="Node the animation outputs (empty: the "
                                                  "first node)")
    weight: FloatProperty(name="Weight", default=1.0, min=0.0,
                          description="Relative share of randomly assigned agents")
    speed_min: FloatProperty(
        name="Speed Min", default=1.0, min=0.05, soft_max=4.0,
        description="Timing variation (streams only): the slowest an agent plays this "
                    "stream, as a factor of its speed")
    speed_max: FloatProperty(
        name="Speed Max", default=1.0, min=0.05, soft_max=4.0,
        description="Timing variation (streams only): the fastest an agent plays this "
                    "stream, as a factor of its speed")
    speed_streams: IntProperty(
        name="Speed Streams", default=1, min=1, max=16,
        description="Streams at speeds spread over the range; each agent plays the one "
                    "nearest the speed it draws (CPU cost is per stream, not per agent)")
    copies: IntProperty(
        name="Copies", default=1, min=1, max=16,
        description="Copies of each speed stream, each M frames further into the "
                    "animation: agents spread over more poses without a longer history")


class CROWD_PG_lod(PropertyGroup):
    """A level of detail of a character: a mesh skinned to the character's armature."""

    object: PointerProperty(name="Mesh", type=bpy.types.Object, poll=_is_mesh,
                            description="Mesh skinned to the character's armature (by an "
                                        "Armature modifier), drawn at this level")


#: colours a palette may hold
PALETTE_COLOURS = 8
_PALETTE_DEFAULTS = ((0.8, 0.1, 0.1), (0.1, 0.25, 0.8), (0.95, 0.85, 0.2), (0.1, 0.6, 0.2),
                     (0.9, 0.9, 0.9), (0.1, 0.1, 0.1), (0.9, 0.45, 0.1), (0.5, 0.2, 0.6))


class CROWD_PG_palette(PropertyGroup):
    """Colours for one material slot of the character's body: each agent wears one
    (docs/variety.md)."""

    material: StringProperty(
        name="Material", description="The body's material these colours replace on each "
                                     "agent (shirt, hair...)")
    mode: EnumProperty(name="Choice", default="RANDOM", items=(
        ("RANDOM", "Random", "Each agent one of the colours at random (seeded)"),
        ("ATTRIBUTE", "Attribute", "An INT point attribute of the agent source gives the "
                                   "colour's index (a team, a section)")))
    attribute: StringProperty(name="Attribute", default="team",
                              description="INT point attribute: the colour's index, from 0")
    count: IntProperty(name="Colours", default=2, min=1, max=PALETTE_COLOURS,
                       description="How many of the colours below are in the palette")
    for _i, _c in enumerate(_PALETTE_DEFAULTS):
        __annotations__[f"color_{_i}"] = FloatVectorProperty(
            name=f"Colour {_i}", subtype="COLOR", size=3, min=0.0, max=1.0, default=_c)
    del _i, _c

    def colors(self) -> tuple:
        return tuple(tuple(getattr(self, f"color_{i}")) for i in range(self.count))


class CROWD_PG_variant(PropertyGroup):
    """A further body of a character (a mesh variant): skinned to the same armature,
    worn by a share of its agents (docs/variety.md)."""

    object: PointerProperty(name="Mesh", type=bpy.types.Object, poll=_is_mesh,
                            description="Mesh skinned to the character's armature (by an "
                                        "Armature modifier): another body for its agents")
    weight: FloatProperty(name="Weight", default=1.0, min=0.0,
                          description="Relative share of the character's agents wearing "
                                      "this body (the main body has Body Weight)")


class CROWD_PG_prop(PropertyGroup):
    """An object a share of the character's agents carry, moving rigidly with one bone
    (a flag, a scarf, a cup; docs/variety.md)."""

    object: PointerProperty(name="Object", type=bpy.types.Object, poll=_is_mesh,
                            description="Mesh placed where it sits on the character now; "
                                        "it follows the bone rigidly (parent it to the "
                                        "bone to see it move in Blender too)")
    bone: StringProperty(name="Bone", description="The armature bone it moves with "
                                                 "(empty: the bone it is parented to)")
    share: FloatProperty(name="Share", default=0.5, min=0.0, max=1.0, subtype="FACTOR",
                         description="Share of the character's agents that carry it "
                                     "(each agent drawn at random, seeded)")


class CROWD_PG_character(PropertyGroup):
    """A character: a rig, the body that draws it and the animations it plays."""

    armature: PointerProperty(name="Armature", type=bpy.types.Object, poll=_is_armature,
                              description="The rig this character's streams animate")
    body: PointerProperty(name="Body", type=bpy.types.Object, poll=_is_mesh,
                          description="Mesh skinned to the armature that draws each agent "
                                      "(empty: the agents run but are not drawn)")
    lods: CollectionProperty(type=CROWD_PG_lod)
    active_lod_index: IntProperty()
    streams: CollectionProperty(type=CROWD_PG_animation)
    active_stream_index: IntProperty()
    uniques: CollectionProperty(type=CROWD_PG_animation)
    active_unique_index: IntProperty()
    weight: FloatProperty(name="Weight", default=1.0, min=0.0,
                          description="Relative share of agents from sources that choose "
                                      "characters by weight")
    palettes: CollectionProperty(type=CROWD_PG_palette)
    active_palette_index: IntProperty()
    body_weight: FloatProperty(name="Body Weight", default=1.0, min=0.0,
                               description="Relative share of the agents wearing the main "
                                           "body when the character has mesh variants")
    variants: CollectionProperty(type=CROWD_PG_variant)
    active_variant_index: IntProperty()
    variant_mode: EnumProperty(name="Variant", default="RANDOM", items=(
        ("RANDOM", "Random", "Each agent a body at random by the weights (seeded)"),
        ("ATTRIBUTE", "Attribute", "An INT point attribute of the agent source gives the "
                                   "body: 0 the main body, 1 the first variant...")))
    variant_attribute: StringProperty(name="Attribute", default="variant",
                                      description="INT point attribute: 0 the main body, 1 "
                                                  "the first variant, ...")
    props: CollectionProperty(type=CROWD_PG_prop)
    active_prop_index: IntProperty()
    # -- look-at (docs/show.md, "Look-at"): the chain that turns toward a look target
    look_bones: StringProperty(
        name="Look Bones",
        description="The bones that turn the head toward a look target, comma-separated, "
                    "parent first, the aimed bone last (e.g. \"neck, head\"; a chest first "
                    "turns the upper body too). Empty: the character does not look at "
                    "things")
    look_shares: StringProperty(
        name="Shares",
        description="Each look bone's share of the turn, comma-separated in the same order, "
                    "summing to 1 (e.g. \"0.4, 0.6\"). Empty: equal shares")
    look_yaw_limit: FloatProperty(
        name="Yaw Limit", default=math.radians(75.0), min=0.0, max=math.pi,
        subtype="ANGLE", unit="ROTATION",
        description="The most the head turns sideways from the body's forward (the "
                    "Forward setting): a target further round is followed to this angle")
    look_pitch_limit: FloatProperty(
        name="Pitch Limit", default=math.radians(40.0), min=0.0, max=math.pi / 2,
        subtype="ANGLE", unit="ROTATION",
        description="The most the head turns up or down from the horizontal")


class CROWD_PG_agent_source(PropertyGroup):
    enabled: BoolProperty(name="Enabled", default=True)
    object: PointerProperty(name="Object", type=bpy.types.Object)
    mode: EnumProperty(name="From", default="VERTICES", items=(
        ("VERTICES", "Vertices", "One agent per vertex of the evaluated mesh"),
        ("VERTEX_GROUP", "Vertex Group", "One agent per vertex with weight > 0 in a group"),
        ("INSTANCES", "Instances", "One agent per instance the object generates "
                                   "(particles, instancing, geometry nodes)")))
    vertex_group: StringProperty(name="Vertex Group")
    heading_mode: EnumProperty(name="Heading", default="FIXED", items=(
        ("FIXED", "Fixed", "Every agent turned by the same angle (instances: their own "
                           "rotation added)"),
        ("ATTRIBUTE", "Attribute", "A FLOAT point attribute in radians about +Z"),
        ("TARGET", "Face Object", "Every agent faces an object")))
    heading: FloatProperty(name="Angle", subtype="ANGLE", unit="ROTATION")
    heading_attribute: StringProperty(name="Heading Attribute", default="heading")
    heading_target: PointerProperty(name="Target", type=bpy.types.Object)
    character_mode: EnumProperty(name="Character", default="WEIGHTS", items=(
        ("WEIGHTS", "By Weight", "Drawn with the characters' weights and the seed"),
        ("ATTRIBUTE", "Attribute", "An INT point attribute: the character's index in the "
                                   "list"),
        ("FIXED", "One Character", "All agents are one character")))
    character_attribute: StringProperty(name="Character Attribute", default="character")
    character_name: StringProperty(name="Character")
    stream_mode: EnumProperty(name="Stream", default="RANDOM", items=(
        ("RANDOM", "Random", "Drawn with the weights of the character's streams and the "
                             "seed"),
        ("ATTRIBUTE", "Attribute", "An INT point attribute: the stream's index among the "
                                   "character's streams"),
        ("FIXED", "One Stream", "All agents play one stream (of their character)")))
    stream_attribute: StringProperty(name="Stream Attribute", default="stream")
    stream_name: StringProperty(name="Stream")
    offset_mode: EnumProperty(name="Offset", default="UNIFORM", items=(
        ("UNIFORM", "Uniform", "Every offset 0..M-1 equally likely"),
        ("NORMAL", "Normal", "Around a mean, rounded and clipped to 0..M-1"),
        ("SPREAD", "Spread", "Neighbours playing the same stream kept out of step (least "
                             "repetition, docs/variety.md)"),
        ("ATTRIBUTE", "Attribute", "An INT point attribute in 0..M-1")))
    offset_mean: FloatProperty(name="Mean", default=-1.0,
                               description="Frames (negative: the middle of 0..M-1)")
    offset_std: FloatProperty(name="Deviation", default=-1.0,
                              description="Frames (negative: M / 6)")
    offset_attribute: StringProperty(name="Offset Attribute", default="offset")
    color_mode: EnumProperty(name="Colour", default="RANDOM", items=(
        ("RANDOM", "Random", "The base colour varied at random per agent"),
        ("ATTRIBUTE", "Attribute", "A colour or vector point attribute")))
    color: FloatVectorProperty(name="Base Colour", subtype="COLOR", size=3, min=0.0,
                               max=1.0, default=(0.8, 0.8, 0.8))
    color_variation: FloatProperty(name="Variation", default=0.5, min=0.0, max=1.0,
                                   subtype="FACTOR")
    color_attribute: StringProperty(name="Colour Attribute", default="Col")
    scale_min: FloatProperty(
        name="Scale Min", default=1.0, min=0.05, soft_max=3.0,
        description="Each agent's body is scaled uniformly by a factor drawn between Scale "
                    "Min and Scale Max (seeded): a range of heights")
    scale_max: FloatProperty(
        name="Scale Max", default=1.0, min=0.05, soft_max=3.0,
        description="Each agent's body is scaled uniformly by a factor drawn between Scale "
                    "Min and Scale Max (seeded): a range of heights")


_LOD_VIEW = ("as seen in a 1080-pixel-high view with a 40° field of view (smaller views "
             "switch sooner, zoomed-in ones later)")


def _render_crowd_changed(settings, context):
    from . import preview
    preview.render_crowd_changed(settings.id_data)


class CROWD_PG_settings(PropertyGroup):
    characters: CollectionProperty(type=CROWD_PG_character)
    active_character_index: IntProperty()
    max_offset: IntProperty(name="Max Offset (M)", default=60, min=1, soft_max=600,
                            description="Frames of pose history per stream; agents play "
                                        "a stream delayed by 0..M-1 frames")
    transition_slots: IntProperty(name="Transition Slots (NT)", default=64, min=0,
                                  description="Agents that can blend between animations "
                                              "at the same time")
    when_full: EnumProperty(name="When Full", default="QUEUE", items=(
        ("QUEUE", "Queue", "Wait for a free slot"),
        ("CUT", "Cut", "Switch at once without blending")))
    seed: IntProperty(name="Seed", default=0, min=0)
    samples_per_frame: IntProperty(
        name="Samples per Frame", default=1, min=1, max=MAX_SAMPLES_PER_FRAME,
        description="Keys baked per scene frame. The clips play at the same speed; more "
                    "samples follow the action between frames (speeds other than 1, motion "
                    "blur, rotations that wrap between frames) at that many times the "
                    "memory")
    forward_axis: EnumProperty(name="Forward", default="NEG_Y", items=(
        ("NEG_Y", "-Y", "The character faces -Y in its rest pose"),
        ("POS_Y", "+Y", "The character faces +Y in its rest pose"),
        ("POS_X", "+X", "The character faces +X in its rest pose"),
        ("NEG_X", "-X", "The character faces -X in its rest pose")),
        description="Used to turn agents toward a target, and the way a character's "
                    "head faces at rest for its look rig")
    lod_near: FloatProperty(name="LOD 1 From", default=30.0, min=0.01, unit="LENGTH",
                            description="Distance from which agents use the first coarser "
                                        "mesh (a character's first LOD mesh, or 25% of the "
                                        "triangles), " + _LOD_VIEW)
    lod_far: FloatProperty(name="LOD 2 From", default=60.0, min=0.01, unit="LENGTH",
                           description="Distance from which agents use the second coarser "
                                       "mesh (a character's second LOD mesh, or 6% of the "
                                       "triangles), " + _LOD_VIEW)
    lod_cards: BoolProperty(name="Far Cards", default=True,
                            description="Draw the farthest agents as a box per body part "
                                        "(8 vertices each) that follows its bone")
    lod_card: FloatProperty(name="Cards From", default=90.0, min=0.01, unit="LENGTH",
                            description="Distance from which agents are drawn as "
                                        "cards, " + _LOD_VIEW)
    lod_joined: FloatProperty(name="Joined Boxes From", default=180.0, min=0.01,
                              unit="LENGTH",
                              description="Distance from which agents are drawn with "
                                          "their small parts' boxes joined (fewer boxes, "
                                          "when they pass the silhouette check there), "
                                          + _LOD_VIEW)
    agent_sources: CollectionProperty(type=CROWD_PG_agent_source)
    show: PointerProperty(type=show_props.CROWD_PG_show,
                          description="Cues, reactions and animated parameters "
                                      "(docs/show.md)")
    active_source_index: IntProperty()
    render_crowd: BoolProperty(
        name="Render Crowd", default=False, update=_render_crowd_changed,
        description="Make the previewed crowd ordinary Blender data (shared pose meshes "
                    "instanced on a points object by Geometry Nodes) so F12, viewport "
                    "renders and playblasts show it; updated on every frame change")
    preview_enabled: BoolProperty(
        name="Preview", default=False, options=set(),
        description="Whether the viewport preview runs (restarted after a file load or "
                    "an undo; in background mode only when Render Crowd needs it)")
    repetition_neighbours: IntProperty(
        name="Neighbours", default=6, min=1, max=64,
        description="Repetition metric: screen-space neighbours each agent is compared "
                    "with (docs/variety.md)")
    plan_budget_mb: FloatProperty(
        name="Budget (MB)", default=520.0, min=0.001,
        description="Plan Variety: GPU memory the pose texture may use, MB of 10^6 bytes "
                    "(default: the paper's 520)")
    plan_max_streams: IntProperty(
        name="Max Streams", default=256, min=1,
        description="Plan Variety: the most streams a plan may use (each costs CPU time "
                    "every frame; the paper's 256 by default)")
    plan_motion_only: BoolProperty(
        name="Motion Only", default=False,
        description="Plan Variety: compare motion alone (agents in step are alike "
                    "whatever their bodies and colours): what a plan changes")


CLASSES = show_props.CLASSES + (CROWD_PG_input, CROWD_PG_state_transition, CROWD_PG_node, CROWD_PG_animation,
           CROWD_PG_lod, CROWD_PG_palette, CROWD_PG_variant, CROWD_PG_prop,
           CROWD_PG_character, CROWD_PG_agent_source,
           CROWD_PG_settings)


def _values(struct, skip):
    """A hashable tuple of every saved property of ``struct`` (recursively); ID
    pointers contribute their names."""
    out = []
    for prop in struct.bl_rna.properties:
        key = prop.identifier
        if key in skip or key == "rna_type":
            continue
        value = getattr(struct, key)
        if prop.type == "COLLECTION":
            out.append((key, tuple(_values(item, skip) for item in value)))
        elif prop.type == "POINTER":
            out.append((key, None if value is None else
                        (value.name if isinstance(value, bpy.types.ID)
                         else _values(value, skip))))
        elif getattr(prop, "is_array", False):
            out.append((key, tuple(value)))
        else:
            out.append((key, value))
    return tuple(out)


_UI_ONLY = {"active_character_index", "active_lod_index", "active_stream_index",
            "active_unique_index", "active_source_index", "active_node_index",
            "active_input_index", "active_transition_index", "preview_enabled",
            "active_cue_index", "active_reaction_index", "active_parameter_index",
            "active_look_target_index",
            "active_palette_index", "active_variant_index", "active_prop_index",
            "render_crowd", "repetition_neighbours", "plan_budget_mb", "plan_max_streams",
            "plan_motion_only"}


def settings_fingerprint(settings) -> int:
    """Hash of everything in ``scene.crowd`` a built crowd depends on (UI list indices
    and the preview switch excluded); equal settings give equal fingerprints."""
    from .show_data import show_fingerprint
    return hash((_values(settings, _UI_ONLY | show_props.ANIMATED),
                 show_fingerprint(settings.id_data)))
