"""The Blender side of the crowd: the only package that imports ``bpy``.

It reads Blender data into plain arrays and values for the core (and writes results
back), and holds the UI. The logic on those arrays lives in ``crowd_addon.core``
(docs/baking.md):

- :mod:`.armature`: armature object -> core ``Skeleton`` (bones ordered parents first,
  rest pose as the bind pose); skinned mesh object -> core ``ProxyMesh``
  (``core.bake.armature_math``).
- :mod:`.action_data`: an action's bone F-curves for an armature (slotted actions of
  Blender 4.4+/5.0 and legacy ``action.fcurves``) packed into a
  ``core.bake.fcurve.CurveSet``,
  its frames to sample, pose markers and loop flag, validated up front.
- :mod:`.bake`: actions -> core ``Clip`` objects at the crowd fps, with progress and
  cancel (F-curve evaluation and pose channels: ``core.bake.fcurve``,
  ``core.bake.pose_channels``).
- :mod:`.agents`: agent sources -> agents (``core.authoring.placement``);
  :mod:`.scene_config`: the Crowd settings -> a ``CrowdConfig`` (node lists:
  ``core.authoring.controller_graph``).
- :mod:`.props`, :mod:`.operators`, :mod:`.panels`, :mod:`.preview`, :mod:`.export`,
  :mod:`.import_usd` (a crowd stage back through Blender's USD importer): the UI;
  :mod:`.registration` registers it; :mod:`.blend_shot`: a .blend's shot for the
  commands (``crowd export --blend`` ..., through ``crowd_addon.shot_source``);
  :mod:`.cli_commands`: Blender's ``-c crowd`` command.

``crowd_addon/__init__.py`` never imports this package at import time, so the core
stays usable without Blender.
"""
