"""Crowd scenes driven through a renderer, shared by both backends' tests.

Each scene builds its crowd with ``conftest.make_config``, steps it, calls the
renderer (``make(crowd, size)`` -> a renderer with ``sync``, ``render``,
``read_image``, ``read_pose_texture``, ``skinned_positions``) and returns named
arrays: ``gpu/...`` what the renderer gave, ``ref/...`` core's answer for the same
thing (CPU skinning of ``crowd.agent_rows``, the pose texture mirror, the dirty
bytes). No GL here: ``blender_backend_run.py`` runs the scenes in a Blender
subprocess, the tests run the image scenes with moderngl too.
"""

import importlib.util
import os

import numpy as np

from crowd_addon.core.base.camera import frame_crowd


def _load_conftest():
    """This directory's conftest (its crowd builders) under a name of its own, so no
    other directory's ``conftest`` module can stand in for it."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "conftest.py")
    spec = importlib.util.spec_from_file_location("gpu_tests_conftest", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


c = _load_conftest()

SIZE = (200, 150)


def _positions(out, key, r, crowd, agents, lod=0):
    mesh = crowd.config.meshes["fan"][lod]
    out[f"gpu/{key}"] = r.skinned_positions(agents, lod=lod)
    out[f"ref/{key}"] = c.world_reference(crowd, agents, mesh)


def streamed(make):
    """Streamed agents at every offset over three frames (three of them moved or
    turned at the second), the pose texture and the bytes each sync sends."""
    crowd = c.Crowd(c.make_config(M=8, agents=24))
    r, out = make(crowd, None), {}
    st = crowd.storage
    for f in range(3):
        if f == 1:
            crowd.place_agents([0, 5], position=crowd.agents.position[[0, 5]]
                               + np.float32([0.5, -0.25, 0.1]))
            crowd.place_agents([7], heading=crowd.agents.heading[[7]] + 1.0)
        crowd.step()
        dirty = st.dirty_ranges()
        stats = r.sync()
        out[f"gpu/bytes{f}"] = np.array(stats.pose_bytes)
        out[f"gpu/instance_bytes{f}"] = np.array(stats.instance_bytes)
        out[f"ref/rows{f}"] = np.array(sum(n for _, n in dirty))
        out[f"gpu/texture{f}"] = r.read_pose_texture()
        out[f"ref/texture{f}"] = st.texture_image()
        _positions(out, f"frame{f}", r, crowd, np.arange(crowd.agents.count))
    out["ref/row_bytes"] = np.array(st.row_bytes)
    return out


def unique(make):
    cfg = c.make_config(uniques=2)
    c.make_unique(cfg, [1, 5, 9], unique=0)
    c.make_unique(cfg, [2, 7], unique=1)
    crowd = c.Crowd(cfg)
    r, out = make(crowd, None), {}
    for _ in range(4):
        crowd.step()
    r.sync()
    _positions(out, "unique", r, crowd, np.array([1, 2, 5, 7, 9]))
    return out


def transitions(make, skinning):
    """Agents blending towards a stream and a unique, three frames."""
    crowd = c.Crowd(c.make_config(NT=4), skinning=skinning)
    r, out = make(crowd, None), {}
    crowd.step()
    r.sync()
    agents = np.array([0, 3, 4, 10])
    crowd.transition_to_streamed(agents[:3], "s2", 6, offset=5)
    crowd.transition_to_unique(agents[3:], "u0", 5)
    for f in range(3):
        crowd.step()
        out[f"gpu/skinned_rows{f}"] = np.array(r.sync().skinned_rows)
        _positions(out, f"frame{f}", r, crowd, agents)
    return out


def lods(make):
    crowd = c.Crowd(c.make_config())
    r, out = make(crowd, None), {}
    crowd.step()
    r.sync()
    for lod in range(len(crowd.config.meshes["fan"])):
        _positions(out, f"lod{lod}", r, crowd, np.arange(0, crowd.agents.count, 3), lod)
    return out


def looks(make):
    """Agents looking at a moving target (a neck, head chain), blending in, held and
    looking away, over six frames: every agent against core's skinning of
    ``Crowd.agent_rows`` (the looks applied on the CPU), and the look bytes each sync
    sends (only when a look starts or stops)."""
    import math
    from crowd_addon.core.runtime.look_at import LookRig, LookTarget
    cfg = c.make_config(M=8, agents=20)
    cfg.look_rigs["fan"] = LookRig(("neck", "head"), (0.4, 0.6),
                                   yaw_limit=math.radians(70), pitch_limit=math.radians(35))
    t = np.arange(60.0)
    cfg.look_targets["ball"] = LookTarget(
        "ball", 0, np.c_[3 + 8 * np.cos(t / 7), 3 + 8 * np.sin(t / 7), 2 + np.sin(t / 4)],
        smoothing=3.0)
    crowd = c.Crowd(cfg)
    r, out = make(crowd, None), {}
    agents = np.arange(crowd.agents.count)
    crowd.look_at(agents[::2], "ball", blend=3)
    crowd.look_at(agents[1::4], "ball", blend=0, hold=3)
    for f in range(6):
        if f == 4:
            crowd.look_away(agents[::4], blend=2)
        crowd.step()
        out[f"gpu/look_bytes{f}"] = np.array(r.sync().look_bytes)
        _positions(out, f"frame{f}", r, crowd, agents)
    return out


def many_influences(make, k=6):
    """A body with ``k`` bones a vertex (up to eight are kept exactly): every agent of
    the full mesh against core skinning with the vertices' own ``k`` influences, and
    every LOD against core skinning of that LOD's mesh, after a transition started."""
    crowd = c.Crowd(c.make_config(influences=k))
    r, out = make(crowd, None), {}
    crowd.step()
    crowd.transition_to_unique([2, 5], "u0", 4)
    crowd.step()
    r.sync()
    agents = np.arange(crowd.agents.count)
    levels = crowd.config.meshes["fan"]
    _, _, idx, w = c.spread_influences(crowd.config.skeletons["fan"], k)
    out["gpu/full"] = r.skinned_positions(agents)
    out["ref/full"] = c.world_reference(crowd, agents, levels[0], (idx, w))
    out["gpu/influences"] = np.array([r.meshes[key].buffers.influences
                                      for key in sorted(r.meshes)])
    for lod in range(len(levels)):
        _positions(out, f"lod{lod}", r, crowd, agents[::3], lod)
    return out


def wrapped(make, max_texture_size):
    """24 streams, M = 24, transitions; ``max_texture_size=256`` wraps the pose rows
    into three column blocks."""
    crowd = c.Crowd(c.make_config(M=24, streams=24, NT=8, max_texture_size=max_texture_size))
    r, out = make(crowd, SIZE), {}
    for i in range(6):
        if i == 2:
            crowd.transition_to_streamed([1, 5, 6], "s7", 8, offset=20)
        crowd.step()
        r.sync()
    out["gpu/blocks"] = np.array(crowd.storage.blocks)
    r.render(frame_crowd(crowd, aspect=SIZE[0] / SIZE[1]))
    out["gpu/image"] = r.read_image()
    _positions(out, "all", r, crowd, np.arange(crowd.agents.count))
    return out


def image(make):
    """Sixteen agents after five frames, framed by the crowd camera."""
    crowd = c.Crowd(c.make_config(M=8, agents=16, spacing=0.9))
    r, out = make(crowd, SIZE), {}
    for _ in range(5):
        crowd.step()
        r.sync()
    r.render(frame_crowd(crowd, aspect=SIZE[0] / SIZE[1]))
    out["gpu/image"] = r.read_image()
    out["gpu/lod"] = r.plan.lists.lod.copy()
    return out

