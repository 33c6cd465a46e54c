"""Files written through a temporary name and a rename get the permissions a plain
``open(path, "w")`` would give them (``tempfile.mkstemp`` makes them 0600); an output
folder a command creates is gone again when the command fails; output folders are
checked (:func:`writable_dir`) before any work and made (:func:`output_dir`) with a
CrowdError naming what is wrong."""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import socket
import tempfile
from pathlib import Path

import numpy as np

from .errors import CrowdError

__all__ = ["file_mode", "write_atomic", "npz_bytes", "staging", "remove_stale_staging",
           "folders_made", "writable_dir", "output_dir"]


def file_mode(target) -> int:
    """Permission bits for a file about to replace ``target``: the existing file's, else
    ``0o666`` less the process umask."""
    try:
        return os.stat(target).st_mode & 0o777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


def write_atomic(path, write, what: str, sync: bool = True) -> None:
    """Write file ``path`` whole or not at all: ``write(f)`` fills a temporary binary
    file in the same folder, which is synced to disk (``sync``: a crash of the
    machine then leaves the old file or the new one), given the permissions
    ``file_mode`` gives and renamed over ``path``. On any error the temporary is removed, the file
    that was at ``path`` stays as it was, and an OSError becomes a CrowdError
    "``path``: cannot write ``what``: ..."."""
    path = os.fspath(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp",
                                   dir=os.path.dirname(os.path.abspath(path)))
        with os.fdopen(fd, "wb") as f:
            write(f)
            if sync:
                f.flush()
                os.fsync(f.fileno())
        os.chmod(tmp, file_mode(path))          # mkstemp's 0600 is for its secrecy
        os.replace(tmp, path)
        tmp = None
    except OSError as e:
        raise CrowdError(f"{path}: cannot write {what}: {e.strerror or e}") from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def npz_bytes(arrays: dict) -> bytes:
    """The ``.npz`` file of ``arrays`` (``np.savez``), made in memory: written to a file
    directly, a failing write (a full disk) left numpy's zip writer half-closed, and its
    clean-up printed a second traceback."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def staging(folder, stem: str, suffix: str = "") -> Path:
    """This process's staging path ``folder/.STEM-HOST-PID SUFFIX`` (what a command
    writes before its outputs take their places): named by host and process, so
    :func:`remove_stale_staging` can tell a killed run's from a live one's."""
    return Path(folder) / f".{stem}-{_host()}-{os.getpid()}{suffix}"


def remove_stale_staging(folder, stem: str, suffix: str = "") -> None:
    """Remove the :func:`staging` paths of ``stem`` in ``folder`` that a process of this
    host left and that is gone (killed outright: SIGKILL, a crash, a power cut). A
    live process's, another host's, and anything not named so are left alone."""
    pattern = re.compile(re.escape(f".{stem}-{_host()}-") + r"(\d+)" + re.escape(suffix))
    try:
        names = os.listdir(folder)
    except OSError:
        return
    for name in names:
        m = pattern.fullmatch(name)
        if m is None or _alive(int(m.group(1))):
            continue
        path = os.path.join(folder, name)
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                os.unlink(path)


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9.]", "_", socket.gethostname()) or "host"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:            # another user's
        return True
    return True


@contextlib.contextmanager
def folders_made(folder, what: str = "output folder"):
    """Create ``folder`` and its missing parents for the ``with`` block; when the block
    raises, remove the folders it created (deepest first, each only if empty) and let
    the exception go on. Folders that were there before are left alone. A folder that
    cannot be created is a CrowdError naming it (as ``what``)."""
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
        raise CrowdError(f"{what} {folder}: cannot create it "
                         f"({e.strerror or e})") from None
    try:
        yield folder
    except BaseException:
        remove()
        raise


def writable_dir(path) -> Path:
    """``path`` checked to be a folder that exists and is writable, or one that can be
    created (its nearest existing ancestor is a writable folder); nothing is created.
    A CrowdError names the folder otherwise."""
    out = Path(path)
    probe = out
    try:
        while not probe.exists() and probe.parent != probe:
            probe = probe.parent
    except OSError as e:                       # a name too long for the file system
        raise CrowdError(f"output folder {str(out)[:80]}...: {e.strerror}") from None
    if not probe.is_dir():
        raise CrowdError(f"output folder {out}: cannot create it ({probe} is not a folder)")
    if not os.access(probe, os.W_OK):
        raise CrowdError(f"output folder {out}: "
                         + ("not writable" if probe == out else f"{probe} is not writable"))
    return out


def output_dir(path) -> Path:
    """``path`` as a folder that exists and is writable (created if missing), or a
    CrowdError naming it."""
    out = writable_dir(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CrowdError(f"output folder {out}: cannot create it ({e.strerror})") from None
    return out
