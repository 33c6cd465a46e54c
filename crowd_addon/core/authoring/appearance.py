"""An agent's body as the placement draws it: its mesh variant among its character's,
the props it carries and the colour of each of its character's palette materials
(:class:`~.placement.CharacterStreams`, :class:`~.placement.Palette`), at random
(seeded) or by a point attribute. :func:`~.placement.place_agents` calls
:func:`bodies` and :func:`palettes`.
"""

from __future__ import annotations

import numpy as np

from ..meshes.bodies import MAX_PROPS
from .config_agents import PALETTE_COLUMNS
from ..base.errors import CrowdError

__all__ = ["bodies", "palettes"]

#: added to a source's seed for the draws of mesh variants (plus 31 x the character),
#: props (plus 31 x the character and the prop) and palette colours (plus 31 x the
#: character and the palette): apart from each other and from the placement's draws
_VARIANT_MESH_DRAW = 1009
_PROP_DRAW = 2003
_PALETTE_DRAW = 3003


def bodies(what, n, characters, char, seed, values) -> tuple:
    """``(variants (n,) int16, props (n,) uint8)``: each agent's mesh variant among
    its character's, and the props it carries."""
    variants, props = np.zeros(n, np.int16), np.zeros(n, np.uint8)
    for k in np.unique(char).tolist():
        c, mine = characters[k], np.flatnonzero(char == k)
        name = f"{what}: character {c.name!r}"
        count = len(c.variant_weights)
        if count > 1 and c.variant_mode == "ATTRIBUTE":
            pick = np.asarray(values(c.variant_attribute, "int"), np.int64)[mine]
            bad = np.flatnonzero((pick < 0) | (pick >= count))
            if bad.size:
                raise CrowdError(f"{name}: attribute {c.variant_attribute!r} gives mesh "
                                 f"variant {int(pick[bad[0]])} at point {int(mine[bad[0]])}; "
                                 f"it has variants 0..{count - 1}")
            variants[mine] = pick
        elif count > 1:
            w = np.asarray(c.variant_weights, np.float64)
            if not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
                raise CrowdError(f"{name}: mesh variant weights must be non-negative with "
                                 f"a positive sum, got {list(c.variant_weights)}")
            rng = np.random.default_rng(seed + _VARIANT_MESH_DRAW + 31 * k)
            variants[mine] = rng.choice(count, size=mine.size, p=w / w.sum())
        if len(c.prop_shares) > MAX_PROPS:
            raise CrowdError(f"{name}: {len(c.prop_shares)} props; at most {MAX_PROPS}")
        for j, share in enumerate(c.prop_shares):
            if not (np.isfinite(share) and 0 <= share <= 1):
                raise CrowdError(f"{name}: prop {j}'s share must be in 0..1, got {share!r}")
            rng = np.random.default_rng(seed + _PROP_DRAW + 31 * k + j)
            on = rng.uniform(0.0, 1.0, mine.size) < share
            props[mine[on]] |= np.uint8(1 << j)
    return variants, props


def palettes(what, n, characters, char, seed, values) -> np.ndarray:
    """(n, PALETTE_COLUMNS, 3) float32: per agent the colour of each palette of its
    character (-1 where there is none)."""
    out = np.full((n, PALETTE_COLUMNS, 3), -1.0, np.float32)
    for k in np.unique(char).tolist():
        c = characters[k]
        if len(c.palettes) > PALETTE_COLUMNS:
            raise CrowdError(f"{what}: character {c.name!r} has {len(c.palettes)} palettes; "
                             f"at most {PALETTE_COLUMNS}")
        mine = np.flatnonzero(char == k)
        for j, pal in enumerate(c.palettes):
            colors = np.asarray(pal.colors, np.float64).reshape(-1, 3)
            name = f"{what}: character {c.name!r}: palette {pal.material!r}"
            if not colors.size or not np.isfinite(colors).all():
                raise CrowdError(f"{name} has no colours (or one that is not finite)")
            if pal.mode == "ATTRIBUTE":
                pick = np.asarray(values(pal.attribute, "int"), np.int64)[mine]
                bad = np.flatnonzero((pick < 0) | (pick >= len(colors)))
                if bad.size:
                    raise CrowdError(f"{name}: attribute {pal.attribute!r} gives "
                                     f"{int(pick[bad[0]])} at point {int(mine[bad[0]])}; "
                                     f"the palette has colours 0..{len(colors) - 1}")
            else:
                pick = np.random.default_rng(seed + _PALETTE_DRAW + 31 * k + j).integers(
                    0, len(colors), mine.size)
            out[mine, j] = np.clip(colors[pick], 0.0, 1.0)
    return out
