"""The Blender side of the crowd: the only package that imports ``bpy``.

It reads Blender data into plain arrays and values for the core (and writes results
back), and holds the UI. The logic on those arrays lives in ``crowd_addon.core``
(docs/baking.md):

- :mod:`.armature`: armature object -> core ``Skeleton`` (bones ordered parents first,
  rest pose as the bind pose); skinned mesh object -> core ``ProxyMesh``
  (``core.armature_math``).
- :mod:`.action_data`: an action's bone F-curves for an armature (slotted actions of
  Blender 4.4+/5.0 and legacy ``action.fcurves``) packed into a ``core.fcurve.CurveSet``,
  its frames to sample, pose markers and loop flag, validated up front.
- :mod:`.bake`: actions -> core ``Clip`` objects at the crowd fps, with progress and
  cancel (F-curve evaluation and pose channels: ``core.fcurve``,
  ``core.pose_channels``).
- :mod:`.agents`: agent sources -> agents (``core.placement``); :mod:`.scene_config`:
  the Crowd settings -> a ``CrowdConfig`` (node lists: ``core.controller_graph``).
- :mod:`.props`, :mod:`.operators`, :mod:`.panels`, :mod:`.preview`, :mod:`.export`,
  :mod:`.import_usd` (a crowd stage back through Blender's USD importer): the UI; :mod:`.registration` registers it; :mod:`.cli_commands`: ``crowd export
  --blend`` and Blender's ``-c crowd`` command.

``crowd_addon/__init__.py`` never imports this package at import time, so the core
stays usable without Blender.
"""
