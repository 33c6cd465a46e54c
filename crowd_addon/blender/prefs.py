"""The extension's preferences: how the viewport preview keeps snapshots for scrubbing.

The preview keeps a snapshot of its crowd every *Snapshot Every* frames within
*Snapshot Memory* (core ``SnapshotCache``), so jumping to any frame of a long shot
re-simulates fewer frames than that spacing instead of replaying from the start.
When the shot's snapshots would pass the memory cap the spacing doubles (the panel
shows the spacing in use).
"""

from __future__ import annotations

import bpy
from bpy.props import IntProperty

__all__ = ["CLASSES", "ADDON", "snapshot_settings", "DEFAULT_EVERY", "DEFAULT_MEMORY_MB"]

#: The add-on module Blender knows the extension by: the repository root's package
#: when installed as an extension (``bl_ext.<repository>.<id>``), else ``crowd_addon``.
_PACKAGE = __package__.rsplit(".", 1)[0]                     # crowd_addon or ....crowd_addon
ADDON = _PACKAGE.rsplit(".", 1)[0] if "." in _PACKAGE else _PACKAGE
DEFAULT_EVERY, DEFAULT_MEMORY_MB = 30, 2048


class CROWD_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = ADDON

    snapshot_every: IntProperty(
        name="Snapshot Every", default=DEFAULT_EVERY, min=1, soft_max=240, subtype="NONE",
        description="Frames between the snapshots the viewport preview keeps: a jump to "
                    "any frame re-simulates fewer frames than this")
    snapshot_memory_mb: IntProperty(
        name="Snapshot Memory (MB)", default=DEFAULT_MEMORY_MB, min=0, soft_max=65536,
        description="Memory the preview's snapshots may take per scene; past it the "
                    "spacing doubles. 0 keeps none (jumps back replay from the start)")

    def draw(self, _context):
        col = self.layout.column()
        col.use_property_split = True
        col.prop(self, "snapshot_every")
        col.prop(self, "snapshot_memory_mb")


def snapshot_settings(context=None) -> tuple:
    """``(every, max_bytes)`` from the preferences (the defaults where Blender has no
    preferences for the extension, e.g. when it is registered by a script)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON)
    p = getattr(addon, "preferences", None)
    every = int(getattr(p, "snapshot_every", DEFAULT_EVERY))
    memory = int(getattr(p, "snapshot_memory_mb", DEFAULT_MEMORY_MB))
    return every, memory * (1 << 20)


CLASSES = (CROWD_AP_preferences,)
