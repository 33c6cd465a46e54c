"""Diversity measured and made: the repetition metric with its neighbour search,
and timing variation (speed streams, copies, spread offsets). Above :mod:`..runtime`.
"""
