"""A character's meshes in the crowd's config: its body, LOD levels, mesh variants,
props and palette materials.

:func:`add_mesh` reads the character's body into its skeleton's ``ProxyMesh`` (with
its LOD meshes when given, else the automatic levels, and the card levels when on),
each mesh variant and each prop (:mod:`.armature` reads every object);
:func:`add_palettes` checks the character's palette materials against the materials
of those meshes. Errors are :class:`CrowdError` messages that name the character and
the LOD, variant, prop or palette at fault; the meshes' remarks go to a list of
notes (the bake report's).
"""

from __future__ import annotations

from ..core.authoring.config_agents import PALETTE_COLUMNS
from ..core.base.errors import CrowdError
from ..core.meshes.levels import CARD

__all__ = ["add_mesh", "add_palettes"]

#: LOD levels the settings give distances for (*LOD 1 From*, *LOD 2 From*)
MESH_LODS = 2


def _lod_levels(c, skeleton, cards, notes) -> tuple:
    """The ``lods`` argument of ``CrowdConfig.add_mesh`` for character ``c``: its LOD
    meshes (one serves both levels), then the card when on, or the automatic ratios,
    then the two far levels when on;
    the meshes' remarks (``ProxyMesh.notes``) go to the list ``notes``."""
    from .armature import proxy_mesh_from_object
    card = (CARD,) if cards else ()
    if len(c.lods) == 0:
        return (0.25, 0.06) + card * 2         # the far level, then with parts joined
    what = f"character {c.name!r}"
    if len(c.lods) > MESH_LODS:
        raise CrowdError(f"{what}: {len(c.lods)} LOD meshes; there are {MESH_LODS} levels "
                         "(LOD 1 From, LOD 2 From)")
    meshes = []
    for k, lod in enumerate(c.lods, start=1):
        if lod.object is None:
            raise CrowdError(f"{what}: LOD {k} has no mesh")
        try:
            meshes.append(proxy_mesh_from_object(lod.object, c.armature, skeleton))
        except CrowdError as e:
            raise CrowdError(f"{what}: LOD {k}: {e}") from None
        for note in meshes[-1].notes:
            if note not in notes:           # the body's mesh may serve as a LOD too
                notes.append(note)
    meshes += meshes[-1:] * (MESH_LODS - len(meshes))
    return tuple(meshes) + card


def add_mesh(cfg, c, skeleton, cards, notes):
    """Add character ``c``'s body with its LOD levels, its mesh variants and its props
    to ``cfg`` on ``skeleton`` (a character without a body may have none of them);
    their remarks go to the list ``notes``."""
    from .armature import prop_from_object, proxy_mesh_from_object
    if c.body is None:
        if len(c.lods) or len(c.variants) or len(c.props):
            raise CrowdError(f"character {c.name!r}: LOD meshes, mesh variants and props "
                             "need a body")
        return
    try:
        body = proxy_mesh_from_object(c.body, c.armature, skeleton)
    except CrowdError as e:
        raise CrowdError(f"character {c.name!r}: body: {e}") from None
    notes.extend(body.notes)            # e.g. vertices with more than eight bones
    cfg.add_mesh(body, lods=_lod_levels(c, skeleton, cards, notes))
    auto = (0.25, 0.06) + ((CARD, CARD) if cards else ())
    for k, v in enumerate(c.variants, start=1):
        what = f"character {c.name!r}: mesh variant {k}"
        if v.object is None:
            raise CrowdError(f"{what} has no mesh")
        try:
            mesh = proxy_mesh_from_object(v.object, c.armature, skeleton)
            cfg.add_variant(mesh, lods=auto)
        except CrowdError as e:
            raise CrowdError(f"{what}: {e}") from None
        notes.extend(n for n in mesh.notes if n not in notes)
    for k, p in enumerate(c.props):
        what = f"character {c.name!r}: prop {k + 1}"
        if p.object is None:
            raise CrowdError(f"{what} has no object")
        try:
            cfg.add_prop(prop_from_object(p.object, c.armature, skeleton, p.bone))
        except CrowdError as e:
            raise CrowdError(f"{what}: {e}") from None



def add_palettes(cfg, c):
    """The character's palette materials (``CrowdConfig.palette_materials``), each a
    material of its body, of a mesh variant or of a prop, named once."""
    if not len(c.palettes):
        return
    what = f"character {c.name!r}"
    if len(c.palettes) > PALETTE_COLUMNS:
        raise CrowdError(f"{what}: {len(c.palettes)} palettes; at most {PALETTE_COLUMNS}")
    meshes = [lv[0] for lv in cfg.mesh_variants(c.name)] + \
        [p.mesh for p in cfg.props.get(c.name, ())]
    looks = list(dict.fromkeys(k.name for m in meshes for k in m.looks))
    names = [p.material for p in c.palettes]
    for name in names:
        if name not in looks:
            raise CrowdError(f"{what}: palette material {name!r} is not a material of its "
                             f"body, mesh variants or props (their materials: {looks})")
    if len(set(names)) != len(names):
        raise CrowdError(f"{what}: two palettes for one material ({names})")
    cfg.palette_materials[c.name] = tuple(names)
