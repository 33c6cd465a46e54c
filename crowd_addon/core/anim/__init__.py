"""Clips and controllers: clips with their event tags, the six controller kinds (paper
s.3.4) and the evaluator that batches every tree's nodes, with the dependency graph
that orders a frame's tasks (s.4.4-4.5). Above :mod:`..base`.
"""
