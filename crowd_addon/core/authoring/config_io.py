"""Save and load a :class:`~.config.CrowdConfig` without Blender (docs/config_format.md).

A configuration is two files side by side, like glTF's ``.gltf`` + ``.bin``:

- ``<stem>.json``, the *manifest*: human readable JSON with the format name and
  version, the settings, skeletons (bone names, parents), clips (name, fps, loop,
  events, bone names), and the streams and uniques as nested controller trees
  ``{"kind": "clip" | "blend2" | "mask" | "layer" | "blend_space_2d" |
  "state_machine", ...}``;
- ``<stem>.npz``, the *arrays*: ``numpy.savez`` (read with ``allow_pickle=False``)
  holding bind poses, inverse binds, clip keys, agent arrays and per-bone weight
  arrays. The manifest names it by relative file name and records its SHA-256, and
  refers to each array as ``{"array": key, "dtype": name, "shape": [...]}``; the key
  is the manifest field path (``"clips[2].keys"``).

The manifest is :mod:`.config_codec`'s (controller trees through :mod:`.codec`'s
registry of kinds, the show and looks through :mod:`.show_codec`); this module
writes and reads the files.

Writes are atomic: both files are written to temporary names in the target
directory, then renamed (arrays first, manifest last); on any error the temporaries
are removed and the previous files are untouched. A manifest whose array file was
replaced by another save (a crash between the two renames) fails its checksum.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile

import numpy as np

from ..base.errors import CrowdError
from ..base.files import file_mode, npz_bytes
from .codec import Decoder, LocatedError
from .config import CrowdConfig
from .config_codec import FORMAT, VERSION, decode_config, encode_config

__all__ = ["save_config", "load_config", "config_digest"]


def _format_json(obj, level=0) -> str:
    """Indented JSON; short flat objects, short lists and lists of numbers stay on one line."""
    pad, inner = "  " * level, "  " * (level + 1)
    if isinstance(obj, dict) and obj:
        flat = json.dumps(obj, ensure_ascii=False, allow_nan=False)
        if len(flat) <= 100 and not any(isinstance(v, dict) and v for v in obj.values()):
            return flat
        body = ",\n".join(f"{inner}{json.dumps(k, ensure_ascii=False)}: "
                          f"{_format_json(v, level + 1)}" for k, v in obj.items())
        return "{\n" + body + "\n" + pad + "}"
    if isinstance(obj, list) and obj:
        flat = json.dumps(obj, ensure_ascii=False, allow_nan=False)
        nested = any(isinstance(v, (dict, list)) and v for v in obj)
        if not nested and (len(flat) <= 100 or not any(isinstance(v, str) for v in obj)):
            return flat
        body = ",\n".join(inner + _format_json(v, level + 1) for v in obj)
        return "[\n" + body + "\n" + pad + "]"
    return json.dumps(obj, ensure_ascii=False, allow_nan=False)


# ------------------------------------------------------------------------ files
def _paths(path) -> tuple:
    path = os.fspath(path)
    root, ext = os.path.splitext(path)
    if ext.lower() == ".npz" or not os.path.basename(root):
        raise CrowdError(f"{path}: the manifest needs a name like 'crowd.json'")
    return path, root + ".npz"


def _sha256(path) -> tuple:
    h, size = hashlib.sha256(), 0
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
            size += len(block)
    return h.hexdigest(), size


def config_digest(config: CrowdConfig) -> str:
    """SHA-256 (hex) of ``config`` as :func:`save_config` encodes it: the manifest
    (keys sorted) and every array's name, dtype, shape and bytes. Equal for equal
    configurations in any process (a snapshot names the crowd it belongs to by it)."""
    manifest, arrays = encode_config(config)
    h = hashlib.sha256(json.dumps(manifest, sort_keys=True).encode("utf-8"))
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"\n{name} {a.dtype.str} {a.shape}\n".encode("utf-8"))
        h.update(a.tobytes())
    return h.hexdigest()


def save_config(config: CrowdConfig, path) -> None:
    """Write ``config`` to ``path`` (the ``.json`` manifest) and ``<stem>.npz``.

    Atomic: both files are written under temporary names in the same directory and
    renamed into place (arrays first); on error the temporaries are removed, the
    previous files stay as they were and the error is raised (OSError as CrowdError).
    """
    path, npz_path = _paths(path)
    try:
        manifest, arrays = encode_config(config)
    except LocatedError as e:
        raise CrowdError(f"{path}: {e}") from None
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise CrowdError(f"{path}: directory {directory} does not exist")
    tmp = []
    try:
        fd, tmp_npz = tempfile.mkstemp(prefix=f".{os.path.basename(npz_path)}.",
                                       suffix=".tmp", dir=directory)
        tmp.append(tmp_npz)
        data = npz_bytes(arrays)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        digest, size = _sha256(tmp_npz)
        manifest["arrays"] = {"uri": os.path.basename(npz_path), "sha256": digest,
                              "bytes": size}
        fd, tmp_json = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp",
                                        dir=directory)
        tmp.append(tmp_json)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(_format_json(manifest) + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp_npz, file_mode(npz_path))
        os.chmod(tmp_json, file_mode(path))
        os.replace(tmp_npz, npz_path)
        tmp.remove(tmp_npz)
        os.replace(tmp_json, path)
        tmp.remove(tmp_json)
    except OSError as e:
        raise CrowdError(f"{path}: cannot write the crowd configuration: {e}") from e
    finally:
        for t in tmp:
            try:
                os.unlink(t)
            except OSError:
                pass


def _reject_constant(name):
    raise ValueError(f"{name} is not allowed")


def load_config(path) -> CrowdConfig:
    """Read a configuration written by :func:`save_config` (or by hand, see
    docs/config_format.md). Every problem raises CrowdError naming file and field."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            manifest = json.load(f, parse_constant=_reject_constant)
    except FileNotFoundError:
        raise CrowdError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise CrowdError(f"{path}: cannot read the manifest: {e}") from None
    except RecursionError:
        raise CrowdError(f"{path}: cannot read the manifest: JSON nested too deeply") \
            from None
    dec = Decoder(path)
    if not isinstance(manifest, dict):
        raise CrowdError(f"{path}: the manifest must be a JSON object")
    fmt = dec.get(manifest, "format", "str")
    if fmt != FORMAT:
        raise dec.at("format").error(f"not a crowd configuration ({fmt!r}, expected "
                                     f"{FORMAT!r})")
    version = dec.get(manifest, "version", "str")
    major = version.split(".")[0]
    if not major.isdigit() or int(major) != VERSION[0]:
        raise dec.at("version").error(f"unsupported version {version!r} (this reader reads "
                                      f"{VERSION[0]}.x)")
    arrays = dec.get(manifest, "arrays", "object")
    ad = dec.at("arrays")
    uri = ad.get(arrays, "uri", "str")
    if os.path.isabs(uri) or os.path.dirname(os.path.normpath(uri)) or uri in ("", ".", ".."):
        raise ad.at("uri").error(f"must name a file beside the manifest, got {uri!r}")
    npz_path = os.path.join(os.path.dirname(path), uri)
    if not os.path.isfile(npz_path):
        raise ad.at("uri").error(f"array file {npz_path} does not exist")
    digest = ad.get(arrays, "sha256", "str", None)
    if digest is not None and _sha256(npz_path)[0] != digest.lower():
        raise ad.at("sha256").error(f"{npz_path} does not match the manifest's checksum "
                                    "(written by another save, or damaged)")
    try:
        npz = np.load(npz_path, allow_pickle=False)
        if not hasattr(npz, "files"):
            raise ValueError("not an .npz archive")
    except Exception as e:  # noqa: BLE001 - any unreadable archive
        raise CrowdError(f"{npz_path}: cannot read the arrays: {e}") from None
    with npz:
        dec = Decoder(path, npz, npz_path)
        try:
            return decode_config(manifest, dec)
        except LocatedError as e:
            raise CrowdError(str(e)) from None
