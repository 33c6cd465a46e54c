"""Blender extension entry point.

Blender loads the repository root as the extension package; everything lives in
``crowd_addon``. This file only re-exports its ``register``/``unregister``.
"""

from .crowd_addon import register, unregister  # noqa: F401
