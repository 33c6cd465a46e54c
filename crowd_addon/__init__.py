"""Crowd animation for Blender (after Paduraru).

``core`` is pure numpy and usable anywhere; :mod:`.api` is the simulation-side API
(headless or in Blender). ``register``/``unregister`` are the Blender extension hooks
(the repository root's ``__init__.py`` re-exports them); they import the ``bpy``
dependent modules only when called, so importing ``crowd_addon`` needs no Blender.
"""


def register():
    """Blender extension hook: properties, operators, panels, handlers
    (:mod:`crowd_addon.blender.registration`)."""
    from .blender import registration
    registration.register()


def unregister():
    """Blender extension hook, symmetric to :func:`register`."""
    from .blender import registration
    registration.unregister()
