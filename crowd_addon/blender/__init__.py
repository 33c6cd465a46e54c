"""The Blender side of the crowd: the only package that imports ``bpy`` (DESIGN.md s.2).

It converts Blender data into core objects and back, and holds the UI. The
conversion of armatures, meshes and actions (docs/baking.md):

- :mod:`.armature`: armature object -> core ``Skeleton`` (bones ordered parents first,
  rest pose as the bind pose); skinned mesh object -> core ``ProxyMesh``.
- :mod:`.action_data`: an action's bone F-curves for an armature (slotted actions of
  Blender 4.4+/5.0 and legacy ``action.fcurves``), its frames to sample, pose markers
  and loop flag, validated up front.
- :mod:`.fcurve_eval`: Blender's F-curve evaluation in numpy (no bpy).
- :mod:`.bake`: actions -> core ``Clip`` objects at the crowd fps, with progress and
  cancel.

``crowd_addon/__init__.py`` never imports this package, so the core stays usable
without Blender.
"""
