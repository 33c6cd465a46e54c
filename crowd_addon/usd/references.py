"""Which files a stage reads, and which versions of an export's layers are in use.

An export's layers live in versions, ``shot.layers/vN/``, and a version is never
changed once written: exporting to the same place again writes ``vN+1``. A version
is deleted only when no stage reads it (:func:`versions_in_use`). The stages that can
read a version of ``shot.layers/`` are

- the stage files beside the export (``*.usd``, ``*.usda``, ``*.usdc`` in its folder:
  its own main layer, and any stage made by hand there);
- the *readers* registered in ``shot.layers/readers/``: one small text file per stage
  elsewhere that reads these layers, holding that stage's path relative to
  ``shot.layers/``. ``crowd stitch`` registers the stitched stage with each of its
  chunks (:func:`register_reader`), because it reads their character layers and blend
  banks where they are.

Each such stage is read as it is on disk now, and followed through everything it
names, transitively (:func:`referenced_files`): a stitched stage reaches a chunk's
blend banks only through its own agents layer's value clips. A registered stage that
is gone, or that no longer reads anything of these layers, keeps nothing.
"""

from __future__ import annotations

import hashlib
import os
import re

from pxr import Sdf, Tf, UsdUtils

__all__ = ["referenced_files", "stages_beside", "versions_in_use", "register_reader",
           "READERS", "STAGE_EXTENSIONS", "COMPOSITION_ONLY"]

#: the folder of a ``<stem>.layers/`` that lists the stages elsewhere reading it
READERS = "readers"
#: the files that are USD layers (and may name other files)
STAGE_EXTENSIONS = (".usd", ".usda", ".usdc")
#: ``customLayerData.crowd.part`` of a layer whose only asset paths are its sublayers,
#: references and payloads (no value clips, no asset-valued attributes): an export's
#: layout
COMPOSITION_ONLY = "layout"


def referenced_files(roots, stop=None) -> set:
    """Every file the USD layers ``roots`` name, transitively, as normalised absolute
    paths: sublayers, references, payloads, value clips (``assetPaths``,
    ``manifestAssetPath``) and asset-valued attributes (textures), each resolved
    against the layer that names it.

    Each layer is read from disk as it is now (``Sdf.Layer.OpenAsAnonymous``: never a
    copy this process may hold in USD's layer registry). A named layer inside the folder
    ``stop`` is listed but not opened; one that is missing, or that USD cannot read, is
    listed and not followed: it names nothing. With ``stop``, an export's layout outside
    it is listed and not followed either (it names only the characters beside it). The
    roots themselves are listed only when another layer names them."""
    stop = os.path.normpath(os.path.abspath(stop)) if stop is not None else None
    found, seen = set(), set()
    todo = [os.path.normpath(os.path.abspath(os.fspath(r))) for r in roots]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        if stop is not None and _inside(path, stop):
            continue
        if stop is not None and _is_layout(path):
            # a layout names only its own folder's characters, which lie beside it,
            # outside ``stop`` as it does: nothing there can reach ``stop``
            continue
        for asset in _assets(path):
            if "://" in asset or Sdf.Layer.IsAnonymousLayerIdentifier(asset):
                continue                        # not a file of this file system
            real = os.path.normpath(os.path.join(os.path.dirname(path), asset))
            found.add(real)
            todo.append(real)
    return found


def _assets(path) -> set:
    """The asset paths layer file ``path`` names, as authored (empty: not a layer)."""
    if os.path.splitext(path)[1].lower() not in STAGE_EXTENSIONS or \
            not os.path.isfile(path):
        return set()
    try:
        layer = Sdf.Layer.OpenAsAnonymous(path)
    except Tf.ErrorException:
        return set()
    if layer is None:
        return set()
    if dict(layer.customLayerData).get("crowd", {}).get("part") == COMPOSITION_ONLY:
        # a crowd export's layout: 65,000 references and nothing else, which USD
        # lists in C++ (walking every field of it from Python takes ~5x longer)
        return set(layer.GetCompositionAssetDependencies()) - {""}
    assets = set()

    def note(asset):
        assets.add(asset)
        return asset                            # unchanged: the walk only reads
    UsdUtils.ModifyAssetPaths(layer, note)
    assets.discard("")
    return assets


def _is_layout(path) -> bool:
    """Whether ``path`` is an export's layout, ``<stem>.layers/vN/layout.<ext>``: known
    by its place, since opening it (65,000 agents, its metadata alone too) costs a
    third of a second."""
    folder, name = os.path.split(path)
    stem, ext = os.path.splitext(name)
    return stem == "layout" and ext.lower() in STAGE_EXTENSIONS and \
        re.fullmatch(r"v\d+", os.path.basename(folder)) is not None and \
        os.path.basename(os.path.dirname(folder)).endswith(".layers")


def _inside(path, folder) -> bool:
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def stages_beside(layers_root) -> list:
    """The stage files in the folder of ``layers_root`` (hidden ones left out: an
    export's temporaries) and the readers registered in it."""
    directory = os.path.dirname(os.path.normpath(layers_root))
    out = []
    try:
        names = os.listdir(directory)
    except OSError:
        names = []
    for name in sorted(names):
        path = os.path.join(directory, name)
        if not name.startswith(".") and \
                os.path.splitext(name)[1].lower() in STAGE_EXTENSIONS and \
                os.path.isfile(path):
            out.append(path)
    readers = os.path.join(layers_root, READERS)
    try:
        records = sorted(os.listdir(readers))
    except OSError:
        records = []
    for name in records:
        if not name.endswith(".txt"):
            continue                            # a record being written
        try:
            with open(os.path.join(readers, name), encoding="utf-8") as f:
                where = f.read().strip()
        except (OSError, UnicodeDecodeError):
            continue
        if where:
            out.append(os.path.normpath(os.path.join(layers_root, where)))
    return out


def versions_in_use(layers_root) -> set:
    """The entries of ``layers_root`` (``v1``, ``v2``, ...) that a stage reads: a stage
    beside the export or a registered reader (:func:`stages_beside`), followed through
    every layer it names (:func:`referenced_files`). The layers inside
    ``layers_root`` are not followed: a version names only its own layers and, for a
    stitched stage, its chunks'."""
    root = os.path.normpath(os.path.abspath(layers_root))
    used = set()
    for path in referenced_files(stages_beside(root), stop=root):
        if _inside(path, root) and path != root:
            used.add(os.path.relpath(path, root).split(os.sep)[0])
    return used


def register_reader(layers_root, stage) -> bool:
    """Record in ``layers_root/readers/`` that the stage at ``stage`` reads these
    layers (its path relative to ``layers_root``, so the two can move together); False
    when the folder cannot be written (then nothing protects what the stage reads from
    a later export to that place)."""
    root = os.path.normpath(os.path.abspath(layers_root))
    where = os.path.relpath(os.path.abspath(stage), root).replace(os.sep, "/")
    folder = os.path.join(root, READERS)
    name = hashlib.sha256(where.encode("utf-8")).hexdigest()[:20] + ".txt"
    target = os.path.join(folder, name)
    tmp = f"{target}.{os.getpid()}.tmp"
    try:
        os.makedirs(folder, exist_ok=True)
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(where + "\n")
        os.replace(tmp, target)
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        return False
    return True
