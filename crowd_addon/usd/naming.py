"""USD names for the crowd's things: prim names, joint paths, layer file names.

Names in a crowd (bones like ``shoulder.L``, stream names with spaces) are free text;
USD prim names and joint path elements must be identifiers. Each name is made valid
with ``Tf.MakeValidIdentifier`` (``shoulder.L`` -> ``shoulder_L``) and, where two
names collide after that, later ones get ``_1``, ``_2``, ... The original names are
kept in the file (``jointNames``, ``customData``) so nothing is lost.
"""

from __future__ import annotations

from pxr import Tf

__all__ = ["unique_identifiers", "joint_paths"]


def unique_identifiers(names, casefold: bool = False) -> list:
    """Valid, pairwise distinct USD identifiers for ``names``, in order.

    ``casefold`` also keeps them distinct ignoring case (for file names on
    case-insensitive file systems).
    """
    out, seen = [], set()
    for name in names:
        base = Tf.MakeValidIdentifier(str(name))
        candidate, k = base, 0
        while (candidate.casefold() if casefold else candidate) in seen:
            k += 1
            candidate = f"{base}_{k}"
        seen.add(candidate.casefold() if casefold else candidate)
        out.append(candidate)
    return out


def joint_paths(bone_names, parents) -> list:
    """UsdSkel joint paths (``"root/hips/spine0"``) of a skeleton.

    Parameters
    ----------
    bone_names : sequence of str, B names.
    parents : (B,) int parent indices, ``-1`` for roots, parents before children.

    Returns
    -------
    list of B str; siblings whose valid names collide are told apart by a suffix.
    """
    children = {}
    for i, p in enumerate(parents):
        children.setdefault(int(p), []).append(i)
    element = [""] * len(bone_names)
    for kids in children.values():
        for i, name in zip(kids, unique_identifiers(bone_names[i] for i in kids)):
            element[i] = name
    paths = []
    for i, p in enumerate(parents):
        paths.append(element[i] if p < 0 else f"{paths[p]}/{element[i]}")
    return paths
