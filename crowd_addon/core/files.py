"""Files written through a temporary name and a rename get the permissions a plain
``open(path, "w")`` would give them (``tempfile.mkstemp`` makes them 0600)."""

from __future__ import annotations

import os

__all__ = ["file_mode"]


def file_mode(target) -> int:
    """Permission bits for a file about to replace ``target``: the existing file's, else
    ``0o666`` less the process umask."""
    try:
        return os.stat(target).st_mode & 0o777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask
