"""A .blend's baked crowd kept in its shot's snapshot folder, so a farm bakes it once.

A chunked export of a .blend runs its snapshot pass and then each chunk in a process
of its own (``crowd snapshot`` then ``crowd export --snapshots``, or the Dask farm's
tasks), and each used to open the .blend and bake its Crowd settings again: about 4 s
of CPU a chunk for the demo's stadium, the same clips every time. The snapshot pass
now keeps the configuration it baked in the snapshot folder; a chunk of the same
.blend reads it there instead of baking.

Files, beside the snapshots (several shots may share a folder):
``baked_<key[:16]>.json`` and ``.npz`` (the configuration,
:func:`~crowd_addon.core.authoring.config_io.save_config`) and
``baked_<key[:16]>.key.json``, written after them: the whole key, the
configuration's digest and the bake report's notes (``--strict`` and the printed
notes behave as after a bake).

The key (:func:`bake_key`) is a SHA-256 of the .blend's path and bytes, the path and
bytes of every library it links, the scene's name, Blender's version and the source
of this extension: a chunk reads the bake only when nothing it was made from
changed. Only a .blend opened from its file for the command (``--blend``) is kept
or read: the .blend already open in a Blender session may hold changes not saved,
so it is baked as it is. A file that is missing, another key's, damaged, or whose
configuration does not have the recorded digest is not used: the chunk bakes, as
it did before. The snapshot pass always bakes and replaces the file, and removes
the bakes of the same .blend and scene kept under other keys (of an earlier
version of the file).
"""

from __future__ import annotations

import hashlib
import json
import os
from functools import lru_cache

from ..core.authoring.config_io import config_digest, load_config, save_config
from ..core.bake.bake_report import BakeReport, Note
from ..core.base.errors import CrowdError
from ..core.base.files import write_atomic

__all__ = ["bake_key", "bake_of", "load_baked", "save_baked"]


def bake_of(scene) -> str:
    """What a kept bake is of: the .blend open here (its path) and ``scene``'s name. A
    newer bake of the same replaces the older one in a folder."""
    import bpy
    return f"{os.path.abspath(bpy.data.filepath)} scene {scene.name}"


def bake_key(scene) -> str:
    """The key of ``scene``'s bake (module docstring), of the .blend just opened here
    from its file (so its bytes are what is baked)."""
    import bpy
    h = hashlib.sha256()
    files = [bpy.data.filepath] + sorted(bpy.path.abspath(lib.filepath)
                                         for lib in bpy.data.libraries)
    for path in files:
        h.update(f"{os.path.abspath(path)}\n".encode("utf-8"))
        _update_with_file(h, path)
    h.update(f"scene {scene.name}\nblender {bpy.app.version_string}\n"
             f"code {_code_digest()}\n".encode("utf-8"))
    return h.hexdigest()


def _update_with_file(h, path):
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError as e:            # a library gone: a key no earlier bake has
        h.update(f"unreadable: {e}".encode("utf-8"))


@lru_cache(maxsize=1)
def _code_digest() -> str:
    """SHA-256 of this extension's Python source (every module, by relative path)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    h = hashlib.sha256()
    for folder, dirs, names in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(n for n in names if n.endswith(".py")):
            path = os.path.join(folder, name)
            h.update(os.path.relpath(path, root).replace(os.sep, "/").encode("utf-8"))
            _update_with_file(h, path)
    return h.hexdigest()


def _paths(folder, key) -> tuple:
    stem = os.path.join(os.fspath(folder), f"baked_{key[:16]}")
    return stem + ".json", stem + ".key.json"


def save_baked(folder, key: str, config, of: str) -> None:
    """Keep ``config`` (baked, its report in ``config.bake_report``) in ``folder``
    under ``key``; the key file goes last, so a reader never pairs it with another
    configuration. An earlier bake of the same (``of``: :func:`bake_of`) under
    another key is removed. CrowdError when it cannot be written."""
    path, key_path = _paths(folder, key)
    report = getattr(config, "bake_report", None) or BakeReport()
    save_config(config, path)
    record = {"key": key, "of": of, "digest": config_digest(config),
              "notes": [[str(n), n.kind, n.severity] for n in report]}
    text = (json.dumps(record, indent=1) + "\n").encode("utf-8")
    write_atomic(key_path, lambda f: f.write(text), "the bake's key")
    _forget_older(folder, key, of)


def _forget_older(folder, key, of):
    """Remove the bakes of ``of`` in ``folder`` kept under other keys (its key file
    first, so none is read half removed)."""
    for name in os.listdir(folder):
        if not (name.startswith("baked_") and name.endswith(".key.json")) or \
                name == os.path.basename(_paths(folder, key)[1]):
            continue
        key_path = os.path.join(folder, name)
        try:
            with open(key_path, encoding="utf-8") as f:
                if json.load(f).get("of") != of:
                    continue
            stem = key_path[:-len(".key.json")]
            for p in (key_path, stem + ".json", stem + ".npz"):
                if os.path.exists(p):
                    os.unlink(p)
        except (OSError, ValueError, AttributeError):
            continue                # not ours to judge: left as it is


def load_baked(folder, key: str):
    """The configuration kept in ``folder`` under ``key`` with its bake report, or
    None when there is none that can be trusted (module docstring)."""
    path, key_path = _paths(folder, key)
    try:
        with open(key_path, encoding="utf-8") as f:
            record = json.load(f)
        if record.get("key") != key:
            return None
        config = load_config(path)
        if config_digest(config) != record.get("digest"):
            return None
        notes = [Note(text, kind, severity) for text, kind, severity in record["notes"]]
    except (OSError, ValueError, TypeError, KeyError, CrowdError):
        return None
    config.bake_report = BakeReport(notes)
    return config
