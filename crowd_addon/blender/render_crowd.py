"""The crowd in Blender's own renders: the *Render Crowd* switch.

F12 (Workbench, EEVEE, Cycles), viewport renders and playblasts know nothing of the
preview's GPU drawing, so with ``scene.crowd.render_crowd`` on the crowd is also made
of ordinary Blender data, with the paper's sharing kept:

* one **pose mesh** per pose in use: a (part, level of detail, pose texture row, aim
  class) key (the aim class: a looking agent's head turn rounded to
  :data:`.render_pieces.AIM_STEP`, 0 for none: :func:`.render_pieces.aim_classes`), a
  part being a mesh variant of a character or one of its props
  (:mod:`crowd_addon.core.meshes.bodies`). Agents of a stream at the same offset read the
  same row, so they share one mesh; an agent in a transition or playing a unique has
  a row of its own. A prop is a piece of its own, not merged into the body as the GPU
  draws it: a flag's pose mesh is shared by every agent whose hand is in that pose,
  whatever else it wears, and no combination of props multiplies the body's pose
  meshes. Each pose mesh is the level's proxy (its triangles, UVs and materials,
  as the crowd's copies that tint each agent as the preview does:
  :mod:`.crowd_materials`) skinned on the CPU by core
  (:func:`crowd_addon.core.base.skinning.skin_vertices`) and written with one bulk
  ``foreach_set``. The meshes hang on objects
  ``CrowdPose.000000 ...`` of the collection :data:`POSES`, which is not linked to the
  scene (only instanced);
* one **points object** (:data:`POINTS`): a vertex per piece, each agent's body first
  (vertex ``i`` is agent ``i``), then one per prop an agent carries, at the agent's
  position, with point attributes ``crowd_pose`` (the index of its pose object),
  ``crowd_drawn`` (false for agents of a character without a body: not instanced),
  ``crowd_agent`` (the agent), ``crowd_prop`` (the prop's index in its character, -1
  for the body), ``crowd_heading`` (radians about +Z), ``crowd_scale`` (its body
  scale), ``crowd_color`` (its tint) and ``crowd_palette0`` .. ``3`` (its palette
  colours, alpha 0 where it has none; docs/variety.md), which the crowd's material
  copies read through Attribute nodes of type *Instancer* (a material of your own can
  too), and a Geometry Nodes modifier that puts the
  picked pose object on every point (*Instance on Points* with *Pick Instance*
  from a *Collection Info* of :data:`POSES`, whose children come in name order).

:func:`sync` brings all of it to the crowd's current frame; the preview calls it
after every step while the switch is on. The level of detail follows the scene
camera at the render resolution with the crowd's own LOD distances, as the GPU
preview would draw through that camera. Cost per frame: skinning the pose meshes
whose pose changed (not the agents) and a ``foreach_set`` each, plus the point
attributes. A pose mesh keeps its pose (its key) from frame to frame, and the pose
storage's row versions say which rows were written since it was skinned: in a step
that is one history slice of each stream (the agents of the other offsets moved on
to pose meshes already made), the uniques and the transitions; the rest are left as
they are (``RenderStats.skinned``).

All of it is the extension's own, and only its own is reused, changed or removed
(:mod:`.render_points`).
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass

import numpy as np

import bpy

from ..core.base.errors import CrowdError
from ..core.base.skinning import skin_vertices
from .crowd_materials import crowd_material, refresh_all, remove_all as crowd_materials
from .owned import made
from .render_pieces import AIM_BITS, ShownPoses, agent_pieces, aim_codes, aimed_rows
from .render_points import (NODE_GROUP, POINTS, POSES, RENDER, points_for, points_object,
                            poses_collection)

__all__ = ["POINTS", "POSES", "NODE_GROUP", "RENDER", "RenderStats", "points_object", "sync",
           "forget", "remove"]

_POSE_PREFIX = "CrowdPose."
_MESH_PREFIX = "CrowdPoseMesh."


@dataclass
class RenderStats:
    """What the last :func:`sync` made: ``agents``, ``poses`` (pose meshes in use),
    ``skinned`` (those skinned again: new to the frame or their pose changed),
    ``vertices`` (skinned vertices written) and ``ms`` (wall time)."""

    agents: int = 0
    poses: int = 0
    skinned: int = 0
    vertices: int = 0
    ms: float = 0.0


def _mesh_for(proxy, name: str, palette=()):
    """A new Blender mesh of ``proxy`` (a core ``ProxyMesh``) in its bind pose: its
    triangles, its UVs and the crowd copies (:mod:`.crowd_materials`) of the materials
    its looks name (when they exist); ``palette``: the character's palette materials,
    whose place is a material's palette column."""
    mesh = bpy.data.meshes.new(name)
    v, t = proxy.vertex_count, proxy.triangles.shape[0]
    mesh.vertices.add(v)
    mesh.vertices.foreach_set("co", np.ascontiguousarray(proxy.positions, np.float32).ravel())
    mesh.loops.add(3 * t)
    mesh.loops.foreach_set("vertex_index", proxy.triangles.astype(np.int32).ravel())
    mesh.polygons.add(t)
    mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * t, 3, dtype=np.int32))
    mesh.polygons.foreach_set("loop_total", np.full(t, 3, np.int32))
    palette = tuple(palette)
    for look in proxy.looks:
        mesh.materials.append(crowd_material(
            look.name, palette.index(look.name) if look.name in palette else None))
    if proxy.material is not None and proxy.looks:
        mesh.polygons.foreach_set("material_index", proxy.material.astype(np.int32))
    if proxy.uvs is not None:
        layer = mesh.uv_layers.new(name="UVMap")
        layer.data.foreach_set("uv", np.ascontiguousarray(proxy.uvs, np.float32).ravel())
    mesh.update()
    mesh.validate()
    return mesh


#: custom property of a pose mesh: :func:`_made_from` of what it was made from
_MADE_FROM = "crowd_made_from"


def _made_from(proxy, palette) -> str:
    """A digest of what a pose mesh takes from ``proxy`` besides its skinned vertex
    positions: its topology, UVs, looks and the palette columns of their materials
    (a re-bake that changes any of them makes the meshes again)."""
    h = hashlib.sha1()
    for a in (proxy.positions, proxy.triangles, proxy.uvs, proxy.material):
        h.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
    h.update(repr((proxy.looks, tuple(palette))).encode())
    return h.hexdigest()


class _Existing:
    """The pose meshes, pose objects and collection members there are now, by name,
    read in one pass each (a lookup by name in ``bpy.data`` walks the list: thousands
    of them a frame cost more than the skinning)."""

    def __init__(self, coll):
        self.coll = coll
        # by name only: whether one is Render Crowd's is asked of those a sync touches
        # (:meth:`mesh`, :meth:`show`), not of all of them every frame
        self.meshes = {m.name: m for m in bpy.data.meshes if m.name.startswith(_MESH_PREFIX)}
        self.objects = {o.name: o for o in bpy.data.objects if o.name.startswith(_POSE_PREFIX)}
        self.linked = set(coll.objects.keys())
        #: meshes replaced this sync, removed in one batch once every pose object in
        #: use shows its new mesh (removing a mesh removes the objects still using it)
        self.stale = []

    def mesh(self, j: int, proxy, made: str, palette):
        """Pose object ``j``'s mesh: the one it has when it was made from ``made``
        (:func:`_made_from`), else a new one of ``proxy`` (``palette``: :func:`_mesh_for`'s)."""
        name = f"{_MESH_PREFIX}{j:06d}"
        mesh = self.meshes.get(name)
        if mesh is not None and not _is_pose_mesh(mesh):
            _not_ours(name)
        if mesh is not None and mesh.get(_MADE_FROM) == made:
            return mesh
        if mesh is not None:
            mesh.name = f"{name}~"                     # frees the name for its successor
            self.stale.append(mesh)
        mesh = self.meshes[name] = _mesh_for(proxy, name, palette)
        mesh[_MADE_FROM] = made
        return mesh

    def indices(self) -> np.ndarray:
        """The ``j`` of every pose object in the pose collection whose pose mesh
        (``CrowdPoseMesh.j``, which :meth:`show` gives it) is there."""
        cut = len(_POSE_PREFIX)
        return np.array([int(name[cut:]) for name in self.linked
                         if f"{_MESH_PREFIX}{name[cut:]}" in self.meshes], np.int64)

    def show(self, j: int, mesh) -> None:
        """Pose object ``j`` shows ``mesh`` and is in the pose collection."""
        name = f"{_POSE_PREFIX}{j:06d}"
        obj = self.objects.get(name)
        if obj is not None and not _is_pose(obj):
            _not_ours(name)
        if obj is None:
            obj = self.objects[name] = bpy.data.objects.new(name, mesh)
        elif obj.data != mesh:
            obj.data = mesh
        if name not in self.linked:
            self.coll.objects.link(obj)
            self.linked.add(name)


def _not_ours(name: str):
    raise CrowdError(f"{name!r} is not Render Crowd's; rename it to use Render Crowd")


def _is_pose_mesh(mesh) -> bool:
    return mesh.name.startswith(_MESH_PREFIX) and mesh.get(_MADE_FROM) is not None


def _is_pose(obj) -> bool:
    return obj.name.startswith(_POSE_PREFIX) and obj.type == "MESH" \
        and obj.data.get(_MADE_FROM) is not None


#: Render Crowd's record of what its pose objects show (one set of them in a file)
_SHOWN = ShownPoses()


def sync(scene, crowd) -> RenderStats:
    """Make the render data (see the module docstring) show ``crowd`` at its current
    frame; returns :class:`RenderStats`."""
    global _SHOWN
    t0 = time.perf_counter()
    agent, part, prop, lod, levels, palettes = agent_pieces(crowd, scene)
    n = agent.size
    storage = crowd.storage
    rows = np.asarray(crowd.view.agent_rows_index(), np.int64)[agent]
    drawn = np.array([bool(lv) for lv in levels], bool)[part] if n else np.zeros(0, bool)
    # a looking agent's pose meshes are its pose's turned to its aim class
    code, turn = aim_codes(crowd)
    key = (((rows * len(levels) + part) * 16 + lod) << AIM_BITS) + code[agent]
    keys, first, pose_of_piece = np.unique(np.where(drawn, key, -1), return_index=True,
                                           return_inverse=True)
    real = keys >= 0
    offset = int((~real).sum())                 # the -1 key sorts first
    keys, first = keys[real], first[real]
    if _SHOWN.storage is not storage:           # another crowd: nothing shown is kept
        _SHOWN = ShownPoses(storage)
    j, kept = _SHOWN.place(keys)
    row = rows[first]
    version = storage.version[row]
    was = np.zeros(keys.size, np.int64)
    was[kept] = _SHOWN.version[j[kept]]
    redo = ~kept | (was != version) | (row >= storage.slot_base)
    stats = RenderStats(agents=int(drawn[prop < 0].sum()), poses=int(keys.size))
    refresh_all()                               # material edits reach the next frame
    coll = poses_collection()
    existing = _Existing(coll)
    topo = (keys >> AIM_BITS) % (16 * len(levels))
    there = existing.indices()
    for t in np.unique(topo):
        k, level = divmod(int(t), 16)
        proxy = levels[k][level]
        made = _made_from(proxy, palettes[k])
        sel = np.flatnonzero(topo == t)
        # a pose object or mesh gone, or made from another level or an older bake
        lost = ~np.isin(j[sel], there) | (_SHOWN.made.get(int(t)) != made)
        redo[sel[lost]] = True
        skin = sel[redo[sel]]
        if not skin.size:
            continue
        meshes = []
        for i in skin.tolist():
            mesh = existing.mesh(int(j[i]), proxy, made, palettes[k])
            existing.show(int(j[i]), mesh)
            meshes.append(mesh)
        pieces = first[skin]
        one = np.zeros(skin.size, np.int64)
        turned = code[agent[pieces]] > 0
        one[turned] = 1 + np.arange(int(turned.sum()))
        verts = skin_vertices(proxy.positions, proxy.bone_indices, proxy.bone_weights,
                              aimed_rows(crowd, agent[pieces], one,
                                         np.r_[np.zeros((1, 2)), turn[agent[pieces[turned]]]]))
        for mesh, co in zip(meshes, verts.astype(np.float32)):
            mesh.vertices.foreach_set("co", co.ravel())
            mesh.update()
        _SHOWN.made[int(t)] = made
        stats.skinned += int(skin.size)
        stats.vertices += verts.shape[0] * verts.shape[1]
    count = int(j.max()) + 1 if j.size else 0
    shown_key = np.full(count, -1, np.int64)
    shown_key[j] = keys
    shown_version = np.zeros(count, np.int64)
    shown_version[j] = version
    _SHOWN.key, _SHOWN.version = shown_key, shown_version
    last = f"{_POSE_PREFIX}{count:06d}"
    for name in [n for n in existing.linked if n >= last]:      # poses no longer in use
        coll.objects.unlink(existing.objects[name] if name in existing.objects
                            else coll.objects[name])
    pose_index = np.zeros(n, np.int32)
    piece_real = pose_of_piece.reshape(-1) - offset
    pose_index[drawn] = j[piece_real[drawn]]
    points = points_for(scene, n)
    me = points.data
    a = crowd.agents
    me.vertices.foreach_set("co", np.ascontiguousarray(a.position[agent], np.float32).ravel())
    me.attributes["crowd_pose"].data.foreach_set("value", pose_index)
    me.attributes["crowd_drawn"].data.foreach_set("value", drawn)
    me.attributes["crowd_agent"].data.foreach_set("value", agent.astype(np.int32))
    me.attributes["crowd_prop"].data.foreach_set("value", prop.astype(np.int32))
    me.attributes["crowd_heading"].data.foreach_set(
        "value", np.ascontiguousarray(a.heading[agent], np.float32))
    me.attributes["crowd_scale"].data.foreach_set(
        "value", np.ascontiguousarray(a.scale[agent], np.float32))
    color = np.ones((n, 4), np.float32)
    color[:, :3] = a.color[agent]
    me.attributes["crowd_color"].data.foreach_set("color", color.ravel())
    palette = a.palette[agent]                               # (n, 4, 3), -1: none
    for c in range(4):
        rgba = np.zeros((n, 4), np.float32)
        has = (palette[:, c] >= 0).all(1)
        rgba[has, :3], rgba[has, 3] = palette[has, c], 1.0
        me.attributes[f"crowd_palette{c}"].data.foreach_set("color", rgba.ravel())
    me.update()
    if existing.stale:                  # after the unused objects were unlinked above
        bpy.data.batch_remove(existing.stale)
    stats.ms = (time.perf_counter() - t0) * 1e3
    return stats


def forget() -> None:
    """Let the next :func:`sync` skin every pose mesh again (after an undo, which may
    have brought the meshes back as they were at another frame)."""
    global _SHOWN
    _SHOWN = ShownPoses()


def remove(scene) -> None:
    """Take the render data away: the points object, the pose objects and meshes, the
    crowd's material copies, the collection and the node group (one batch: removing
    thousands of IDs one by one walks Blender's lists each time): Render Crowd's own,
    nothing else (see the module docstring)."""
    forget()
    points = points_object()
    ids = [] if points is None else [points, points.data]
    ids += [o for o in bpy.data.objects if _is_pose(o)]
    ids += [m for m in bpy.data.meshes if _is_pose_mesh(m)]
    ids += crowd_materials()
    ids += [b for data in (bpy.data.collections, bpy.data.node_groups) for b in data
            if made(b, RENDER)]
    if ids:
        bpy.data.batch_remove(ids)
