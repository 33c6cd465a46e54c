"""The show as scene data (``scene.crowd.show``): cues, reactions, animated parameters.

What each setting means is the core's (docs/show.md, :mod:`crowd_addon.core.authoring.show`);
:mod:`.show_data` turns these into a core :class:`~crowd_addon.core.authoring.show.Show` when the
crowd is built, resolving selections against the agent sources. Parameter values are
ordinary animatable properties: keyframes and drivers on ``value`` are sampled over
the scene's frame range.
"""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       IntProperty, PointerProperty, StringProperty)
from bpy.types import PropertyGroup

__all__ = ["CLASSES", "CROWD_PG_cue", "CROWD_PG_reaction", "CROWD_PG_parameter",
           "CROWD_PG_look_target", "CROWD_PG_show", "ANIMATED"]

#: Identifiers of properties whose value changes with the frame (animated): left out
#: of the settings fingerprint; their F-curves and drivers count instead.
ANIMATED = {"value"}

_OPS = tuple((op, op, f"attribute {op} value") for op in ("==", "!=", "<", "<=", ">", ">="))


class CROWD_PG_cue(PropertyGroup):
    """At a frame, apply an action to a selection of agents."""

    mute: BoolProperty(name="Mute", description="A muted cue does nothing")
    timeline: BoolProperty(name="On Timeline", default=True,
                           description="Run at its frame; off: only reactions run it")
    frame: IntProperty(name="Frame", default=1, description="Frame the cue starts at")
    # -- action
    action: EnumProperty(name="Action", default="STREAM", items=(
        ("STREAM", "Go to Stream", "Blend the agents to a stream"),
        ("UNIQUE", "Play Unique", "Blend the agents to a unique animation, restarted"),
        ("TRIGGER", "Set Trigger", "Set a trigger on a stream or unique (state machines)"),
        ("PARAMETER", "Set Parameter", "Set a parameter of a stream or unique"),
        ("LOOK", "Look At", "Turn the agents' heads toward a look target (Show > Look "
                            "Targets); Blend is the blend in, Hold the time before they "
                            "look away (0: they keep looking)")))
    target: StringProperty(name="Target", description="Stream or unique animation name "
                                                      "(Look At: a look target's name)")
    duration: FloatProperty(name="Blend", default=8.0, min=0.0, soft_max=120.0,
                            description="Blend length in frames (0 cuts)")
    offset_mode: EnumProperty(name="Offset", default="KEEP", items=(
        ("KEEP", "Keep", "Each agent keeps its own offset"),
        ("RANDOM", "Random", "A random offset per agent (seeded)"),
        ("GIVEN", "Given", "Every agent at one offset")))
    offset: IntProperty(name="Offset Frames", default=0, min=0,
                        description="The offset every agent gets (Offset: Given)")
    when_full: EnumProperty(name="When Full", default="DEFAULT", items=(
        ("DEFAULT", "Crowd Setting", "As the crowd's When Full setting"),
        ("QUEUE", "Queue", "Wait for a free transition slot"),
        ("CUT", "Cut", "Switch at once when no slot is free")))
    hold: IntProperty(name="Hold", default=0, min=0,
                      description="Frames after which the agents go back to what they "
                                  "played before (0: they stay)")
    interrupt: BoolProperty(name="Interrupt",
                            description="Also move agents another cue is holding")
    switch_trigger: StringProperty(
        name="Switch Trigger",
        description="A mass reaction at no per-agent cost: agents on streams whose state "
                    "machine takes this trigger (and whose every agent the cue selects) stay "
                    "on their stream and follow it into the new state, each at its own "
                    "offset; only the others blend to the target through transition slots "
                    "(empty: every agent blends through slots)")
    release_trigger: StringProperty(
        name="Release Trigger",
        description="With a switch trigger and a hold: the trigger set on the switched "
                    "streams when the hold ends (the state machine's way back)")
    parameter: StringProperty(name="Name", description="Trigger or parameter name")
    set_value: FloatProperty(name="Value", description="Parameter value")
    # -- selection
    source: StringProperty(name="Source", description="Agent source (empty: every source)")
    select: EnumProperty(name="Select", default="ALL", items=(
        ("ALL", "All", "Every agent of the source"),
        ("ATTRIBUTE", "Attribute", "Agents whose source point attribute compares true"),
        ("GROUP", "Vertex Group", "Agents on vertices of a vertex group of the source"),
        ("INSIDE", "Inside Object", "Agents inside an object's bounding box")))
    attribute: StringProperty(name="Attribute", description="Point attribute of the source "
                                                            "mesh (INT, FLOAT or BOOLEAN)")
    op: EnumProperty(name="Op", items=_OPS, default="==")
    compare: FloatProperty(name="Compare", description="Value the attribute is compared with")
    vertex_group: StringProperty(name="Vertex Group",
                                 description="Vertex group of the source mesh (Select: "
                                             "Vertex Group)")
    bounds: PointerProperty(name="Bounds", type=bpy.types.Object,
                            description="Agents inside this object's bounding box")
    fraction: FloatProperty(name="Fraction", default=1.0, min=0.0, max=1.0, subtype="FACTOR",
                            description="Keep a random share of the selection")
    seed: IntProperty(name="Seed", default=0, min=0,
                      description="Seed of the random fraction, spread and offsets")
    # -- timing
    timing: EnumProperty(name="Timing", default="AT_ONCE", items=(
        ("AT_ONCE", "At Once", "Every agent at the cue's frame"),
        ("SPREAD", "Spread", "Each agent at a random frame of a range"),
        ("SWEEP", "Sweep", "A front that reaches the agents in turn (a Mexican wave)")))
    spread: IntProperty(name="Over Frames", default=10, min=0,
                        description="Frames over which the agents start (Timing: Spread)")
    sweep_mode: EnumProperty(name="Sweep", default="ANGLE", items=(
        ("ANGLE", "Around", "In order of angle around the centre"),
        ("DISTANCE", "Away", "In order of distance from the centre")))
    sweep_centre: PointerProperty(name="Centre", type=bpy.types.Object,
                                  description="Object whose location is the centre "
                                              "(empty: the world origin)")
    sweep_speed: FloatProperty(name="Speed", default=0.5,
                               description="Radians per second around (negative: "
                                           "clockwise) or metres per second away")
    sweep_start: FloatProperty(name="Start Angle", subtype="ANGLE", unit="ROTATION",
                               description="Where the front starts, from +X")
    sweep_laps: IntProperty(name="Laps", default=1, min=1,
                            description="Times the front goes round (Sweep: Around)")


class CROWD_PG_reaction(PropertyGroup):
    """When an event fires, run a cue's action on those agents (or near them)."""

    mute: BoolProperty(name="Mute", description="A muted reaction does nothing")
    event: StringProperty(name="Event", description="Event tag (an action's pose marker)")
    source: StringProperty(name="Playing", description="Only agents playing this stream "
                                                       "or unique (empty: any)")
    cue: StringProperty(name="Cue", description="The cue whose action runs")
    radius: FloatProperty(name="Radius", default=0.0, min=0.0, unit="LENGTH",
                          description="Also every agent this close (0: only them)")


class CROWD_PG_parameter(PropertyGroup):
    """A parameter (or trigger) of a stream or unique, animatable like any property."""

    target: StringProperty(name="Target", description="Stream or unique animation name")
    kind: EnumProperty(name="Kind", default="PARAMETER", items=(
        ("PARAMETER", "Parameter", "The value is the parameter, every frame"),
        ("TRIGGER", "Trigger", "The trigger fires when the value rises above 0.5")))
    value: FloatProperty(name="Value", description="Keyframe or drive it")


class CROWD_PG_look_target(PropertyGroup):
    """A point the agents can look at (a *Look At* cue names it): an object's world
    position, sampled at every frame of the scene's range when the crowd is built."""

    object: PointerProperty(name="Object", type=bpy.types.Object,
                            description="The object whose world position the agents look "
                                        "at (an animated ball, a player); sampled at "
                                        "every frame of the scene's range when the crowd "
                                        "is built, once when it is not animated")
    smoothing: FloatProperty(name="Smoothing", default=4.0, min=0.0, soft_max=30.0,
                             description="Frames the agents take to follow the target: a "
                                         "sudden move is 63 % followed after this many "
                                         "frames (0: followed exactly)")


class CROWD_PG_show(PropertyGroup):
    cues: CollectionProperty(type=CROWD_PG_cue)
    active_cue_index: IntProperty()
    reactions: CollectionProperty(type=CROWD_PG_reaction)
    active_reaction_index: IntProperty()
    parameters: CollectionProperty(type=CROWD_PG_parameter)
    active_parameter_index: IntProperty()
    look_targets: CollectionProperty(type=CROWD_PG_look_target)
    active_look_target_index: IntProperty()
    look_lag: EnumProperty(name="Look Lag", default="OFFSET", items=(
        ("OFFSET", "Offset", "Each agent sees the target as late as its animation offset "
                             "(0 .. M-1 frames: a stand spread over its streams' spread)"),
        ("SEEDED", "Seeded", "Each agent sees the target late by a seeded delay of 0 .. "
                             "Max Lag frames")),
        description="How late each agent follows a look target, so a stand does not "
                    "turn as one")
    look_max_lag: IntProperty(name="Max Lag", default=12, min=0, soft_max=60,
                              description="The longest delay in frames (Look Lag: Seeded)")
    script: PointerProperty(
        name="Script", type=bpy.types.Text,
        description="A Python module (a text in this file) whose register(crowd) runs "
                    "each time the crowd is built, in the preview and in exports; it "
                    "runs only where scripts in .blend files are trusted")


CLASSES = (CROWD_PG_cue, CROWD_PG_reaction, CROWD_PG_parameter, CROWD_PG_look_target,
           CROWD_PG_show)
