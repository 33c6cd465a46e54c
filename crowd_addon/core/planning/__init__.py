"""Planning before building: the paper's memory model (s.5) and its report, and the
variety planner that picks M, copies and offsets within a budget. Above
:mod:`..authoring`.
"""
