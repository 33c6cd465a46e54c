"""Blender's actions and armatures as numpy, without Blender: F-curves evaluated as
Blender does, pose channels to local SQT, sample times and markers, the between-keys
accuracy check, rest skeletons and influences, and the bake's report. Above :mod:`..anim`.
"""
