"""Small procedural Blender scenes for the extension's tests (bpy, in process).

Loaded by the test modules from their own folder (``sys.path``), since the tests
run with ``--import-mode=importlib``. Everything is built from scratch in an empty
factory scene, so no test depends on a file on disk.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import bpy

from crowd_addon.blender.operators import CROWD_OT_bake, BakeJob

BONES = (  # name, parent, head, tail
    ("root", None, (0, 0, 0), (0, 0, 0.9)),
    ("spine", "root", (0, 0, 0.9), (0, 0, 1.4)),
    ("head", "spine", (0, 0, 1.4), (0, 0, 1.7)),
    ("arm.L", "spine", (0.1, 0, 1.35), (0.6, 0, 1.35)),
    ("arm.R", "spine", (-0.1, 0, 1.35), (-0.6, 0, 1.35)),
)


def reset():
    """An empty factory scene at 24 fps, frame range 1..48."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = 24, 1.0
    scene.frame_start, scene.frame_end = 1, 48
    scene.frame_set(1)
    return scene


#: a second, smaller character: a seven-bone rig of other proportions (no "Arms")
KID_BONES = (
    ("root", None, (0, 0, 0), (0, 0, 0.6)),
    ("spine", "root", (0, 0, 0.6), (0, 0, 0.9)),
    ("neck", "spine", (0, 0, 0.9), (0, 0, 1.0)),
    ("head", "neck", (0, 0, 1.0), (0, 0, 1.2)),
    ("arm.L", "spine", (0.08, 0, 0.85), (0.4, 0, 0.8)),
    ("hand.L", "arm.L", (0.4, 0, 0.8), (0.5, 0, 0.78)),
    ("arm.R", "spine", (-0.08, 0, 0.85), (-0.4, 0, 0.8)),
)


def make_armature(name="Rig", bones=BONES):
    """An armature of ``bones`` (default: five) with a bone collection "Arms" of its
    bones named arm.L, arm.R."""
    data = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    for bname, parent, head, tail in bones:
        eb = data.edit_bones.new(bname)
        eb.head, eb.tail = head, tail
        if parent:
            eb.parent = data.edit_bones[parent]
    bpy.ops.object.mode_set(mode="OBJECT")
    arms = data.collections.new("Arms")
    for bname in ("arm.L", "arm.R"):
        arms.assign(data.bones[bname])
    for pb in obj.pose.bones:
        pb.rotation_mode = "QUATERNION"
    return obj


def make_action(rig, name, seed=0, frames=(1, 13, 25), amplitude=0.5, markers=(),
                bones=None, loop=True):
    """An action keying every bone's rotation (or only ``bones``) at ``frames`` with
    seeded random rotations, the last key equal to the first, a manual frame range
    over ``frames`` marked cyclic when ``loop``; pose markers ``(name, frame)``. The
    rig is left with no action assigned."""
    rng = np.random.default_rng(seed)
    act = bpy.data.actions.new(name)
    rig.animation_data_create()
    rig.animation_data.action = act
    names = [pb.name for pb in rig.pose.bones] if bones is None else list(bones)
    first = {}
    for i, f in enumerate(frames):
        for bname in names:
            pb = rig.pose.bones[bname]
            if i == len(frames) - 1 and len(frames) > 2:
                q = first[bname]
            else:
                axis = rng.normal(size=3)
                axis /= np.linalg.norm(axis)
                ang = rng.uniform(-amplitude, amplitude)
                q = (math.cos(ang / 2), *(math.sin(ang / 2) * axis))
                first.setdefault(bname, q)
            pb.rotation_quaternion = q
            pb.keyframe_insert("rotation_quaternion", frame=f)
    act.use_frame_range = True
    act.frame_start, act.frame_end = frames[0], frames[-1]
    act.use_cyclic = loop
    for mname, mframe in markers:
        m = act.pose_markers.new(mname)
        m.frame = mframe
    rig.animation_data.action = None
    for pb in rig.pose.bones:
        pb.rotation_quaternion = (1, 0, 0, 0)
    return act


def make_proxy(rig, name="Body", width=0.06):
    """A box per bone (``width`` metres half-wide), each box's vertices weighted fully
    to its bone, deformed by an Armature modifier."""
    verts, faces, groups = [], [], []
    cube = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (0, 1)], float)
    quads = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3))
    bones = [(b.name, b.head_local, b.tail_local) for b in rig.data.bones]
    for bname, head, tail in bones:
        h, t = np.array(head, float), np.array(tail, float)
        base = len(verts)
        for c in cube:
            p = h + (t - h) * c[2]
            verts.append(tuple(p + width * np.array([c[0], c[1], 0.0])))
        faces += [tuple(base + i for i in q) for q in quads]
        groups.append((bname, list(range(base, base + 8))))
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    for bname, idx in groups:
        obj.vertex_groups.new(name=bname).add(idx, 1.0, "REPLACE")
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = rig
    obj.parent = rig
    return obj


def make_seats(nx=10, ny=8, name="Seats", spacing=1.0):
    """A grid of ``nx * ny`` vertices (no faces) at z = 0, ``spacing`` metres apart."""
    xs, ys = np.meshgrid(np.arange(nx) * spacing, np.arange(ny) * spacing, indexing="xy")
    co = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    me = bpy.data.meshes.new(name)
    me.vertices.add(co.shape[0])
    me.vertices.foreach_set("co", co.astype(np.float32).ravel())
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def walking_crowd(markers=()):
    """A fresh scene with the crowd most preview tests draw: a rig with a box body, one
    stream "walk" (M = 8, seed 3) and six by five agents 1.5 m apart turned by 0.4
    rad, LOD 0 up to 500 m (small images: the level the CPU checks skin). Returns
    (scene, rig, body, walk action)."""
    scene = reset()
    rig = make_armature()
    walk = make_action(rig, "walk", seed=1, markers=list(markers), amplitude=1.0)
    s = scene.crowd
    s.max_offset, s.seed = 8, 3
    body = make_proxy(rig)
    add_stream(add_character(s, rig, body), "walk", walk)
    src = s.agent_sources.add()
    src.name, src.object = "seats", make_seats(6, 5, spacing=1.5)
    src.heading_mode, src.heading = "FIXED", 0.4
    s.lod_near, s.lod_far, s.lod_card, s.lod_joined = 500.0, 600.0, 700.0, 800.0
    return scene, rig, body, walk


def image_pixels(path) -> np.ndarray:
    """The image file at ``path`` as Blender loads it: ``(H, W, 4)`` float32, rows
    bottom-up (the image is removed from ``bpy.data`` again)."""
    img = bpy.data.images.load(str(path))
    try:
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)


def add_character(settings, rig, body=None, name=None, weight=1.0):
    """A character of ``scene.crowd`` (named after the rig unless ``name``)."""
    c = settings.characters.add()
    c.name = name or rig.name
    c.armature, c.body, c.weight = rig, body, weight
    return c


def add_lod(character, mesh):
    """A LOD mesh of a character (levels 1, 2 in the order added)."""
    lod = character.lods.add()
    lod.name, lod.object = f"LOD {len(character.lods)}", mesh
    return lod


def add_stream(owner, name, action, pool="streams"):
    """A stream (or unique) with one action node, of a character (or, given
    ``scene.crowd``, of its first character)."""
    if not hasattr(owner, "streams"):
        owner = owner.characters[0]
    anim = getattr(owner, pool).add()
    anim.name = name
    node = anim.nodes.add()
    node.name = "clip"
    node.kind = "CLIP"
    node.action = action
    return anim


def add_node(anim, name, kind, inputs=(), **props):
    """A node of ``kind`` reading the named ``inputs`` (``(label, node)`` pairs or
    node names); ``props`` set its other properties."""
    node = anim.nodes.add()
    node.name = name
    node.kind = kind
    for inp in inputs:
        label, target = inp if isinstance(inp, tuple) else (inp, inp)
        i = node.inputs.add()
        i.name, i.node = label, target
    for k, v in props.items():
        setattr(node, k, v)
    return node


class registered:
    """Context manager: the extension registered in this process for the block
    (left as found: a registration made by someone else is kept)."""

    def __enter__(self):
        import crowd_addon
        self.mine = not hasattr(bpy.types.Scene, "crowd")
        if self.mine:
            crowd_addon.register()
        return self

    def __exit__(self, *exc):
        import crowd_addon
        if self.mine:
            crowd_addon.unregister()


def extension_fixture():
    """A module-scoped autouse fixture for a test module (``extension =
    cs.extension_fixture()``): the extension registered for the module's tests, and
    every preview they left running stopped before it is unregistered."""
    @pytest.fixture(scope="module", autouse=True)
    def extension():
        with registered():
            yield
            from crowd_addon.blender import preview
            preview.stop_all()
    return extension


def init_gpu():
    """Blender's gpu module (and a GL context for moderngl) usable in background mode:
    the extension's own one-time initialising render."""
    from crowd_addon.blender.headless_gpu import init_headless_gpu
    init_headless_gpu()


class FakeBakeOperator:
    """Stands in for the modal bake operator's instance (no event loop in background
    mode): the operator's own ``modal``/``_end`` run against it, and what it reports is
    kept in ``reports`` as ``(kinds, message)``."""

    modal, _end = CROWD_OT_bake.modal, CROWD_OT_bake._end
    _timer = None

    def __init__(self, scene):
        self._job = BakeJob(scene)
        self.reports = []

    def report(self, kind, message):
        self.reports.append((set(kind), message))


#: a crowd script that leaves a mark of each part that runs: its module body writes
#: ``BODY``, its ``register(crowd)`` writes ``REGISTER``
MARKING_SCRIPT = '''\
from pathlib import Path
Path({body!r}).write_text("module body ran")


def register(crowd):
    Path({register!r}).write_text("register ran")
'''


def script_markers(folder, tag) -> tuple:
    """The marker files of :func:`scripted_blend`'s script ``tag``: (body, register)."""
    from pathlib import Path
    return Path(folder) / f"{tag}.body", Path(folder) / f"{tag}.register"


def scripted_blend(path, markers, tag, text="show.py"):
    """The :func:`walking_crowd` with a crowd script (the text ``text``) that writes
    :func:`script_markers` ``(markers, tag)`` when it runs, saved as ``path`` and left
    open; returns the two marker paths (neither written yet)."""
    scene = walking_crowd()[0]
    body, register = script_markers(markers, tag)
    script = bpy.data.texts.new(text)
    script.from_string(MARKING_SCRIPT.format(body=str(body), register=str(register)))
    scene.crowd.show.script = script
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return body, register
