"""All-or-nothing output of a main layer and its folder of layers.

An export is ``shot.usdc`` plus a *version* of its layers beside it,
``shot.layers/vN/`` (characters, streams, baked agents), which the main layer's asset
paths name. Everything is first written into a hidden temporary folder in the target
directory (``.shot.usdc.XXXX.tmp``, with an ``owner`` file naming the process).
:meth:`ExportFiles.commit` then

1. renames the finished layers to the new version folder, ``shot.layers/vN`` (the
   previous export, whose main layer names ``vN-1``, is untouched);
2. renames the main layer into place: this one rename is the commit;
3. removes the older versions that no stage reads (only what exports write:
   nothing else in ``shot.layers/`` is the export's to delete).

A crash (or kill) before step 2 leaves the previous export whole; after it, the new
one. A version is never changed once written, and is deleted only when no stage reads
it (usd/references.py): not the stages beside the export, nor the stages registered
in ``shot.layers/readers/`` (a stitched stage registers itself with each chunk it
reads), each followed through every layer it names. So re-exporting a chunk in place
leaves the version that a stitched stage reads. What a killed export leaves behind
(its temporary folder, an orphan version) is removed by the next export to the same
place: temporaries of our naming whose owner process is gone, and every older version
no stage reads.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import socket
import tempfile

from pxr import Tf

from ..core.base.errors import CrowdError
from .references import versions_in_use

__all__ = ["ExportFiles", "FORMATS", "remove_stale_temporaries"]

#: file extension -> Sdf file format of every layer of the export
FORMATS = {".usdc": "usdc", ".usd": "usdc", ".usda": "usda"}

#: what exports wrote straight into ``<stem>.layers/`` before versions (2026-11-23):
#: removed like an old version once no stage reads it
_UNVERSIONED = frozenset({"characters", "streams", "agents.usdc", "agents.usda"})


class ExportFiles:
    """The files of one export (use as a context manager; call :meth:`commit`).

    Parameters
    ----------
    path : the main layer, ``.usdc`` (default binary), ``.usd`` (binary) or
        ``.usda`` (text); its layers go to ``<stem>.layers/`` in the same directory.
    """

    def __init__(self, path):
        self.path = os.path.abspath(os.fspath(path))
        stem, ext = os.path.splitext(os.path.basename(self.path))
        if ext.lower() not in FORMATS or not stem:
            raise CrowdError(f"{path}: the output needs a name ending in "
                             f"{', '.join(FORMATS)} (got {ext or 'no extension'!r})")
        self.format = FORMATS[ext.lower()]
        self.ext = f".{self.format}"
        self.directory = os.path.dirname(self.path)
        self.layers_root = os.path.join(self.directory, f"{stem}.layers")
        if not os.path.isdir(self.directory):
            raise CrowdError(f"{path}: directory {self.directory} does not exist")
        if os.path.isdir(self.path):
            raise CrowdError(f"{path}: is a directory")
        if os.path.lexists(self.layers_root) and not os.path.isdir(self.layers_root):
            raise CrowdError(f"{path}: {self.layers_root} exists and is not a folder of "
                             "layers")
        self.version = f"v{_next_version(self.layers_root)}"
        self.layers_name = f"{stem}.layers/{self.version}"
        self.layers_dir = os.path.join(self.layers_root, self.version)
        self._tmp = None
        self.written = {}            # relative path -> bytes

    def __enter__(self):
        remove_stale_temporaries(self.directory, os.path.basename(self.path))
        try:
            self._tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(self.path)}.",
                                         suffix=".tmp", dir=self.directory)
        except OSError as e:
            raise CrowdError(f"{self.path}: cannot write in {self.directory}: "
                             f"{e.strerror or e}") from None
        with open(os.path.join(self._tmp, "owner"), "w", encoding="utf-8") as f:
            f.write(f"{socket.gethostname()} {os.getpid()}\n")
        os.mkdir(os.path.join(self._tmp, "layers"))
        return self

    def __exit__(self, *exc):
        shutil.rmtree(self._tmp, ignore_errors=True)
        self._tmp = None
        return False

    def asset_path(self, name: str) -> str:
        """Asset path of layer ``name`` (e.g. ``"streams/walk"``) relative to the main
        layer, as written in references and sublayers."""
        return f"./{self.layers_name}/{name}{self.ext}"

    def layer_path(self, name: str) -> str:
        """Asset path of layer ``name`` relative to another layer of the folder (as the
        value clips in the agents layer name the layers they read)."""
        return f"./{name}{self.ext}"

    def save(self, layer, name: str | None = None) -> int:
        """Write ``layer`` as layer ``name`` of the folder, or as the main layer when
        ``name`` is None; returns its size in bytes."""
        if name is None:
            target, key = os.path.join(self._tmp, f"main{self.ext}"), os.path.basename(
                self.path)
        else:
            target = os.path.join(self._tmp, "layers", *f"{name}{self.ext}".split("/"))
            key = f"{self.layers_name}/{name}{self.ext}"
        try:
            os.makedirs(os.path.dirname(target), exist_ok=True)
            ok = layer.Export(target)
        except (OSError, Tf.ErrorException) as e:
            raise CrowdError(f"{self.path}: cannot write layer {key}: {e}") from None
        if not ok:
            raise CrowdError(f"{self.path}: cannot write layer {key}")
        self.written[key] = os.path.getsize(target)
        return self.written[key]

    def copy(self, source: str, name: str) -> int:
        """Copy the file ``source`` into the folder as ``name`` (e.g. ``"textures/skin.png"``);
        returns its size in bytes."""
        target = os.path.join(self._tmp, "layers", *name.split("/"))
        key = f"{self.layers_name}/{name}"
        try:
            os.makedirs(os.path.dirname(target), exist_ok=True)
            shutil.copyfile(source, target)
        except OSError as e:
            raise CrowdError(f"{self.path}: cannot copy {source} to {key}: {e}") from None
        self.written[key] = os.path.getsize(target)
        return self.written[key]

    def commit(self) -> None:
        """Move the finished export into place (see the module docstring)."""
        staged = os.path.join(self._tmp, "layers")
        main = os.path.join(self._tmp, f"main{self.ext}")
        mask = os.umask(0)
        os.umask(mask)
        _step("start")
        try:
            os.makedirs(self.layers_root, exist_ok=True)
            os.chmod(staged, 0o777 & ~mask)
            if os.path.lexists(self.layers_dir):
                raise CrowdError(f"{self.path}: another export wrote {self.layers_dir} "
                                 "meanwhile; export again")
            os.rename(staged, self.layers_dir)
        except OSError as e:
            raise CrowdError(f"{self.path}: cannot move the export into place: "
                             f"{e.strerror or e}") from None
        _step("layers")
        try:
            os.replace(main, self.path)                      # the commit
        except OSError as e:
            shutil.rmtree(self.layers_dir, ignore_errors=True)
            raise CrowdError(f"{self.path}: cannot move the export into place: "
                             f"{e.strerror or e}") from None
        _step("main")
        self._remove_unread()

    def _remove_unread(self) -> None:
        """Step 3: delete the older versions that no stage reads
        (:func:`~crowd_addon.usd.references.versions_in_use`: the stages beside the
        export and the readers registered in ``<stem>.layers/readers/``, such as a
        stitched stage reading this chunk). Only what exports write is ever deleted:
        version folders (``vN`` below ours: a version above is another export's, still
        committing) and the entries of the layout before versions
        (:data:`_UNVERSIONED`); any other file or folder in ``<stem>.layers/`` is not
        the export's and stays. When what is in use cannot be told, nothing is
        deleted: a later export tries again."""
        ours = int(self.version[1:])
        try:
            names = os.listdir(self.layers_root)
        except OSError:
            return
        old = [n for n in names if n in _UNVERSIONED
               or ((m := re.fullmatch(r"v(\d+)", n)) and int(m.group(1)) < ours)]
        if not old:
            return
        try:
            used = versions_in_use(self.layers_root)
        except Exception:  # noqa: BLE001 - the export is committed; keep everything
            return
        for name in old:
            if name in used:
                continue
            path = os.path.join(self.layers_root, name)
            if os.path.isdir(path) and not os.path.islink(path):
                shutil.rmtree(path, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    os.unlink(path)


def _step(name: str) -> None:
    """A point of :meth:`ExportFiles.commit` (``start``, ``layers``, ``main``); tests
    replace it to kill the process there."""


def _next_version(layers_root) -> int:
    """One more than the highest ``vN`` folder in ``layers_root`` (1 when none)."""
    try:
        names = os.listdir(layers_root)
    except OSError:
        return 1
    found = [int(m.group(1)) for n in names if (m := re.fullmatch(r"v(\d+)", n))]
    return max(found, default=0) + 1


def remove_stale_temporaries(directory, main_name):
    """Remove ``.MAIN.XXXX.tmp`` folders of exports to ``main_name`` in ``directory``
    whose owner process (on this host) is gone, or that name no owner."""
    pattern = re.compile(re.escape(f".{main_name}.") + r"[A-Za-z0-9_]+\.tmp")
    try:
        names = os.listdir(directory)
    except OSError:
        return
    host = socket.gethostname()
    for name in names:
        path = os.path.join(directory, name)
        if not pattern.fullmatch(name) or not os.path.isdir(path) or os.path.islink(path):
            continue
        try:
            with open(os.path.join(path, "owner"), encoding="utf-8") as f:
                owner_host, pid = f.read().split()
            alive = owner_host != host or _running(int(pid))
        except (OSError, ValueError):
            alive = False
        if not alive:
            shutil.rmtree(path, ignore_errors=True)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True

