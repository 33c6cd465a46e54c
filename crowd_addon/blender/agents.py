"""Agents from scene geometry: one agent per vertex, vertex-group member or instance.

Each agent source (``scene.crowd.agent_sources``, :class:`.props.CROWD_PG_agent_source`)
gives world positions (metres) and base headings (radians about +Z) of its points,
read from the depsgraph-evaluated object (modifiers and geometry nodes applied) with
``foreach_get`` into numpy; only the vertex-group filter walks the vertices, because
Blender exposes no array access to group weights. The placement policy (headings,
a character and one of its streams per agent, an offset in ``0 .. M-1`` frames, a
colour) is :func:`crowd_addon.core.authoring.placement.place_agents`, with the source's
settings as a :class:`~crowd_addon.core.authoring.placement.PlacementPolicy`, the scene's
characters as :class:`~crowd_addon.core.authoring.placement.CharacterStreams` and its point
attributes read here. Random choices are seeded from ``scene.crowd.seed`` and the
source's index, so the same scene gives the same agents.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.base.errors import CrowdError
from ..core.authoring.placement import (SOURCE_SEED, AgentSet, CharacterStreams, Palette,
                                        PlacementPolicy, place_agents, z_angle)
from ..core.variety.timing import Timing

__all__ = ["agents_from_source", "agents_from_scene", "describe_source", "placement_policy",
           "character_streams", "PlacedSource"]


@dataclass(frozen=True)
class PlacedSource:
    """Which agents an enabled agent source made: ``index`` (its place in
    ``scene.crowd.agent_sources``), ``name``, ``object_name``, agent ids ``first ..
    first + count - 1`` and ``rows``: ``(count,)`` int64 vertex index of the source
    mesh each agent stands on (None for an 'Instances' source)."""

    index: int
    name: str
    object_name: str
    first: int
    count: int
    rows: np.ndarray | None


# ----------------------------------------------------------------------- geometry
def _mesh_points(obj, depsgraph, what):
    """(evaluated mesh, local positions (V, 3) float64, world matrix (4, 4))."""
    if obj.type != "MESH":
        raise CrowdError(f"{what}: object {obj.name!r} is a {obj.type}, not a mesh "
                         "(use 'Instances' for objects that generate instances)")
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return mesh, co.reshape(-1, 3).astype(np.float64), np.array(ev.matrix_world, np.float64)


def _group_members(obj, mesh, name, what) -> np.ndarray:
    """Indices of vertices with weight > 0 in vertex group ``name`` (ascending)."""
    group = obj.vertex_groups.get(name)
    if group is None:
        raise CrowdError(f"{what}: object {obj.name!r} has no vertex group {name!r} "
                         f"(it has {[g.name for g in obj.vertex_groups]})")
    gi = group.index
    members = [v.index for v in mesh.vertices for g in v.groups
               if g.group == gi and g.weight > 0.0]
    if not members:
        raise CrowdError(f"{what}: vertex group {name!r} of {obj.name!r} has no vertex "
                         "with a weight above 0")
    return np.asarray(members, np.int64)


_ATTR_FIELDS = {"FLOAT": ("value", 1), "INT": ("value", 1), "INT8": ("value", 1),
                "FLOAT_VECTOR": ("vector", 3), "FLOAT_COLOR": ("color", 4),
                "BYTE_COLOR": ("color", 4)}
#: attribute data types accepted per kind of per-point value the placement asks for
_ATTR_KINDS = {"float": ("FLOAT",), "int": ("INT", "INT8"),
               "color": ("FLOAT_COLOR", "BYTE_COLOR", "FLOAT_VECTOR")}


def _attribute(mesh, name, kinds, what, obj) -> np.ndarray:
    """A POINT attribute as ``(V,)`` or ``(V, k)`` array; ``kinds`` are the accepted
    ``data_type`` values."""
    attr = mesh.attributes.get(name)
    if attr is None:
        raise CrowdError(f"{what}: mesh of {obj.name!r} has no attribute {name!r}")
    if attr.domain != "POINT" or attr.data_type not in kinds:
        raise CrowdError(f"{what}: attribute {name!r} of {obj.name!r} is "
                         f"{attr.data_type} on {attr.domain}; expected {'/'.join(kinds)} "
                         "on points")
    field, width = _ATTR_FIELDS[attr.data_type]
    dtype = np.int32 if attr.data_type in ("INT", "INT8") else np.float32
    out = np.empty(len(attr.data) * width, dtype)
    attr.data.foreach_get(field, out)
    return out if width == 1 else out.reshape(-1, width)


def _instances(obj, depsgraph) -> np.ndarray:
    """World matrices ``(n, 4, 4)`` of the instances ``obj`` generates."""
    mats = [np.array(inst.matrix_world) for inst in depsgraph.object_instances
            if inst.is_instance and inst.parent is not None and inst.parent.original == obj]
    return np.array(mats, np.float64).reshape(-1, 4, 4)


# -------------------------------------------------------------------------- agents
def placement_policy(source) -> PlacementPolicy:
    """The placement settings of a ``CROWD_PG_agent_source`` as plain values."""
    target = source.heading_target
    return PlacementPolicy(
        heading_mode=source.heading_mode, heading=source.heading,
        heading_attribute=source.heading_attribute,
        target=None if target is None else tuple(target.matrix_world.translation),
        character_mode=source.character_mode,
        character_attribute=source.character_attribute,
        character_name=source.character_name,
        stream_mode=source.stream_mode, stream_attribute=source.stream_attribute,
        stream_name=source.stream_name, offset_mode=source.offset_mode,
        offset_mean=source.offset_mean, offset_std=source.offset_std,
        offset_attribute=source.offset_attribute, color_mode=source.color_mode,
        color=tuple(source.color), color_variation=source.color_variation,
        color_attribute=source.color_attribute, scale_min=source.scale_min,
        scale_max=source.scale_max)


def character_streams(settings) -> tuple:
    """The scene's characters (``scene.crowd.characters``) as plain
    :class:`~crowd_addon.core.authoring.placement.CharacterStreams`, in list order."""
    return tuple(CharacterStreams(c.name, tuple(a.name for a in c.streams),
                                  tuple(a.weight for a in c.streams), c.weight,
                                  tuple(stream_timing(a) for a in c.streams),
                                  tuple(Palette(p.material, p.colors(), p.mode, p.attribute)
                                        for p in c.palettes),
                                  (c.body_weight, *(v.weight for v in c.variants))
                                  if len(c.variants) else (),
                                  c.variant_mode, c.variant_attribute,
                                  tuple(p.share for p in c.props))
                 for c in settings.characters)


def stream_timing(anim) -> Timing:
    """A stream's timing variation (:class:`~crowd_addon.core.variety.timing.Timing`) from its
    properties."""
    return Timing(anim.speed_min, anim.speed_max, anim.speed_streams, anim.copies)


def describe_source(source, index: int | None = None) -> str:
    """How errors name an agent source: its name, or its place in the list when the
    name is empty, and its object ("agent source 2 (object 'Stands')")."""
    label = repr(source.name) if source.name.strip() else \
        (str(index + 1) if index is not None else "(unnamed)")
    obj = source.object
    return f"agent source {label}" + (f" (object {obj.name!r})" if obj is not None else "")


def _points(source, depsgraph, what):
    """``(positions (n, 3), base headings (n,), rows, attribute)`` of a source:
    ``rows`` the vertex indices (None for instances), ``attribute(name, kind)`` the
    per-point values of a point attribute."""
    obj = source.object
    if obj is None:
        raise CrowdError(f"{what}: no object chosen")
    if source.mode == "INSTANCES":
        mats = _instances(obj, depsgraph)
        if mats.shape[0] == 0:
            raise CrowdError(f"{what}: object {obj.name!r} generates no instances")

        def no_attribute(_name, _kind):
            raise CrowdError(f"{what}: attributes are read from mesh vertices; with "
                             "'Instances' use fixed, random or target settings")
        return mats[:, :3, 3], z_angle(mats), None, no_attribute
    mesh, local, world = _mesh_points(obj, depsgraph, what)
    rows = _group_members(obj, mesh, source.vertex_group, what) \
        if source.mode == "VERTEX_GROUP" else np.arange(local.shape[0], dtype=np.int64)
    if rows.size == 0:
        raise CrowdError(f"{what}: mesh {obj.name!r} has no vertices")
    pos = local[rows] @ world[:3, :3].T + world[:3, 3]

    def attribute(name, kind):
        return _attribute(mesh, name, _ATTR_KINDS[kind], what, obj)[rows]
    return pos, np.full(rows.size, z_angle(world)), rows, attribute


def _place(source, depsgraph, characters, max_offset, seed, forward_axis, index):
    what = describe_source(source, index)
    pos, base_heading, rows, attribute = _points(source, depsgraph, what)
    agents = place_agents(what, pos, base_heading, placement_policy(source),
                          characters=characters, max_offset=max_offset, seed=seed,
                          forward_axis=forward_axis, attribute=attribute)
    return agents, rows


def agents_from_source(source, depsgraph, *, characters, max_offset, seed,
                       forward_axis="NEG_Y", index: int | None = None) -> AgentSet:
    """The agents of one source.

    Parameters
    ----------
    source : a ``CROWD_PG_agent_source``.
    depsgraph : the evaluated depsgraph to read geometry from.
    characters : the scene's characters as
        :class:`~crowd_addon.core.authoring.placement.CharacterStreams` (:func:`character_streams`).
    max_offset : M. seed : int. forward_axis : key of
        :data:`crowd_addon.core.authoring.placement.FORWARD`.
    index : the source's place in the scene's list, named in errors when it has no name.
    """
    return _place(source, depsgraph, characters, max_offset, seed, forward_axis, index)[0]


def agents_from_scene(scene, depsgraph) -> tuple:
    """All enabled sources of ``scene.crowd`` concatenated in list order: ``(AgentSet,
    placed)``, ``placed`` a tuple of :class:`PlacedSource`, one per enabled source.
    Source ``i`` draws its random numbers from seed ``scene.crowd.seed + i *
    SOURCE_SEED``; agents' streams index the scene's streams, character after
    character (the crowd's stream list)."""
    s = scene.crowd
    characters = character_streams(s)
    sets, placed, first = [], [], 0
    for i, src in enumerate(s.agent_sources):
        if not src.enabled:
            continue
        agents, rows = _place(src, depsgraph, characters, s.max_offset,
                              s.seed + i * SOURCE_SEED, s.forward_axis, i)
        placed.append(PlacedSource(i, src.name, src.object.name, first, agents.count, rows))
        sets.append(agents)
        first += agents.count
    return AgentSet.concatenate(sets), tuple(placed)
