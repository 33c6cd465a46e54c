"""Procedural skeletons and clips for tests, benchmarks and demos without Blender.

The humanoid has the paper's 82 bones by default (spine, neck/head, two arms with
five three-bone fingers, two legs, plus face/extra bones to reach the count); the
clips are smooth periodic motions with exactly matching ends so they loop.
"""

from __future__ import annotations

import numpy as np

from ..base import pose as sqt
from ..base import quaternion as quat
from ..anim.clip import Clip
from ..base.skeleton import Skeleton

__all__ = ["humanoid", "humanoid_mesh", "spread_weights", "periodic_clip", "paper_config",
           "paper_stream_tree"]


def humanoid(name="fan", bones=82) -> Skeleton:
    """A depth-first humanoid skeleton of ``bones`` bones (at least 24)."""
    names, parents, offsets = [], [], []

    def add(n, parent, off):
        names.append(n)
        parents.append(parent)
        offsets.append(off)
        return len(names) - 1

    root = add("root", -1, (0, 0, 0))
    hips = add("hips", root, (0, 0, 1.0))
    spine = hips
    for i in range(3):
        spine = add(f"spine{i}", spine, (0, 0, 0.15))
    neck = add("neck", spine, (0, 0, 0.15))
    add("head", neck, (0, 0, 0.1))
    for side, sx in (("L", 1), ("R", -1)):
        sh = add(f"shoulder.{side}", spine, (sx * 0.08, 0, 0.1))
        up = add(f"upperarm.{side}", sh, (sx * 0.12, 0, 0))
        fo = add(f"forearm.{side}", up, (sx * 0.28, 0, 0))
        ha = add(f"hand.{side}", fo, (sx * 0.25, 0, 0))
        for f in range(5):
            p = ha
            for j in range(3):
                p = add(f"finger{f}_{j}.{side}", p, (sx * 0.03, 0.02 * (f - 2), 0))
    for side, sx in (("L", 1), ("R", -1)):
        th = add(f"thigh.{side}", hips, (sx * 0.1, 0, -0.05))
        sh = add(f"shin.{side}", th, (0, 0, -0.45))
        ft = add(f"foot.{side}", sh, (0, 0, -0.42))
        add(f"toe.{side}", ft, (0, 0.12, -0.05))
    head = names.index("head")
    i = 0
    while len(names) < bones:
        add(f"face{i}", head, (0.01 * (i % 5), 0.05, 0.02 * (i // 5)))
        i += 1
    names, parents, offsets = names[:bones], parents[:bones], offsets[:bones]
    bind = sqt.identity_pose(len(names))
    bind[:, sqt.TRANS] = offsets
    return Skeleton(name, names, parents, bind)


def periodic_clip(skeleton: Skeleton, name: str, frames=61, amplitude=0.6, seed=0, fps=30.0,
                  loop=True, events=(), bones=None) -> Clip:
    """A smooth looping clip: each bone swings about a random axis, period ``frames-1``.

    ``bones`` limits the motion to the given bone names (others keep the bind pose),
    e.g. the arms for a wave layer.
    """
    rng = np.random.default_rng(seed)
    b = skeleton.bone_count
    t = np.arange(frames) / (frames - 1) * 2 * np.pi
    axis = quat.normalize(rng.normal(size=(b, 4)))[:, 1:]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, b)
    amp = np.full(b, amplitude)
    if bones is not None:
        keep = np.isin(np.array(skeleton.bone_names), list(bones))
        amp = np.where(keep, amp, 0.0)
    angle = amp[None] * np.sin(t[:, None] + phase[None])            # (F, B)
    q = np.concatenate([np.cos(angle / 2)[..., None],
                        np.sin(angle / 2)[..., None] * axis[None]], axis=-1)
    keys = np.broadcast_to(skeleton.bind_pose, (frames, b, sqt.WIDTH)).astype(np.float64)
    keys = keys.copy()
    keys[..., sqt.ROT] = quat.multiply(keys[..., sqt.ROT], q)
    if bones is None or skeleton.bone_names[1] in bones:
        keys[:, 1, sqt.TRANS] += 0.05 * np.sin(t)[:, None] * np.array([0, 0, 1.0])
    keys[-1] = keys[0]
    return Clip(name, keys, fps=fps, loop=loop, events=events,
                bone_names=skeleton.bone_names)


def humanoid_mesh(skeleton: Skeleton, sides=8, rings=4, name=None):
    """A low-poly skinned body for :func:`humanoid`-like skeletons.

    One open tube per bone longer than 4 cm (from its parent's head to its own
    head, skinned to the parent and blending into the bone over its last half) and
    a sphere on the ``head`` bone if there is one. Returns a
    :class:`~.mesh.ProxyMesh` in the bind pose.
    """
    from ..meshes.mesh import ProxyMesh

    heads = skeleton.bind_model[:, :3, 3]
    pos, tris, idx, wts = [], [], [], []
    base = 0
    ang = np.arange(sides) * 2 * np.pi / sides
    for b, p in enumerate(skeleton.parents):
        if p < 0:
            continue
        a, c = heads[p], heads[b]
        axis = c - a
        length = float(np.linalg.norm(axis))
        if length < 0.04:
            continue
        axis /= length
        helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
        u = np.cross(axis, helper)
        u /= np.linalg.norm(u)
        v = np.cross(axis, u)
        radius = float(np.clip(0.22 * length, 0.025, 0.11))
        t = np.linspace(0, 1, rings)
        ring = (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v) * radius   # (sides, 3)
        pts = a + t[:, None, None] * (c - a) + ring[None]                        # (rings, sides, 3)
        pos.append(pts.reshape(-1, 3))
        wb = np.clip((t - 0.5) / 0.5, 0, 1) * 0.5
        w = np.stack([1 - wb, wb], 1)
        wts.append(np.repeat(w, sides, 0))
        idx.append(np.tile([p, b], (rings * sides, 1)))
        r0 = base + np.arange(rings - 1)[:, None] * sides
        s0, s1 = np.arange(sides), (np.arange(sides) + 1) % sides
        q00, q01 = r0 + s0, r0 + s1
        q10, q11 = q00 + sides, q01 + sides
        tris.append(np.stack([np.stack([q00, q01, q11], -1),
                              np.stack([q00, q11, q10], -1)], 2).reshape(-1, 3))
        base += rings * sides
    if "head" in skeleton.bone_names:
        h = skeleton.bone_names.index("head")
        lat = np.linspace(0, np.pi, rings + 3)[1:-1]
        sph = np.concatenate([
            [[0, 0, -1.0]],
            np.stack([np.sin(lat)[:, None] * np.cos(ang), np.sin(lat)[:, None] * np.sin(ang),
                      -np.cos(lat)[:, None] * np.ones_like(ang)], -1).reshape(-1, 3),
            [[0, 0, 1.0]]])
        centre = heads[h] + np.array([0, 0, 0.1])
        pos.append(centre + 0.11 * sph)
        n_lat = lat.size
        idx.append(np.tile([h, h], (sph.shape[0], 1)))
        wts.append(np.tile([1.0, 0.0], (sph.shape[0], 1)))
        s0, s1 = np.arange(sides), (np.arange(sides) + 1) % sides
        bottom, top = base, base + 1 + n_lat * sides
        ring = lambda k, s: base + 1 + k * sides + s                          # noqa: E731
        f = [np.stack([np.full(sides, bottom), ring(0, s1), ring(0, s0)], -1)]
        for k in range(n_lat - 1):
            f.append(np.stack([ring(k, s0), ring(k, s1), ring(k + 1, s1)], -1))
            f.append(np.stack([ring(k, s0), ring(k + 1, s1), ring(k + 1, s0)], -1))
        f.append(np.stack([ring(n_lat - 1, s0), ring(n_lat - 1, s1), np.full(sides, top)], -1))
        tris.append(np.concatenate(f))
    return ProxyMesh.from_influences(name or f"{skeleton.name}_body", skeleton.name,
                                     np.concatenate(pos), np.concatenate(tris),
                                     np.concatenate(idx), np.concatenate(wts),
                                     bone_count=skeleton.bone_count)


def box_prop(skeleton: Skeleton, bone: str, name: str = "box", size=(0.06, 0.06, 0.3),
             offset=(0.0, 0.0, 0.0), look=None):
    """A :class:`~.bodies.Prop`: a box ``size`` (metres) centred ``offset`` from the
    head of bone ``bone`` at the bind pose (armature space), rigid on that bone (a
    flag pole, a cup); ``look``: a :class:`~.mesh.Look` for it (None: none)."""
    from ..meshes.bodies import Prop, rigid_mesh

    b = skeleton.bone_index(bone)
    corners = np.array(np.meshgrid([-.5, .5], [-.5, .5], [-.5, .5], indexing="ij"))
    pos = corners.reshape(3, -1).T * np.asarray(size) + skeleton.bind_model[b, :3, 3] + offset
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([t for a, b_, c, d in quads for t in ((a, b_, c), (a, c, d))])
    looks = {} if look is None else {"looks": (look,)}
    return Prop(name, skeleton.name, b, rigid_mesh(name, skeleton.name, b, pos, tris,
                                                   skeleton.bone_count, **looks))


def spread_weights(skeleton: Skeleton, k: int, seed=0):
    """The :func:`humanoid_mesh` body with every vertex weighted to the ``k`` bones whose
    heads are nearest, by 1 / (distance + 5 cm)^2 with some noise (a smooth rig, as an
    FBX export has): ``(positions, triangles, indices (V, k), weights (V, k))``."""
    body = humanoid_mesh(skeleton)
    heads = skeleton.bind_model[:, :3, 3]
    d = np.linalg.norm(body.positions[:, None].astype(np.float64) - heads[None], axis=2)
    idx = np.argsort(d, axis=1, kind="stable")[:, :k]
    w = 1.0 / (np.take_along_axis(d, idx, 1) + 0.05) ** 2
    w *= np.random.default_rng(seed).uniform(0.5, 1.5, w.shape)
    return body.positions, body.triangles, idx, w


def paper_stream_tree(s: int):
    """Stream ``s`` of :func:`paper_config`: a clip or a small controller tree, cycling
    through plain clip, 2-way blend, additive wave layer, 2-D blend space and state
    machine (triggers ``goal`` / ``calm``)."""
    from ..anim.blends import Blend2, BlendSpace2D, Layer
    from ..anim.controllers import ClipPlayer
    from ..anim.state_machine import StateMachine, StateTransition
    c = lambda k: ClipPlayer(f"clip{(s + k) % 12}")  # noqa: E731
    kind = s % 5
    if kind == 0:
        return c(0)
    if kind == 1:
        return Blend2(c(0), c(1), weight=0.35)
    if kind == 2:
        return Layer(c(0), ClipPlayer("wave"), mode="additive",
                     bone_weights={"upperarm.R": 1, "forearm.R": 1, "hand.R": 1})
    if kind == 3:
        return BlendSpace2D([c(0), c(1), c(2), c(3)], [(0, 0), (1, 0), (0, 1), (1, 1)],
                            x=0.3, y=0.6)
    return StateMachine({"idle": c(0), "cheer": c(5)},
                        [StateTransition("idle", "cheer", 10, trigger="goal"),
                         StateTransition("cheer", "idle", 10, trigger="calm")])


def paper_config(agents: int, streams: int = 256, max_offset: int = 60, slots: int = 800,
                 bones: int = 82):
    """The paper's benchmark configuration (s.5) with synthetic content: ``streams``
    streams (:func:`paper_stream_tree`) over twelve looping clips of 90-310 frames
    (``clap`` tags on every third) and an arm wave, M, NT, an ``bones``-bone humanoid
    and ``agents`` agents (uniform offsets, no mesh, at the origin)."""
    from .config import CrowdConfig
    sk = humanoid("fan", bones)
    cfg = CrowdConfig(max_offset=max_offset, transition_slots=slots, seed=1)
    cfg.add_skeleton(sk)
    for i in range(12):
        cfg.add_clip(periodic_clip(sk, f"clip{i}", frames=90 + 20 * i, seed=i,
                                   events=[("clap", 12.0)] if i % 3 == 0 else ()))
    cfg.add_clip(periodic_clip(sk, "wave", frames=45, seed=99,
                               bones=["upperarm.R", "forearm.R", "hand.R"]))
    for s in range(streams):
        cfg.add_stream(f"stream{s}", "fan", paper_stream_tree(s))
    cfg.add_agents(agents)
    return cfg
