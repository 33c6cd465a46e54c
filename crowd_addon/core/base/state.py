"""Copying a part's nested state (dicts, lists, arrays and plain values)."""

import numpy as np

__all__ = ["copy_state"]


def copy_state(state):
    """A deep copy of a nested state (dicts, lists, arrays and plain values)."""
    if isinstance(state, np.ndarray):
        return state.copy()
    if isinstance(state, dict):
        return {k: copy_state(v) for k, v in state.items()}
    if isinstance(state, list):
        return [copy_state(v) for v in state]
    return state
