"""Files written through a temporary name and a rename get the permissions a plain
``open(path, "w")`` would give them (``tempfile.mkstemp`` makes them 0600); an output
folder a command creates is gone again when the command fails."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from .errors import CrowdError

__all__ = ["file_mode", "folders_made"]


def file_mode(target) -> int:
    """Permission bits for a file about to replace ``target``: the existing file's, else
    ``0o666`` less the process umask."""
    try:
        return os.stat(target).st_mode & 0o777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


@contextlib.contextmanager
def folders_made(folder):
    """Create ``folder`` and its missing parents for the ``with`` block; when the block
    raises, remove the folders it created (deepest first, each only if empty) and let
    the exception go on. Folders that were there before are left alone. A folder that
    cannot be created is a CrowdError naming it."""
    folder = Path(folder)
    made, probe = [], folder
    while not probe.exists() and probe.parent != probe:
        made.append(probe)
        probe = probe.parent

    def remove():
        for path in made:
            try:
                path.rmdir()
            except OSError:
                break

    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        remove()
        raise CrowdError(f"output folder {folder}: cannot create it "
                         f"({e.strerror or e})") from None
    try:
        yield folder
    except BaseException:
        remove()
        raise
