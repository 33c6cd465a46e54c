"""Copying a part's nested state (dicts, lists, arrays and plain values), and
setting an array from a state value."""

import numpy as np

__all__ = ["copy_state", "assign"]


def copy_state(state):
    """A deep copy of a nested state (dicts, lists, arrays and plain values)."""
    if isinstance(state, np.ndarray):
        return state.copy()
    if isinstance(state, dict):
        return {k: copy_state(v) for k, v in state.items()}
    if isinstance(state, list):
        return [copy_state(v) for v in state]
    return state


def assign(dest: np.ndarray, value) -> None:
    """``dest[...] = value``, where ``value`` may be a packed array that unpacks itself
    into ``dest`` (``unpack_into``: a snapshot's pose history, without a whole copy
    first)."""
    into = getattr(value, "unpack_into", None)
    if into is not None:
        into(dest)
    else:
        dest[...] = value
