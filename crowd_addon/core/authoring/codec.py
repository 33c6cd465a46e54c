"""The manifest's field codec: :class:`Encoder` and :class:`Decoder`, and the registry
of controller kinds they write and read controller trees through (docs/config_format.md).

Controllers serialise through a registry keyed by kind: :func:`register_kind`
adds ``kind -> (class, to_dict, from_dict)``, so a new controller kind brings its
own codec and the reader's core never changes. ``to_dict(node, enc)`` returns the
node's fields (without ``"kind"``) using :class:`Encoder` for children and arrays;
``from_dict(d, dec)`` rebuilds it using :class:`Decoder`, which type-checks fields
(:data:`TYPES`) and names the file and field path in every error
(:class:`LocatedError`). The built-in kinds are :mod:`.controller_codec`'s.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..base.errors import CrowdError
from .config import MAX_TREE_DEPTH

__all__ = ["REQUIRED", "MAX_INT", "MAX_NUMBER", "TYPES", "LocatedError", "join",
           "register_kind", "unregister_kind", "controller_kinds", "ControllerKind", "Encoder",
           "Decoder"]

REQUIRED = object()


def join(path: str, key) -> str:
    """The field path of ``key`` (a name, or an index of a list) under ``path``."""
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


class LocatedError(CrowdError):
    """A CrowdError whose message already names the file and field."""


# ------------------------------------------------------------------------ registry
@dataclass(frozen=True)
class ControllerKind:
    """A controller kind's codec: ``to_dict(node, enc) -> dict``, ``from_dict(d, dec)``."""

    kind: str
    cls: type
    to_dict: Callable
    from_dict: Callable


_KINDS: dict = {}
_BY_CLASS: dict = {}


def register_kind(kind: str, cls: type, to_dict: Callable, from_dict: Callable, *,
                  replace: bool = False) -> None:
    """Register how controllers of class ``cls`` are written as ``{"kind": kind, ...}``.

    The class is matched exactly (a subclass needs its own kind). ``replace`` allows
    redefining an existing kind or class.
    """
    if not isinstance(kind, str) or not kind:
        raise CrowdError(f"controller kind must be a non-empty string, got {kind!r}")
    if not replace and (kind in _KINDS or cls in _BY_CLASS):
        raise CrowdError(f"controller kind {kind!r} / class {cls.__name__} is already "
                         "registered (pass replace=True)")
    old = _KINDS.get(kind)
    if old is not None:
        _BY_CLASS.pop(old.cls, None)
    _KINDS.pop(_BY_CLASS.pop(cls, None), None)
    _KINDS[kind] = ControllerKind(kind, cls, to_dict, from_dict)
    _BY_CLASS[cls] = kind


def unregister_kind(kind: str) -> None:
    entry = _KINDS.pop(kind, None)
    if entry is not None:
        _BY_CLASS.pop(entry.cls, None)


def controller_kinds() -> dict:
    """The registered kinds, ``kind -> ControllerKind``."""
    return dict(_KINDS)


# ------------------------------------------------------------------------- encoder
class Encoder:
    """Writes one field path of the manifest; arrays go to the shared ``.npz`` dict."""

    def __init__(self, arrays: dict, path: str = ""):
        self.arrays, self.path = arrays, path

    def at(self, *keys) -> "Encoder":
        p = self.path
        for k in keys:
            p = join(p, k)
        return Encoder(self.arrays, p)

    def error(self, msg) -> CrowdError:
        return LocatedError(f"{self.path}: {msg}" if self.path else msg)

    def controller(self, node, *keys) -> dict:
        enc = self.at(*keys)
        kind = _BY_CLASS.get(type(node))
        if kind is None:
            raise enc.error(f"controller type {type(node).__name__} has no registered kind "
                            "(codec.register_kind)")
        body = _KINDS[kind].to_dict(node, enc)
        if "kind" in body:
            raise enc.error(f"to_dict of kind {kind!r} must not set 'kind'")
        return {"kind": kind, **body}

    def array(self, value, *keys) -> dict:
        """Store ``value`` (dtype kept) in the ``.npz``; returns the manifest reference."""
        enc = self.at(*keys)
        a = np.ascontiguousarray(value)
        if a.dtype.kind not in "biuf":
            raise enc.error(f"cannot save an array of dtype {a.dtype}")
        if a.dtype.kind == "f" and a.size:
            with np.errstate(invalid="ignore"):
                huge = np.isfinite(a) & (np.abs(a) > MAX_NUMBER)
            if huge.any():
                raise enc.error(f"cannot save {float(a[huge][0]):g}: values must be at most "
                                f"{MAX_NUMBER:g} in magnitude (no reader would load them)")
        self.arrays[enc.path] = a
        return {"array": enc.path, "dtype": a.dtype.name, "shape": list(a.shape)}

    def bone_weights(self, spec, *keys):
        """None -> null; dict bone name -> weight -> ``{"bones": {...}}``; else an array."""
        if spec is None:
            return None
        if isinstance(spec, dict):
            return {"bones": {str(k): v for k, v in spec.items()}}
        return self.array(spec, *keys)


# ------------------------------------------------------------------------- decoder
#: Bounds of every number read from a file: integers (sizes, frames, indices, seeds)
#: below 2**31 in magnitude, other numbers finite and at most 1e9 (times, speeds,
#: weights, fps), so nothing downstream overflows or allocates without end.
MAX_INT, MAX_NUMBER = 2**31 - 1, 1e9


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and abs(v) <= MAX_INT


def _is_number(v) -> bool:
    return (isinstance(v, (int, float)) and not isinstance(v, bool)
            and math.isfinite(v) and abs(v) <= MAX_NUMBER)


TYPES = {
    "str": (lambda v: isinstance(v, str), "a string"),
    "name": (lambda v: isinstance(v, str) and bool(v.strip()), "a non-empty name"),
    "int": (_is_int, f"an integer of magnitude at most {MAX_INT}"),
    "number": (_is_number, "a finite number of magnitude at most 1e9"),
    "bool": (lambda v: isinstance(v, bool), "true or false"),
    "list": (lambda v: isinstance(v, list), "a list"),
    "object": (lambda v: isinstance(v, dict), "an object"),
    "weight": (lambda v: isinstance(v, str) or _is_number(v),
               "a finite number (magnitude at most 1e9) or a parameter name"),
}


class Decoder:
    """Reads one field path of the manifest; errors name the file and the path.

    ``skeleton`` is the Skeleton of the animation being read (None outside one), so
    per-bone arrays can be checked against its bone count.
    """

    def __init__(self, file: str, npz=None, npz_file: str = "", path: str = "",
                 skeleton=None, depth: int = 0):
        self.file, self.npz, self.npz_file = file, npz, npz_file
        self.path, self.skeleton, self.depth = path, skeleton, depth

    def at(self, *keys) -> "Decoder":
        p = self.path
        for k in keys:
            p = join(p, k)
        return Decoder(self.file, self.npz, self.npz_file, p, self.skeleton, self.depth)

    def error(self, msg, file=None) -> CrowdError:
        where = f"{file or self.file}: {self.path}" if self.path else f"{file or self.file}"
        return LocatedError(f"{where}: {msg}")

    def get(self, d: dict, key: str, kind: str, default=REQUIRED, nullable=False):
        """``d[key]`` checked to be of ``kind`` (see ``TYPES``); ``default`` if absent."""
        if not isinstance(d, dict):
            raise self.error("must be an object")
        if key not in d:
            if default is REQUIRED:
                raise self.error(f"missing field {key!r}")
            return default
        v = d[key]
        if v is None and nullable:
            return None
        check, what = TYPES[kind]
        if not check(v):
            raise self.at(key).error(f"must be {what}, got {json.dumps(v)[:60]}")
        return v

    def items(self, d: dict, key: str, kind: str, default=REQUIRED) -> list:
        """A list field whose every item is of ``kind``."""
        values = self.get(d, key, "list", default)
        check, what = TYPES[kind]
        for i, v in enumerate(values):
            if not check(v):
                raise self.at(key, i).error(f"must be {what}, got {json.dumps(v)[:60]}")
        return values

    def controller(self, d: dict, key, *more):
        """The controller at ``d[key]`` (or ``d[key][more...]`` for list items)."""
        value = self.get(d, key, "list" if more else "object")
        dec = self.at(key)
        for k in more:
            if not 0 <= k < len(value):
                raise dec.error(f"missing item {k}")
            value, dec = value[k], dec.at(k)
        dec.depth = self.depth + 1
        if dec.depth > MAX_TREE_DEPTH:
            raise dec.error(f"controllers nested deeper than {MAX_TREE_DEPTH} levels")
        return _decode_controller(value, dec)

    def controllers(self, d: dict, key) -> list:
        return [self.controller(d, key, i) for i in range(len(self.get(d, key, "list")))]

    def array(self, d: dict, key: str, kinds: str = "f", shape=None) -> np.ndarray:
        """The ``.npz`` array referenced by ``d[key]``; ``kinds`` are allowed dtype kinds,
        ``shape`` the expected shape (``None`` entries match anything)."""
        ref, dec = self.get(d, key, "object"), self.at(key)
        return dec._resolve(ref, kinds, shape)

    def _resolve(self, ref, kinds, shape):
        name = self.get(ref, "array", "str")
        dtype = self.get(ref, "dtype", "str")
        want = self.items(ref, "shape", "int")
        if name not in self.npz.files:
            raise self.error(f"array {name!r} is missing", self.npz_file)
        try:
            a = self.npz[name]
        except Exception as e:  # noqa: BLE001 - e.g. an object array (pickle refused)
            raise self.error(f"array {name!r} cannot be read: {e}", self.npz_file) from None
        if a.dtype.name != dtype or list(a.shape) != want:
            raise self.error(f"array {name!r} is {a.dtype.name} {tuple(a.shape)}, the manifest "
                             f"says {dtype} {tuple(want)}", self.npz_file)
        if a.dtype.kind not in kinds:
            raise self.error(f"array {name!r} has dtype {a.dtype.name}, expected "
                             f"{'an integer' if kinds == 'iu' else 'a float'} dtype",
                             self.npz_file)
        if shape is not None and (a.ndim != len(shape) or any(
                s is not None and s != n for s, n in zip(shape, a.shape))):
            expected = tuple("*" if s is None else s for s in shape)
            raise self.error(f"array {name!r} has shape {tuple(a.shape)}, expected "
                             f"{expected}".replace("'*'", "*"), self.npz_file)
        if a.dtype.kind == "f" and a.size:      # NaN and inf: named by their owners
            with np.errstate(invalid="ignore"):
                bad = np.isfinite(a) & (np.abs(a) > MAX_NUMBER)
            if bad.any():
                at = tuple(int(i) for i in np.argwhere(bad)[0])
                raise self.error(f"array {name!r} holds {float(a[at]):g} at {list(at)}: "
                                 f"values must be at most {MAX_NUMBER:g} in magnitude",
                                 self.npz_file)
        return a

    def bone_weights(self, d: dict, key: str):
        """Inverse of :meth:`Encoder.bone_weights` for the optional field ``d[key]``."""
        self.get(d, key, "object", None, nullable=True)
        return self.at(key).weights(d.get(key))

    def weights(self, spec):
        """``None``, ``{"bones": {name: weight}}`` -> dict, or an array reference -> (B,)."""
        if spec is None:
            return None
        if not isinstance(spec, dict):
            raise self.error('must be null, {"bones": {...}} or an array reference')
        if "bones" in spec:
            bones = self.get(spec, "bones", "object")
            for name, w in bones.items():
                if not TYPES["number"][0](w):
                    raise self.at("bones", name).error("bone weight must be a number")
            return dict(bones)
        bones = None if self.skeleton is None else self.skeleton.bone_count
        return self._resolve(spec, "fiu", (bones,))


def _decode_controller(d, dec: Decoder):
    if not isinstance(d, dict):
        raise dec.error("a controller must be an object")
    kind = dec.get(d, "kind", "str")
    entry = _KINDS.get(kind)
    if entry is None:
        raise dec.error(f"unknown controller kind {kind!r} (known: {sorted(_KINDS)})")
    try:
        node = entry.from_dict(d, dec)
    except LocatedError:
        raise
    except (CrowdError, TypeError, ValueError, KeyError) as e:
        raise dec.error(str(e) if isinstance(e, CrowdError) else f"{type(e).__name__}: {e}") \
            from None
    if not isinstance(node, entry.cls):
        raise dec.error(f"from_dict of kind {kind!r} returned {type(node).__name__}")
    return node
