"""What Blender's C code writes to the process's standard output and error (its log
lines, GHOST's EGL reports): a file descriptor sent elsewhere for a ``with`` block,
with C's own buffers flushed on the way back (Python's ``sys.stdout`` never sees
those writes).
"""

from __future__ import annotations

import contextlib
import os
import sys

__all__ = ["fd_redirected"]


@contextlib.contextmanager
def fd_redirected(fd: int, target: int):
    """For the ``with`` block, what is written to file descriptor ``fd`` (1: stdout, 2:
    stderr) goes to file descriptor ``target``; nothing is redirected when ``fd`` is
    not open (no standard output at all)."""
    stream = sys.stdout if fd == 1 else sys.stderr
    stream.flush()
    try:
        saved = os.dup(fd)
    except OSError:
        yield
        return
    try:
        os.dup2(target, fd)
        yield
    finally:
        stream.flush()
        _flush_c_stdio()
        os.dup2(saved, fd)
        os.close(saved)


def _flush_c_stdio():
    try:
        import ctypes
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):     # no C library to flush (Windows)
        pass
