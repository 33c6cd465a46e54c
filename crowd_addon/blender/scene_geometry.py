"""A Blender scene's own geometry and sun for the crowd renderers.

:func:`scene_geometry` gathers what a render of the scene shows around the crowd --
every evaluated mesh, curve or text object (instances included) that renders -- as
one :class:`~crowd_addon.gpu.scene_geometry.SceneGeometry` of world-space triangles,
coloured by their materials (a material's viewport display colour, as Workbench
shows it, unless left at its default grey, then its Principled BSDF's base colour;
the object's colour where a slot has no material). The crowd's own objects are left
out, since the crowd draws those itself: characters' armatures, bodies and LOD
meshes, agent sources and what they instance, and Render Crowd's instances; so are the
show's animated look targets (:func:`moving_look_targets`: geometry taken at one frame
would show a moving ball frozen).
:func:`scene_light` is the first rendering sun lamp's direction as the renderers'
``light``.
"""

from __future__ import annotations

import numpy as np

from ..core.base.errors import CrowdError
from ..gpu.scene_geometry import DEFAULT_AMBIENT, SceneGeometry, sun_light

__all__ = ["scene_geometry", "scene_light", "crowd_objects", "moving_look_targets",
           "MAX_SCENE_TRIANGLES"]

#: More scene triangles than this are refused (the preview draws them every frame).
MAX_SCENE_TRIANGLES = 20_000_000
_KINDS = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
_GREY = (0.8, 0.8, 0.8)


def crowd_objects(scene) -> set:
    """Names of the objects the scene's crowd settings use as templates: characters'
    armatures, bodies and LOD meshes, and agent sources; and Render Crowd's points
    object (its instances are the crowd itself)."""
    from .render_points import points_object
    points = points_object()
    names = set() if points is None else {points.name}
    settings = getattr(scene, "crowd", None)
    if settings is None:
        return names
    for ch in settings.characters:
        names.update(o.name for o in (ch.armature, ch.body) if o is not None)
        names.update(lod.object.name for lod in ch.lods if lod.object is not None)
    names.update(s.object.name for s in settings.agent_sources if s.object is not None)
    return names


def moving_look_targets(scene) -> set:
    """Names of the show's look targets that something animates (an animated ball):
    left out of the scene geometry, which is taken at one frame and would show them
    frozen there (Blender's own viewport and renders draw them moving)."""
    from .show_data import _animated
    settings = getattr(scene, "crowd", None)
    if settings is None:
        return set()
    return {t.object.name for t in settings.show.look_targets
            if t.object is not None and _animated(t.object)}


def _material_color(mat) -> tuple:
    """Linear RGB of ``mat``: its viewport display colour (what Workbench shows) when
    set, else the base colour of its Principled BSDF (what EEVEE and Cycles show),
    else the display colour's default grey."""
    display = tuple(mat.diffuse_color)[:3]
    if not np.allclose(display, _GREY, atol=1e-4):
        return display
    tree = getattr(mat, "node_tree", None)
    for node in tree.nodes if tree is not None else ():
        if node.type == "BSDF_PRINCIPLED":
            return tuple(node.inputs["Base Color"].default_value)[:3]
    return display


def _object_colors(obj) -> np.ndarray:
    """``(slots or 1, 3)`` colours of the object's material slots (the object's own
    colour when it has none)."""
    mats = [slot.material for slot in obj.material_slots] or [None]
    colors = [_material_color(m) if m is not None else tuple(obj.color)[:3] for m in mats]
    return np.asarray(colors, np.float32).reshape(-1, 3)


def _triangles(obj, matrix):
    """World-space corners, corner normals and corner colours of evaluated ``obj``."""
    mesh = obj.to_mesh()
    try:
        mesh.calc_loop_triangles()
        t = len(mesh.loop_triangles)
        if t == 0:
            return None
        loops = np.empty(3 * t, np.int32)
        mesh.loop_triangles.foreach_get("loops", loops)
        mat_index = np.empty(t, np.int32)
        mesh.loop_triangles.foreach_get("material_index", mat_index)
        verts = np.empty(len(mesh.loops), np.int32)
        mesh.loops.foreach_get("vertex_index", verts)
        co = np.empty(3 * len(mesh.vertices), np.float32)
        mesh.vertices.foreach_get("co", co)
        normals = np.empty(3 * len(mesh.loops), np.float32)
        mesh.corner_normals.foreach_get("vector", normals)       # Blender 4.1+
        colors = _object_colors(obj)
    finally:
        obj.to_mesh_clear()
    m = np.asarray(matrix, np.float64)
    p = co.reshape(-1, 3)[verts[loops]].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    normal_matrix = np.linalg.inv(m[:3, :3]).T if abs(np.linalg.det(m[:3, :3])) > 1e-12 \
        else m[:3, :3]
    n = normals.reshape(-1, 3)[loops].astype(np.float64) @ normal_matrix.T
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    c = colors[np.clip(mat_index, 0, len(colors) - 1)].repeat(3, axis=0)
    return p.astype(np.float32), n.astype(np.float32), c


def scene_geometry(scene, depsgraph=None, exclude=()) -> SceneGeometry:
    """The triangles of ``scene`` around its crowd (see the module docstring), from
    ``depsgraph`` (default: the context's evaluated one) at the current frame.
    ``exclude``: more object names to leave out. A scene of more than
    :data:`MAX_SCENE_TRIANGLES` triangles is a CrowdError naming the count."""
    import bpy
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    skip = crowd_objects(scene) | moving_look_targets(scene) | set(exclude)
    parts, names, total = [], [], 0
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type not in _KINDS or obj.original.hide_render or obj.original.name in skip:
            continue
        if inst.is_instance and inst.parent is not None and inst.parent.original.name in skip:
            continue
        tri = _triangles(obj, inst.matrix_world)
        if tri is None:
            continue
        total += tri[0].shape[0] // 3
        if total > MAX_SCENE_TRIANGLES:
            raise CrowdError(f"scene {scene.name!r}: more than {MAX_SCENE_TRIANGLES:,} "
                             "triangles around the crowd; hide some objects from renders")
        parts.append(tri)
        names.append(obj.original.name)
    if not parts:
        empty = np.zeros((0, 3), np.float32)
        return SceneGeometry(empty, empty, empty)
    p, n, c = (np.concatenate(a) for a in zip(*parts))
    return SceneGeometry(p, n, c, tuple(dict.fromkeys(names)))


def scene_light(scene, ambient: float = DEFAULT_AMBIENT):
    """The renderers' ``light`` for the scene's first rendering sun lamp (by name),
    or None when it has none."""
    suns = sorted((o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"
                   and not o.hide_render), key=lambda o: o.name)
    if not suns:
        return None
    m = np.asarray(suns[0].matrix_world, np.float64)
    return sun_light(-m[:3, 2], ambient)
