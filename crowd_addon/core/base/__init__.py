"""Foundations every other part of core shares: the error type, run bounds, file modes,
quaternions, SQT poses, skeletons, skinning maths (paper Eq. 1), cameras and copying
nested state. Imports nothing of ours outside this sub-package.
"""
