"""All-or-nothing output of a main layer and its folder of layers.

An export is ``shot.usdc`` plus the folder ``shot.layers/`` beside it (characters,
streams, baked agents). Everything is first written into a hidden temporary folder
in the target directory; :meth:`ExportFiles.commit` then swaps the finished folder in
(the previous one is moved aside) and renames the main layer into place, so a
failure at any point before leaves no new file behind and the previous export as it
was. If a rename in the swap itself fails, the swap is undone before the error is
raised.
"""

from __future__ import annotations

import os
import shutil
import tempfile

from pxr import Tf

from ..core.errors import CrowdError

__all__ = ["ExportFiles", "FORMATS"]

#: file extension -> Sdf file format of every layer of the export
FORMATS = {".usdc": "usdc", ".usd": "usdc", ".usda": "usda"}


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
        self.layers_name = f"{stem}.layers"
        self.layers_dir = os.path.join(self.directory, self.layers_name)
        if not os.path.isdir(self.directory):
            raise CrowdError(f"{path}: directory {self.directory} does not exist")
        if os.path.isdir(self.path):
            raise CrowdError(f"{path}: is a directory")
        if os.path.lexists(self.layers_dir) and not os.path.isdir(self.layers_dir):
            raise CrowdError(f"{path}: {self.layers_dir} exists and is not a folder of "
                             "layers")
        self._tmp = None
        self.written = {}            # relative path -> bytes

    def __enter__(self):
        try:
            self._tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(self.path)}.",
                                         suffix=".tmp", dir=self.directory)
        except OSError as e:
            raise CrowdError(f"{self.path}: cannot write in {self.directory}: "
                             f"{e.strerror or e}") from None
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

    def commit(self) -> None:
        """Move the finished export into place (see the module docstring)."""
        staged = os.path.join(self._tmp, "layers")
        main = os.path.join(self._tmp, f"main{self.ext}")
        previous = os.path.join(self._tmp, "previous")
        mask = os.umask(0)
        os.umask(mask)
        moved_old = moved_new = False
        try:
            os.chmod(staged, 0o777 & ~mask)
            if os.path.isdir(self.layers_dir):
                os.rename(self.layers_dir, previous)
                moved_old = True
            os.rename(staged, self.layers_dir)
            moved_new = True
            os.replace(main, self.path)
        except OSError as e:
            if moved_new:
                os.rename(self.layers_dir, staged)
            if moved_old:
                os.rename(previous, self.layers_dir)
            raise CrowdError(f"{self.path}: cannot move the export into place: "
                             f"{e.strerror or e}") from None
