"""Agents from scene geometry: one agent per vertex, vertex-group member or instance.

Each agent source (``scene.crowd.agent_sources``, :class:`.props.CROWD_PG_agent_source`)
gives world positions (metres), headings (radians about +Z: the rotation applied to
the character's rest pose), a stream per agent, an offset in ``0 .. M-1`` frames and
a colour. Geometry is read from the depsgraph-evaluated object (modifiers and
geometry nodes applied) with ``foreach_get`` into numpy; only the vertex-group
filter walks the vertices, because Blender exposes no array access to group
weights. Random choices are seeded from ``scene.crowd.seed`` and the source's
index, so the same scene gives the same agents.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.agents import assign_offsets, assign_streams, check_offsets
from ..core.errors import CrowdError

__all__ = ["AgentSet", "agents_from_source", "agents_from_scene", "FORWARD", "SOURCE_SEED"]

#: the character's rest-pose facing per ``forward_axis`` setting (x, y)
FORWARD = {"NEG_Y": (0.0, -1.0), "POS_Y": (0.0, 1.0), "POS_X": (1.0, 0.0),
           "NEG_X": (-1.0, 0.0)}
#: seed stride between agent sources
SOURCE_SEED = 7919


@dataclass(frozen=True)
class AgentSet:
    """Agents as arrays: positions (n, 3) float32 metres, headings (n,) float32
    radians, streams (n,) int32 stream indices, offsets (n,) int32 frames, colors
    (n, 3) float32 0..1."""

    positions: np.ndarray
    headings: np.ndarray
    streams: np.ndarray
    offsets: np.ndarray
    colors: np.ndarray

    @property
    def count(self) -> int:
        return int(self.offsets.shape[0])

    @staticmethod
    def concatenate(sets):
        if not sets:
            return AgentSet(np.zeros((0, 3), np.float32), np.zeros(0, np.float32),
                            np.zeros(0, np.int32), np.zeros(0, np.int32),
                            np.zeros((0, 3), np.float32))
        return AgentSet(*(np.concatenate([getattr(s, f) for s in sets])
                          for f in ("positions", "headings", "streams", "offsets", "colors")))


# ----------------------------------------------------------------------- geometry
def _z_angle(matrix) -> np.ndarray:
    """Rotation about +Z (radians) of 4x4 world matrices ``(..., 4, 4)``."""
    return np.arctan2(matrix[..., 1, 0], matrix[..., 0, 0])


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
def agents_from_source(source, depsgraph, *, streams, stream_weights, max_offset, seed,
                       forward_axis="NEG_Y") -> AgentSet:
    """The agents of one source.

    Parameters
    ----------
    source : a ``CROWD_PG_agent_source``.
    depsgraph : the evaluated depsgraph to read geometry from.
    streams : stream names (index = stream id); stream_weights : (S,) weights.
    max_offset : M. seed : int. forward_axis : key of :data:`FORWARD`.
    """
    what = f"agent source {source.name!r}"
    obj = source.object
    if obj is None:
        raise CrowdError(f"{what}: no object chosen")
    mesh = None
    if source.mode == "INSTANCES":
        mats = _instances(obj, depsgraph)
        if mats.shape[0] == 0:
            raise CrowdError(f"{what}: object {obj.name!r} generates no instances")
        pos = mats[:, :3, 3]
        base_heading = _z_angle(mats)
        rows = None
    else:
        mesh, local, world = _mesh_points(obj, depsgraph, what)
        rows = _group_members(obj, mesh, source.vertex_group, what) \
            if source.mode == "VERTEX_GROUP" else np.arange(local.shape[0])
        if rows.size == 0:
            raise CrowdError(f"{what}: mesh {obj.name!r} has no vertices")
        pos = local[rows] @ world[:3, :3].T + world[:3, 3]
        base_heading = np.full(rows.size, _z_angle(world))
    n = pos.shape[0]

    def attribute(name, kinds):
        if mesh is None:
            raise CrowdError(f"{what}: attributes are read from mesh vertices; with "
                             "'Instances' use fixed, random or target settings")
        return _attribute(mesh, name, kinds, what, obj)[rows]

    if source.heading_mode == "TARGET":
        if source.heading_target is None:
            raise CrowdError(f"{what}: heading faces a target but none is chosen")
        tgt = np.array(source.heading_target.matrix_world.translation, np.float64)
        d = tgt[None, :2] - pos[:, :2]
        fx, fy = FORWARD[forward_axis]
        heading = np.arctan2(d[:, 1], d[:, 0]) - np.arctan2(fy, fx)
    elif source.heading_mode == "ATTRIBUTE":
        heading = base_heading + attribute(source.heading_attribute, ("FLOAT",))
    else:
        heading = base_heading + source.heading
    heading = np.mod(heading + np.pi, 2 * np.pi) - np.pi

    if source.stream_mode == "ATTRIBUTE":
        st = attribute(source.stream_attribute, ("INT", "INT8")).astype(np.int64)
        bad = np.flatnonzero((st < 0) | (st >= len(streams)))
        if bad.size:
            raise CrowdError(f"{what}: attribute {source.stream_attribute!r} gives stream "
                             f"{int(st[bad[0]])} at point {int(bad[0])}; streams are "
                             f"0..{len(streams) - 1} ({list(streams)})")
    elif source.stream_mode == "FIXED":
        if source.stream_name not in streams:
            raise CrowdError(f"{what}: unknown stream {source.stream_name!r} "
                             f"(streams: {list(streams)})")
        st = np.full(n, list(streams).index(source.stream_name))
    else:
        try:
            st = assign_streams(n, len(streams), stream_weights, seed)
        except CrowdError as e:
            raise CrowdError(f"{what}: {e}") from None

    if source.offset_mode == "ATTRIBUTE":
        off = attribute(source.offset_attribute, ("INT", "INT8"))
        try:
            check_offsets(off, max_offset, f"{what}: point")
        except CrowdError as e:
            raise CrowdError(f"{e} (attribute {source.offset_attribute!r})") from None
    else:
        mean = None if source.offset_mean < 0 else source.offset_mean
        std = None if source.offset_std < 0 else source.offset_std
        off = assign_offsets(n, max_offset, source.offset_mode.lower(), seed + 1, mean, std)

    if source.color_mode == "ATTRIBUTE":
        col = attribute(source.color_attribute,
                        ("FLOAT_COLOR", "BYTE_COLOR", "FLOAT_VECTOR"))[:, :3]
    else:
        rnd = np.random.default_rng(seed + 2).uniform(0.0, 1.0, (n, 3))
        base = np.asarray(source.color, np.float64)
        col = base + source.color_variation * (rnd - base)
    col = np.clip(col, 0.0, 1.0)
    return AgentSet(pos.astype(np.float32), heading.astype(np.float32),
                    np.asarray(st, np.int32), np.asarray(off, np.int32),
                    np.asarray(col, np.float32))


def agents_from_scene(scene, depsgraph, streams, stream_weights) -> AgentSet:
    """All enabled sources of ``scene.crowd`` concatenated in list order; source ``i``
    draws its random numbers from seed ``scene.crowd.seed + i * SOURCE_SEED``."""
    s = scene.crowd
    sets = [agents_from_source(src, depsgraph, streams=streams, stream_weights=stream_weights,
                               max_offset=s.max_offset, seed=s.seed + i * SOURCE_SEED,
                               forward_axis=s.forward_axis)
            for i, src in enumerate(s.agent_sources) if src.enabled]
    return AgentSet.concatenate(sets)
