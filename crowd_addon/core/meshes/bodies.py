"""What each agent is drawn with: its character's mesh variant and the props it carries.

A character (a skeleton) has one or more **mesh variants**, bodies that share its
skeleton (``CrowdConfig.meshes[skeleton]`` is variant 0, ``CrowdConfig.variants
[skeleton]`` the others, each a list of LOD levels), and up to :data:`MAX_PROPS`
**props**: :class:`Prop`, a small mesh rigidly bound to one bone (a flag in the hand,
a scarf, a cap). Every agent has a variant (``CrowdConfig.agent_variant``) and a set
of props (``CrowdConfig.agent_props``, a bit per prop), chosen once when the agents
are placed and stored in the configuration.

A **body** is one (skeleton, variant, props) triple that some agent uses: the
variant's levels with the props' triangles merged into each level, the far levels too
(a flag raised above a crowd of 10-pixel fans is what shows their goal; a prop is a
few boxes), so that a body draws, skins and exports as one mesh; the GPU preview, the
USD export (a layer per body) and the repetition metric see the same bodies in the
same order: :func:`crowd_bodies`. (*Render Crowd*, whose cost is a pose mesh per pose
in use, instances the variant and each prop as pieces of their own instead, so that
props share pose meshes across bodies.) A prop skinned by a single bone with weight 1
is the bone's rigid motion: the vertex moves by the bone's skinning matrix, as Blender
moves an object parented to that bone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError
from .levels import CARD
from .mesh import Look, ProxyMesh

__all__ = ["Prop", "Body", "MAX_PROPS", "crowd_bodies", "body_keys", "merge_meshes",
           "rigid_mesh", "is_card", "prop_names"]

#: Props a character may have: an agent's set of props is a byte.
MAX_PROPS = 8


@dataclass(frozen=True, eq=False)
class Prop:
    """A mesh rigidly bound to bone ``bone`` (index) of skeleton ``skeleton``:
    ``mesh`` is in the skeleton's armature space at the bind pose, every vertex weighted
    1 to that bone (:func:`rigid_mesh` makes one)."""

    name: str
    skeleton: str
    bone: int
    mesh: ProxyMesh

    def __post_init__(self):
        what = f"prop {self.name!r}"
        if not isinstance(self.name, str) or not self.name.strip():
            raise CrowdError(f"a prop of skeleton {self.skeleton!r} has an empty name")
        if not isinstance(self.mesh, ProxyMesh):
            raise CrowdError(f"{what}: mesh must be a ProxyMesh, got {type(self.mesh).__name__}")
        if self.mesh.skeleton != self.skeleton:
            raise CrowdError(f"{what}: its mesh is for skeleton {self.mesh.skeleton!r}, not "
                             f"{self.skeleton!r}")
        bone = int(self.bone)
        idx, w = self.mesh.bone_indices, self.mesh.bone_weights
        if not ((idx[:, 0] == bone).all() and np.allclose(w[:, 0], 1.0)):
            raise CrowdError(f"{what}: every vertex must be weighted 1 to bone {bone} (a prop "
                             "moves rigidly with one bone; use rigid_mesh)")
        object.__setattr__(self, "bone", bone)


def rigid_mesh(name, skeleton, bone, positions, triangles, bone_count=None,
               **looks) -> ProxyMesh:
    """A :class:`~.mesh.ProxyMesh` of ``positions`` (V, 3) armature space at the bind
    pose and ``triangles`` every vertex of which follows bone ``bone`` alone;
    ``looks``: ``uvs``, ``material``, ``looks``, ``normals``."""
    v = np.asarray(positions).reshape(-1, 3).shape[0]
    normals = looks.pop("normals", None)
    return ProxyMesh.from_influences(name, skeleton, positions, triangles,
                                     np.full((v, 1), int(bone)), np.ones((v, 1)), normals,
                                     bone_count, **looks)


def is_card(mesh: ProxyMesh) -> bool:
    """Whether ``mesh`` is a card level (:func:`~.levels.card_lod`, or the card per body
    part of :func:`~.levels.parts_lod`, both named ``<mesh>.card``)."""
    return mesh.name.endswith("." + CARD)


def merge_meshes(name: str, parts) -> ProxyMesh:
    """One mesh of ``parts`` (ProxyMeshes of one skeleton), their vertices and
    triangles one after the other. Looks are merged by name (the first part's look of
    a name wins); a part without looks among parts with looks takes a grey look named
    after it; texture coordinates are zero where a part has none."""
    parts = list(parts)
    if len(parts) == 1:
        return parts[0]
    width = max(p.influences for p in parts)
    looked = any(p.looks for p in parts)
    looks, index = [], {}

    def look_id(look):
        if look.name not in index:
            index[look.name] = len(looks)
            looks.append(look)
        return index[look.name]

    pos, nor, tri, idx, w, mat, uvs = [], [], [], [], [], [], []
    base = 0
    for p in parts:
        pad = width - p.influences
        pos.append(p.positions)
        nor.append(p.normals)
        tri.append(p.triangles.astype(np.int64) + base)
        idx.append(np.pad(p.bone_indices, ((0, 0), (0, pad))))
        w.append(np.pad(p.bone_weights, ((0, 0), (0, pad))))
        if looked:
            own = p.looks or (Look(p.name),)
            ids = np.array([look_id(k) for k in own], np.int64)
            local = np.zeros(p.triangle_count, np.int64) if p.material is None \
                else p.material.astype(np.int64)
            mat.append(ids[local])
        uvs.append(p.uvs if p.uvs is not None
                   else np.zeros((p.triangle_count, 3, 2), np.float32))
        base += p.vertex_count
    has_uvs = any(p.uvs is not None for p in parts)
    first = parts[0]
    return ProxyMesh(name, first.skeleton, np.concatenate(pos), np.concatenate(tri),
                     np.concatenate(idx), np.concatenate(w), np.concatenate(nor),
                     first.bone_count, tuple(n for p in parts for n in p.notes),
                     np.concatenate(uvs) if has_uvs else None,
                     np.concatenate(mat) if looked else None, tuple(looks))


@dataclass(frozen=True)
class Body:
    """A (skeleton, variant, props) triple some agent uses: ``skeleton`` its index in
    the configuration's skeletons, ``variant`` the mesh variant, ``props`` a bit per
    prop of the character, ``name`` (``"<variant mesh>"`` plus ``"+<prop>"`` per prop)
    and ``levels`` the LOD meshes to draw it with (empty when the character has no
    mesh: its agents are not drawn)."""

    skeleton: int
    variant: int
    props: int
    name: str
    levels: tuple

    @property
    def prop_ids(self) -> list:
        """The character's props this body carries (indices)."""
        return [j for j in range(MAX_PROPS) if self.props >> j & 1]


def prop_names(config, skeleton: str, mask: int) -> list:
    """The names of the props of ``skeleton`` in the bit set ``mask``."""
    props = config.props.get(skeleton, ())
    return [p.name for j, p in enumerate(props) if int(mask) >> j & 1]


def crowd_bodies(config, agent_skeleton) -> tuple:
    """``(bodies, agent_body)``: the :class:`Body` s the agents of ``config`` use,
    ordered by (skeleton, variant, props), and ``(N,)`` int64 each agent's index among
    them, given ``agent_skeleton`` (N,) (each agent's skeleton index)."""
    keys, agent_body = body_keys(config, agent_skeleton)
    names = list(config.skeletons)
    bodies = tuple(_body(config, int(s), names[int(s)], int(v), int(m)) for s, v, m in keys)
    return bodies, agent_body


def body_keys(config, agent_skeleton) -> tuple:
    """``(keys, agent_body)``: the (skeleton, variant, props) triples of the bodies the
    agents use ((B, 3) int64, in :func:`crowd_bodies` order) and each agent's index
    among them, without making the bodies' meshes."""
    skel = np.asarray(agent_skeleton, np.int64).reshape(-1)
    n = skel.size
    variant = config.variant_ids.astype(np.int64)
    props = config.prop_masks.astype(np.int64)
    if variant.shape != (n,) or props.shape != (n,):
        raise CrowdError(f"crowd: {n} agents but agent_variant / agent_props hold "
                         f"{variant.shape} / {props.shape}")
    key = (skel << 24) | (variant << 8) | props
    keys, agent_body = np.unique(key, return_inverse=True)
    triples = np.stack([keys >> 24, (keys >> 8) & 0xFFFF, keys & 0xFF], 1)
    return triples, agent_body.reshape(-1).astype(np.int64)


def _body(config, s: int, skeleton: str, v: int, mask: int) -> Body:
    variants = config.mesh_variants(skeleton)
    if not variants:
        return Body(s, v, mask, skeleton, ())
    if v >= len(variants):
        raise CrowdError(f"skeleton {skeleton!r}: an agent uses mesh variant {v}, but it has "
                         f"{len(variants)} (0..{len(variants) - 1})")
    props = config.props.get(skeleton, [])
    chosen = [j for j in range(MAX_PROPS) if mask >> j & 1]
    if chosen and chosen[-1] >= len(props):
        raise CrowdError(f"skeleton {skeleton!r}: an agent carries prop {chosen[-1]}, but it "
                         f"has {len(props)} props")
    levels = variants[v]
    extra = [props[j].mesh for j in chosen]
    name = "+".join([levels[0].name] + [props[j].name for j in chosen])
    suffix = name[len(levels[0].name):]
    out = tuple(m if not extra else merge_meshes(_with_props(m.name, suffix), [m, *extra])
                for m in levels)
    return Body(s, v, mask, name, out)


def _with_props(level: str, suffix: str) -> str:
    """A level's name with its props' (``"+flag+cap"``): after the level's, before the
    far levels' ``.card`` (so ``is_card`` still knows them)."""
    end = "." + CARD
    if level.endswith(end):
        return level[:-len(end)] + suffix + end
    return level + suffix

