"""Crowd -> UsdSkel stage (issue 5; layout and usage in docs/usd_export.md).

Imports ``pxr`` (usd-core outside Blender, Blender's bundled ``pxr`` inside); the
command line imports this package only when ``crowd export`` runs.
"""

from .export import FORMAT_VERSION, ExportResult, export_crowd

__all__ = ["export_crowd", "ExportResult", "FORMAT_VERSION"]
