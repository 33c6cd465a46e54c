"""What Render Crowd instances, and in which pose: the pieces, their levels and aims.

Each agent is one piece for its mesh variant and one more per prop it carries
(:func:`agent_pieces`); a piece's level of detail follows the scene camera at the render
resolution with the crowd's own LOD distances (:func:`agent_lods`), as the GPU
preview would draw through that camera; a looking agent's head turn is rounded to
:data:`AIM_STEP` into an aim class (:func:`aim_classes`), so agents of one pose whose
turns round alike share a pose mesh, whose skinning rows :func:`aimed_rows` gives
(:func:`aim_codes`: the classes as codes that keep from frame to frame);
:class:`ShownPoses` keeps which pose object shows which pose, and when its row was
written, so a frame skins again only what changed. :mod:`.render_crowd` makes the
Blender data of them.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.meshes.lod import agent_heights, levels_from_pixels, projected_heights, switch_pixels
from ..core.runtime.look_at import apply_look, look_angles, turns_of
from ..gpu.draw_lists import view_depths

__all__ = ["AIM_BITS", "AIM_STEP", "ShownPoses", "agent_lods", "agent_pieces", "aim_classes",
           "aim_codes", "aimed_rows"]


def agent_lods(crowd, scene, levels) -> np.ndarray:
    """``(N,)`` level of detail of each agent seen through ``scene``'s camera at its
    render resolution, by its projected height in pixels (as the GPU draws it:
    :mod:`crowd_addon.core.meshes.lod`) (every agent's finest level when the scene has no camera);
    ``levels`` (N,): the levels each agent's mesh has."""
    from .cameras import camera_from_object
    from .cameras import scene_size

    if scene.camera is None or scene.camera.type != "CAMERA":
        return np.zeros(crowd.agents.count, np.int64)
    w, h = scene_size(scene)
    camera = camera_from_object(scene.camera, w / h)
    cfg = crowd.config
    names = list(cfg.skeletons)
    bodies = [cfg.meshes.get(n) or () for n in names]
    heights = agent_heights(bodies, np.asarray(crowd.view.agent_skeleton, np.int64),
                            crowd.agents.scale)
    depth, focal = view_depths(crowd.agents.position, camera.view_projection, h)
    return levels_from_pixels(projected_heights(heights, depth, focal), switch_pixels(cfg),
                              levels).astype(np.int64)


def agent_pieces(crowd, scene):
    """What the points instance: each agent's mesh variant, then one piece per prop an
    agent carries (props are small and rigid: their pose meshes are shared by every
    agent whose bone is in the same pose, instead of a pose mesh per combination of
    props; at every level, as on the GPU). Returns ``(agent, drawable,
    prop, lod, levels, palettes)``: per piece its agent, drawable index (a (skeleton,
    variant) or (skeleton, prop) pair), prop index (-1: the body) and level (through
    ``scene``'s camera: :func:`agent_lods`), and per drawable its LOD meshes (empty:
    not drawn) and its character's palette materials."""
    cfg = crowd.config
    names = list(cfg.skeletons)
    skel = np.asarray(crowd.view.agent_skeleton, np.int64)
    variant = cfg.variant_ids.astype(np.int64)
    mask = cfg.prop_masks.astype(np.int64)
    pairs, of_agent = np.unique(skel * 65536 + variant, return_inverse=True)
    levels = [tuple(cfg.mesh_variants(names[k >> 16])[k & 0xFFFF])
              if cfg.meshes.get(names[k >> 16]) else () for k in pairs.tolist()]
    palettes = [cfg.palette_materials.get(names[k >> 16], ()) for k in pairs.tolist()]
    of_agent = of_agent.reshape(-1)
    lod = agent_lods(crowd, scene, np.array([len(lv) for lv in levels], np.int64)[of_agent])
    agent = [np.arange(skel.size)]
    drawable, prop, level = [of_agent], [np.full(skel.size, -1)], [lod]
    for k, name in enumerate(names):
        for j, p in enumerate(cfg.props.get(name, ())):
            on = (skel == k) & (mask >> j & 1 == 1)
            ids = np.flatnonzero(on)
            if ids.size:
                agent.append(ids)
                drawable.append(np.full(ids.size, len(levels)))
                prop.append(np.full(ids.size, j))
                level.append(np.zeros(ids.size, np.int64))
                levels.append((p.mesh,))
                palettes.append(cfg.palette_materials.get(name, ()))
    return (np.concatenate(agent), np.concatenate(drawable), np.concatenate(prop),
            np.concatenate(level), levels, palettes)


#: Render Crowd's aim step: a looking agent's head turn (yaw, pitch) is rounded to it,
#: so agents of one pose whose turns round alike share a pose mesh (docs/gpu.md)
AIM_STEP = math.radians(2.0)


def aim_classes(crowd, step: float = AIM_STEP) -> tuple:
    """``(aim, turns)``: per agent its aim class (0: not turned: no look, or a turn
    that rounds to nothing) and per class the head's turn ``(dyaw, dpitch)``, each a
    whole number of ``step`` (core/runtime/look_at.py's turn of that agent's look, rounded)."""
    view = crowd.view
    n = view.agent_count
    ids = np.arange(n)
    w = view.looks.weights(view.frame, ids)
    angles = np.zeros((n, 2))
    for sk, chain in enumerate(view.look_chains):
        pick = np.flatnonzero((w > 0) & (view.agent_skeleton == sk))
        if chain is None or not pick.size:
            continue
        rows = view.skinning.rows(view.agent_rows_index(pick))
        angles[pick] = np.c_[look_angles(rows, chain, crowd.look_targets_model(pick),
                                         w[pick])]
    q = np.rint(angles / step).astype(np.int64)
    turned = (q != 0).any(1)
    aim = np.zeros(n, np.int64)
    pairs, inverse = np.unique(q[turned], axis=0, return_inverse=True)
    aim[turned] = inverse.reshape(-1) + 1
    return aim, np.r_[np.zeros((1, 2)), pairs.reshape(-1, 2) * step]


def aimed_rows(crowd, agents, aims, turns) -> np.ndarray:
    """Skinning rows of ``agents`` (one skeleton), their looks as aim classes
    ``aims`` (:func:`aim_classes`)."""
    view = crowd.view
    rows = view.skinning.rows(view.agent_rows_index(agents))
    m = np.flatnonzero(aims > 0)
    if m.size:
        chain = view.look_chains[int(view.agent_skeleton[agents[0]])]
        t = turns[aims[m]]
        rows[m] = apply_look(rows[m], chain, turns_of(rows[m], chain, t[:, 0], t[:, 1])) \
            .astype(rows.dtype)
    return rows


class ShownPoses:
    """What each pose object ``j`` showed after Render Crowd's last sync of
    ``storage``'s crowd: its ``key`` (a piece key; -1 none) and the pose storage's
    ``version`` of its row when it was skinned. A sync keeps a key on its pose object
    and skins again only where the row was written since (the new history slice, the
    uniques), for a transition slot (blended anew each frame) or a key new to the
    frame, which takes a pose object left free."""

    def __init__(self, storage=None):
        self.storage = storage
        self.key = np.zeros(0, np.int64)
        self.version = np.zeros(0, np.int64)
        #: (part * 16 + level) -> the digest of what its meshes were made from
        self.made = {}

    def place(self, keys: np.ndarray) -> tuple:
        """``(j, kept)``: the pose object of each of the sorted unique ``keys`` (its
        last one where it had one, else one left free, else a new one at the end) and
        whether it had it."""
        old = self.key
        order = np.argsort(old, kind="stable")
        at = np.clip(np.searchsorted(old[order], keys), 0, max(old.size - 1, 0))
        kept = (old[order][at] == keys) if old.size else np.zeros(keys.size, bool)
        j = np.full(keys.size, -1, np.int64)
        j[kept] = order[at[kept]]
        taken = np.zeros(old.size, bool)
        taken[j[kept]] = True
        free = np.flatnonzero(~taken)
        new = np.flatnonzero(~kept)
        use = min(free.size, new.size)
        j[new[:use]] = free[:use]
        j[new[use:]] = old.size + np.arange(new.size - use)
        return j, kept


#: bits of a piece key below its row, part and level: its aim (:func:`aim_codes`)
AIM_BITS = 20


def aim_codes(crowd) -> tuple:
    """``(code, turn)``: per agent a code of its aim class that stays the same from frame
    to frame (0: not turned; else its rounded yaw and pitch steps, each offset by 512)
    and per agent the turn ``(dyaw, dpitch)`` its class stands for."""
    aim, turns = aim_classes(crowd)
    q = np.rint(turns / AIM_STEP).astype(np.int64)
    code = np.where(aim > 0, ((q[aim, 0] + 512) << 10) + q[aim, 1] + 512, 0)
    return code, turns[aim]
