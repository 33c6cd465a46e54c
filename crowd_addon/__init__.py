"""Crowd animation for Blender (after Paduraru).

``core`` is pure numpy and usable anywhere; ``register``/``unregister`` are the
Blender extension hooks (the repository root's ``__init__.py`` re-exports them).
"""


def register():
    """Blender extension hook. The UI, operators and handlers arrive with the Blender
    issue; until then the extension loads and registers nothing."""


def unregister():
    """Blender extension hook, symmetric to :func:`register`."""
