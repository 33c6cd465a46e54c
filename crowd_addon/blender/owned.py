"""Which Blender data the extension made: a mark on each datablock it makes.

The extension reuses, replaces and removes only data that carries its mark (the
custom property :data:`MARK`, whose value says what made it), never data of the user's
that merely bears one of its names: a new datablock whose name is taken is named by
Blender (``Stands.001``). Data made once per scene is found through the scene instead
(*Generate Seats*: the scene's custom properties that point at its objects), since a
duplicate of a marked object carries the mark too.
"""

from __future__ import annotations

__all__ = ["MARK", "mark", "made"]

#: the custom property that marks a datablock the extension made
MARK = "crowd_generated"


def mark(block, what: str):
    """``block``, marked as made by ``what``."""
    block[MARK] = what
    return block


def made(block, what: str) -> bool:
    """Whether ``block`` (or None) carries the mark of ``what``."""
    return block is not None and block.get(MARK) == what
