"""A recorded crowd shot -> UsdSkel stage (layout and usage in docs/usd_export.md).

Imports ``pxr`` (usd-core outside Blender, Blender's bundled ``pxr`` inside); the
command line imports this package only when ``crowd export`` runs.
"""

from .export import FORMAT_VERSION, LAYOUTS, ExportResult, check_export, export_crowd, export_steps

__all__ = ["export_crowd", "export_steps", "check_export", "ExportResult", "FORMAT_VERSION",
           "LAYOUTS"]
