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

Controllers serialise through a registry keyed by kind: :func:`register_kind`
adds ``kind -> (class, to_dict, from_dict)``, so a new controller kind brings its
own codec and the reader's core never changes. ``to_dict(node, enc)`` returns the
node's fields (without ``"kind"``) using :class:`Encoder` for children and arrays;
``from_dict(d, dec)`` rebuilds it using :class:`Decoder`, which type-checks fields
and names the file and field path in every error.

Writes are atomic: both files are written to temporary names in the target
directory, then renamed (arrays first, manifest last); on any error the temporaries
are removed and the previous files are untouched. A manifest whose array file was
replaced by another save (a crash between the two renames) fails its checksum.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..base import pose as sqt
from ..anim.clip import Clip
from .config import MAX_TREE_DEPTH, PALETTE_COLUMNS, WHEN_FULL, AnimationDef, CrowdConfig
from ..anim.controllers import (Blend2, BlendMask, BlendSpace2D, ClipPlayer, Layer,
                                StateMachine, StateTransition)
from ..base.errors import CrowdError
from ..base.files import file_mode
from ..meshes.bodies import Prop
from ..meshes.mesh import Look, ProxyMesh
from .show import Action, Cue, Reaction, Show, Sweep, Track
from ..base.skeleton import Skeleton

__all__ = ["FORMAT", "VERSION", "save_config", "load_config", "config_digest", "register_kind",
           "unregister_kind", "controller_kinds", "ControllerKind", "Encoder", "Decoder"]

FORMAT = "crowd_addon.config"
VERSION = (1, 4)            # (major, minor): readers accept any minor of their major
_REQUIRED = object()


def _join(path: str, key) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


class _LocatedError(CrowdError):
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
            p = _join(p, k)
        return Encoder(self.arrays, p)

    def error(self, msg) -> CrowdError:
        return _LocatedError(f"{self.path}: {msg}" if self.path else msg)

    def controller(self, node, *keys) -> dict:
        enc = self.at(*keys)
        kind = _BY_CLASS.get(type(node))
        if kind is None:
            raise enc.error(f"controller type {type(node).__name__} has no registered kind "
                            "(config_io.register_kind)")
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


_TYPES = {
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
            p = _join(p, k)
        return Decoder(self.file, self.npz, self.npz_file, p, self.skeleton, self.depth)

    def error(self, msg, file=None) -> CrowdError:
        where = f"{file or self.file}: {self.path}" if self.path else f"{file or self.file}"
        return _LocatedError(f"{where}: {msg}")

    def get(self, d: dict, key: str, kind: str, default=_REQUIRED, nullable=False):
        """``d[key]`` checked to be of ``kind`` (see ``_TYPES``); ``default`` if absent."""
        if not isinstance(d, dict):
            raise self.error("must be an object")
        if key not in d:
            if default is _REQUIRED:
                raise self.error(f"missing field {key!r}")
            return default
        v = d[key]
        if v is None and nullable:
            return None
        check, what = _TYPES[kind]
        if not check(v):
            raise self.at(key).error(f"must be {what}, got {json.dumps(v)[:60]}")
        return v

    def items(self, d: dict, key: str, kind: str, default=_REQUIRED) -> list:
        """A list field whose every item is of ``kind``."""
        values = self.get(d, key, "list", default)
        check, what = _TYPES[kind]
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
                if not _TYPES["number"][0](w):
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
    except _LocatedError:
        raise
    except (CrowdError, TypeError, ValueError, KeyError) as e:
        raise dec.error(str(e) if isinstance(e, CrowdError) else f"{type(e).__name__}: {e}") \
            from None
    if not isinstance(node, entry.cls):
        raise dec.error(f"from_dict of kind {kind!r} returned {type(node).__name__}")
    return node


# ---------------------------------------------------------------- built-in kinds
def _clip_to(n, enc):
    return {"clip": n.clip, "speed": n.speed, "start": n.start}


def _clip_from(d, dec):
    return ClipPlayer(dec.get(d, "clip", "str"), dec.get(d, "speed", "number", 1.0),
                      dec.get(d, "start", "number", 0.0))


def _blend2_to(n, enc):
    return {"a": enc.controller(n.a, "a"), "b": enc.controller(n.b, "b"), "weight": n.weight}


def _blend2_from(d, dec):
    return Blend2(dec.controller(d, "a"), dec.controller(d, "b"),
                  dec.get(d, "weight", "weight", 0.5))


def _mask_to(n, enc):
    return {"children": [enc.controller(c, "children", i) for i, c in enumerate(n.children())],
            "masks": [enc.bone_weights(m, "masks", i) for i, m in enumerate(n.masks)]}


def _mask_from(d, dec):
    masks = [dec.at("masks", i).weights(v) for i, v in enumerate(dec.get(d, "masks", "list"))]
    if any(m is None for m in masks):
        raise dec.at("masks").error("a mask cannot be null")
    return BlendMask(dec.controllers(d, "children"), masks)


def _layer_to(n, enc):
    ref = None if n.reference is None else {"clip": n.reference[0], "frame": n.reference[1]}
    return {"base": enc.controller(n.base, "base"), "layer": enc.controller(n.layer, "layer"),
            "mode": n.mode, "bone_weights": enc.bone_weights(n.bone_weights, "bone_weights"),
            "weight": n.weight, "reference": ref}


def _layer_from(d, dec):
    ref = dec.get(d, "reference", "object", None, nullable=True)
    if ref is not None:
        r = dec.at("reference")
        ref = (r.get(ref, "clip", "str"), r.get(ref, "frame", "number"))
    return Layer(dec.controller(d, "base"), dec.controller(d, "layer"),
                 dec.get(d, "mode", "str", "override"), dec.bone_weights(d, "bone_weights"),
                 dec.get(d, "weight", "weight", 1.0), ref)


def _space_to(n, enc):
    return {"children": [enc.controller(c, "children", i) for i, c in enumerate(n.children())],
            "points": n.points.tolist(), "x": n.x, "y": n.y}


def _space_from(d, dec):
    points = dec.items(d, "points", "list")
    for i, p in enumerate(points):
        if len(p) != 2 or not all(_TYPES["number"][0](v) for v in p):
            raise dec.at("points", i).error("a point must be [x, y] numbers")
    return BlendSpace2D(dec.controllers(d, "children"), np.array(points, np.float64).reshape(-1, 2),
                        dec.get(d, "x", "weight", "x"), dec.get(d, "y", "weight", "y"))


def _sm_to(n, enc):
    states = [{"name": s, "controller": enc.controller(c, "states", i, "controller")}
              for i, (s, c) in enumerate(zip(n.state_names, n.states))]
    trans = [{"source": t.source, "target": t.target, "duration": t.duration,
              "trigger": t.trigger,
              "condition": None if t.condition is None else
              {"parameter": t.condition[0], "op": t.condition[1], "value": t.condition[2]}}
             for t in n.transitions]
    return {"states": states, "initial": n.initial, "transitions": trans}


def _sm_from(d, dec):
    states = {}
    for i, s in enumerate(dec.items(d, "states", "object")):
        sd = dec.at("states", i)
        name = sd.get(s, "name", "name")
        if name in states:
            raise sd.at("name").error(f"duplicate state {name!r}")
        states[name] = sd.controller(s, "controller")
    trans = []
    for i, t in enumerate(dec.items(d, "transitions", "object", [])):
        td = dec.at("transitions", i)
        cond = td.get(t, "condition", "object", None, nullable=True)
        if cond is not None:
            cd = td.at("condition")
            cond = (cd.get(cond, "parameter", "str"), cd.get(cond, "op", "str"),
                    cd.get(cond, "value", "number"))
        try:
            trans.append(StateTransition(td.get(t, "source", "str"), td.get(t, "target", "str"),
                                         td.get(t, "duration", "number", 8.0),
                                         td.get(t, "trigger", "str", None, nullable=True), cond))
        except _LocatedError:
            raise
        except CrowdError as e:
            raise td.error(str(e)) from None
    return StateMachine(states, trans, dec.get(d, "initial", "str", None, nullable=True))


for _k, _c, _t, _f in (("clip", ClipPlayer, _clip_to, _clip_from),
                       ("blend2", Blend2, _blend2_to, _blend2_from),
                       ("mask", BlendMask, _mask_to, _mask_from),
                       ("layer", Layer, _layer_to, _layer_from),
                       ("blend_space_2d", BlendSpace2D, _space_to, _space_from),
                       ("state_machine", StateMachine, _sm_to, _sm_from)):
    register_kind(_k, _c, _t, _f)


# ------------------------------------------------------------------ config codec
_SETTINGS = (  # manifest key = CrowdConfig attribute, JSON type, default (None: required)
    ("max_offset", "int", None), ("transition_slots", "int", None), ("fps", "number", None),
    ("seed", "int", 0), ("when_full", "str", "queue"), ("max_texture_size", "int", 16384),
    ("start_frame", "int", 0))
_MESH_ARRAYS = {"positions": ("f", (None, 3)), "normals": ("f", (None, 3)),
                "triangles": ("iu", (None, 3)), "bone_indices": ("iu", (None, None)),
                "bone_weights": ("f", (None, None))}
#: Optional arrays of a mesh level: how it looks (texture coordinates, look per triangle).
_LOOK_ARRAYS = {"uvs": ("f", (None, 3, 2)), "material": ("iu", (None,))}
#: Influence columns a mesh level may store (ProxyMesh: 4, or 8 past four a vertex).
_INFLUENCE_WIDTHS = (4, 8)
_AGENTS = (("stream", "iu", 1), ("unique", "iu", 1), ("offset", "iu", 1),
           ("position", "f", 3), ("heading", "f", 1), ("color", "f", 3))


def _encode_config(cfg: CrowdConfig) -> tuple:
    arrays = {}
    enc = Encoder(arrays)
    m = {"format": FORMAT, "version": f"{VERSION[0]}.{VERSION[1]}",
         "generator": "crowd_addon.core.authoring.config_io",
         "units": {"time": "frames", "length": "metres", "angle": "radians",
                   "quaternion": "w, x, y, z", "sqt": "scale[0:3] rot[3:7] trans[7:10]"},
         "arrays": None,
         "settings": {k: getattr(cfg, k) for k, _, _ in _SETTINGS}, "skeletons": [], "clips": []}
    for pool in ("skeletons", "clips"):
        for i, (key, obj) in enumerate(getattr(cfg, pool).items()):
            if key != obj.name:
                raise enc.at(pool, i).error(f"stored under {key!r} but named {obj.name!r}")
    for i, sk in enumerate(cfg.skeletons.values()):
        e = enc.at("skeletons", i)
        m["skeletons"].append({"name": sk.name, "bone_names": list(sk.bone_names),
                               "parents": [int(p) for p in sk.parents],
                               "bind_pose": e.array(sk.bind_pose, "bind_pose"),
                               "inverse_bind": e.array(sk.inverse_bind, "inverse_bind")})
    for i, c in enumerate(cfg.clips.values()):
        m["clips"].append({"name": c.name, "fps": c.fps, "loop": c.loop,
                           "events": [[n, f] for n, f in c.events],
                           "bone_names": None if c.bone_names is None else list(c.bone_names),
                           "keys": enc.at("clips", i).array(c.keys, "keys")})
    for pool in ("streams", "uniques"):
        m[pool] = [{"name": a.name, "skeleton": a.skeleton,
                    **_timing(a), "root": enc.controller(a.root, pool, i, "root")}
                   for i, a in enumerate(getattr(cfg, pool))]
    m["lod_pixels"] = [float(x) for x in cfg.lod_pixels]
    if cfg.lod_distances is not None:
        m["lod_distances"] = [float(x) for x in cfg.lod_distances]
    m["meshes"] = []
    for i, (skel, levels) in enumerate(cfg.meshes.items()):
        e = enc.at("meshes", i)
        m["meshes"].append({"skeleton": skel, "levels": [
            _encode_level(lv, e.at("levels", j)) for j, lv in enumerate(levels)]})
        if cfg.variants.get(skel):          # files without variants as before
            m["meshes"][-1]["variants"] = [
                [_encode_level(lv, e.at("variants", v, j)) for j, lv in enumerate(lvs)]
                for v, lvs in enumerate(cfg.variants[skel])]
    props = [p for ps in cfg.props.values() for p in ps]
    if props:
        m["props"] = [{"name": p.name, "skeleton": p.skeleton, "bone": p.bone,
                       "mesh": _encode_level(p.mesh, enc.at("props", i, "mesh"))}
                      for i, p in enumerate(props)]
    e = enc.at("agents")
    m["agents"] = {"count": cfg.agent_count}
    for key, _, _ in _AGENTS:
        m["agents"][key] = e.array(getattr(cfg, f"agent_{key}"), key)
    if (cfg.scales != 1).any():              # files without scale variation as before
        m["agents"]["scale"] = e.array(cfg.scales, "scale")
    if (cfg.palette >= 0).any():             # ... and without palettes
        m["agents"]["palette"] = e.array(cfg.palette, "palette")
        m["palette_materials"] = {k: list(v) for k, v in cfg.palette_materials.items()}
    if (cfg.variant_ids != 0).any():         # ... and without mesh variants or props
        m["agents"]["variant"] = e.array(cfg.variant_ids, "variant")
    if (cfg.prop_masks != 0).any():
        m["agents"]["props"] = e.array(cfg.prop_masks, "props")
    m["show"] = _encode_show(cfg.show, enc.at("show"))
    if cfg.look_rigs or cfg.look_targets:    # files without looks as before
        m["look"] = _encode_look(cfg, enc.at("look"))
    return _plain(m, ""), arrays


def _encode_level(lv, e) -> dict:
    """A mesh level (ProxyMesh) as the file holds it."""
    return {"name": lv.name, **{k: e.array(getattr(lv, k), k)
                                for k in (*_MESH_ARRAYS, *_LOOK_ARRAYS)
                                if getattr(lv, k) is not None},
            "looks": [{"name": k.name, "color": list(k.color), "texture": k.texture}
                      for k in lv.looks]}


def _skeleton_of(entry, d, cfg) -> str:
    """The ``skeleton`` an entry read at ``d`` names, one of ``cfg``'s."""
    skel = d.get(entry, "skeleton", "str")
    if skel not in cfg.skeletons:
        raise d.at("skeleton").error(f"unknown skeleton {skel!r} "
                                     f"(known: {sorted(cfg.skeletons)})")
    return skel


def _decode_level(lv, dl, skel, cfg):
    """The ProxyMesh of a mesh level of skeleton ``skel`` read at ``dl``."""
    arrays = {k: dl.array(lv, k, kinds, shape) for k, (kinds, shape) in _MESH_ARRAYS.items()}
    for k in ("bone_indices", "bone_weights"):
        if arrays[k].shape[1] not in _INFLUENCE_WIDTHS:
            raise dl.at(k).error(f"array {lv[k]['array']!r} has shape {arrays[k].shape}, "
                                 f"expected (*, 4) or (*, 8)", dl.npz_file)
    for k, (kinds, shape) in _LOOK_ARRAYS.items():
        if lv.get(k) is not None:
            arrays[k] = dl.array(lv, k, kinds, shape)
    looks = []
    for n, look in enumerate(dl.items(lv, "looks", "object", [])):
        dk = dl.at("looks", n)
        try:
            looks.append(Look(dk.get(look, "name", "name"),
                              tuple(dk.items(look, "color", "number")),
                              dk.get(look, "texture", "str", "")))
        except CrowdError as e:
            raise dk.error(str(e)) from None
    try:
        return ProxyMesh(dl.get(lv, "name", "name"), skel,
                         bone_count=cfg.skeletons[skel].bone_count, looks=tuple(looks),
                         **arrays)
    except CrowdError as e:
        raise dl.error(str(e)) from None


# ------------------------------------------------------------------------- show
_ACTION = (("kind", "str", None), ("target", "str", None), ("duration", "number", 8.0),
           ("hold", "int", 0), ("name", "str", ""), ("value", "number", 0.0),
           ("trigger", "str", ""), ("release", "str", ""))
#: action fields left out of a file while empty, so files without them hash the same
_OPTIONAL_ACTION = ("trigger", "release")
_SWEEP = (("mode", "str", "angle"), ("speed", "number", None),
          ("start_angle", "number", 0.0), ("laps", "int", 1))
_CUE = (("frame", "int", None), ("spread", "int", 0), ("seed", "int", 0),
        ("interrupt", "bool", False), ("muted", "bool", False), ("timeline", "bool", True))
_REACTION = (("event", "name", None), ("cue", "name", None), ("source", "str", ""),
             ("radius", "number", 0.0), ("muted", "bool", False))


def _encode_show(show: Show, enc) -> dict:
    cues = []
    for i, c in enumerate(show.cues):
        a = c.action
        cues.append({"name": c.name, **{k: getattr(c, k) for k, _, _ in _CUE},
                     "action": {**{k: getattr(a, k) for k, _, _ in _ACTION
                                   if getattr(a, k) or k not in _OPTIONAL_ACTION},
                                "offset": a.offset, "when_full": a.when_full},
                     "agents": None if c.agents is None else
                     enc.at("cues", i).array(c.agents, "agents"),
                     "sweep": None if c.sweep is None else
                     {"centre": list(c.sweep.centre), **{k: getattr(c.sweep, k)
                                                         for k, _, _ in _SWEEP}}})
    return {"cues": cues,
            "reactions": [{"name": r.name, **{k: getattr(r, k) for k, _, _ in _REACTION}}
                          for r in show.reactions],
            "tracks": [{"target": t.target, "name": t.name, "kind": t.kind, "first": t.first,
                        "values": enc.at("tracks", i).array(t.values, "values")}
                       for i, t in enumerate(show.tracks)]}


def _fields(d, obj, spec) -> dict:
    return {k: d.get(obj, k, kind, _REQUIRED if default is None else default)
            for k, kind, default in spec}


def _built(d, make):
    try:
        return make()
    except CrowdError as e:
        raise d.error(str(e)) from None


def _decode_show(m: dict, dec) -> Show:
    show = dec.get(m, "show", "object", None)
    if show is None:                       # files before 1.2 have no show
        return Show()
    dec = dec.at("show")
    cues = []
    for i, c in enumerate(dec.items(show, "cues", "object", [])):
        d = dec.at("cues", i)
        da = d.at("action")
        raw = d.get(c, "action", "object")
        action = _fields(da, raw, _ACTION)
        offset = raw.get("offset", "keep")
        if offset not in ("keep", "random") and not _TYPES["int"][0](offset):
            raise da.at("offset").error(f"must be 'keep', 'random' or an offset, got "
                                        f"{json.dumps(offset)[:60]}")
        action = _built(da, lambda: Action(offset=offset, when_full=da.get(
            raw, "when_full", "str", None, nullable=True), **action))
        agents = d.array(c, "agents", "iu", (None,)) if c.get("agents") is not None else None
        sweep = None
        if c.get("sweep") is not None:
            ds, raw_sweep = d.at("sweep"), d.get(c, "sweep", "object")
            centre = ds.items(raw_sweep, "centre", "number")
            sweep = _built(ds, lambda: Sweep(centre, **_fields(ds, raw_sweep, _SWEEP)))
        name = d.get(c, "name", "name")
        cues.append(_built(d, lambda: Cue(name, action=action, agents=agents, sweep=sweep,
                                          **_fields(d, c, _CUE))))
    reactions = []
    for i, r in enumerate(dec.items(show, "reactions", "object", [])):
        d = dec.at("reactions", i)
        name = d.get(r, "name", "name")
        reactions.append(_built(d, lambda: Reaction(name, **_fields(d, r, _REACTION))))
    tracks = []
    for i, t in enumerate(dec.items(show, "tracks", "object", [])):
        d = dec.at("tracks", i)
        fields = _fields(d, t, (("target", "name", None), ("name", "name", None),
                                ("kind", "str", "parameter"), ("first", "int", None)))
        values = d.array(t, "values", "f", (None,))
        tracks.append(_built(d, lambda: Track(values=values, **fields)))
    return _built(dec, lambda: Show(tuple(cues), tuple(reactions), tuple(tracks)))


# ------------------------------------------------------------------------- look
_LOOK_RIG = (("yaw_limit", "number", None), ("pitch_limit", "number", None))


def _encode_look(cfg, enc) -> dict:
    return {"lag": cfg.look_lag, "max_lag": int(cfg.look_max_lag),
            "rigs": {sk: {"bones": list(r.bones), "shares": list(r.shares),
                          "yaw_limit": r.yaw_limit, "pitch_limit": r.pitch_limit,
                          "forward": list(r.forward)} for sk, r in cfg.look_rigs.items()},
            "targets": [{"name": t.name, "first": t.first, "smoothing": t.smoothing,
                         "positions": enc.at("targets", i).array(t.positions, "positions")}
                        for i, t in enumerate(cfg.look_targets.values())]}


def _decode_look(m: dict, dec, cfg):
    from ..runtime.look_at import LookRig, LookTarget
    look = dec.get(m, "look", "object", None)
    if look is None:                       # files without looks
        return
    dec = dec.at("look")
    cfg.look_lag = dec.get(look, "lag", "str", "offset")
    cfg.look_max_lag = dec.get(look, "max_lag", "int", 12)
    rigs = dec.get(look, "rigs", "object", {})
    for sk in rigs:
        d, r = dec.at("rigs", sk), dec.at("rigs").get(rigs, sk, "object")
        bones, shares = d.items(r, "bones", "name"), d.items(r, "shares", "number")
        forward = d.items(r, "forward", "number")
        cfg.look_rigs[sk] = _built(d, lambda: LookRig(tuple(bones), tuple(shares),
                                                       forward=tuple(forward),
                                                       **_fields(d, r, _LOOK_RIG)))
    for i, t in enumerate(dec.items(look, "targets", "object", [])):
        d = dec.at("targets", i)
        fields = _fields(d, t, (("name", "name", None), ("first", "int", None),
                                ("smoothing", "number", 4.0)))
        positions = d.array(t, "positions", "f", (None, 3))
        if fields["name"] in cfg.look_targets:
            raise d.at("name").error(f"two look targets are named {fields['name']!r}")
        cfg.look_targets[fields["name"]] = _built(
            d, lambda: LookTarget(positions=positions, **fields))


def _plain(obj, path):
    """A pure-JSON copy of ``obj`` (numpy scalars converted; NaN/inf and others refused)."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, np.integer)) and not isinstance(obj, np.bool_):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (float, np.floating)):
        if not np.isfinite(obj):
            raise CrowdError(f"{path}: cannot save the non-finite number {obj}")
        return float(obj)
    if isinstance(obj, dict):
        return {str(k): _plain(v, _join(path, str(k))) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v, _join(path, i)) for i, v in enumerate(obj)]
    raise CrowdError(f"{path}: cannot save a value of type {type(obj).__name__}: {obj!r:.60}")


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


def _decode_config(m: dict, dec: Decoder) -> CrowdConfig:
    cfg = CrowdConfig()
    sd = dec.at("settings")
    settings = dec.get(m, "settings", "object")
    for key, kind, default in _SETTINGS:
        setattr(cfg, key, sd.get(settings, key, kind, _REQUIRED if default is None else default))
    if cfg.when_full not in WHEN_FULL:
        raise sd.at("when_full").error(f"must be one of {WHEN_FULL}, got {cfg.when_full!r}")
    for i, s in enumerate(dec.items(m, "skeletons", "object")):
        d = dec.at("skeletons", i)
        name = d.get(s, "name", "name")
        names = d.items(s, "bone_names", "name")
        parents = d.items(s, "parents", "int")
        b = len(names)
        bind = d.array(s, "bind_pose", "f", (b, sqt.WIDTH))
        inv = d.array(s, "inverse_bind", "f", (b, 4, 4))
        if name in cfg.skeletons:
            raise d.at("name").error(f"duplicate skeleton name {name!r}")
        cfg.skeletons[name] = _exact_skeleton(d, name, names, parents, bind, inv)
    for i, c in enumerate(dec.items(m, "clips", "object")):
        d = dec.at("clips", i)
        name = d.get(c, "name", "name")
        bones = d.items(c, "bone_names", "name", None) if c.get("bone_names") is not None \
            else None
        keys = d.array(c, "keys", "f", (None, None if bones is None else len(bones), sqt.WIDTH))
        events = []
        for j, ev in enumerate(d.items(c, "events", "list", [])):
            if len(ev) != 2 or not isinstance(ev[0], str) or not _TYPES["number"][0](ev[1]):
                raise d.at("events", j).error("an event must be [name, frame]")
            events.append((ev[0], ev[1]))
        if name in cfg.clips:
            raise d.at("name").error(f"duplicate clip name {name!r}")
        cfg.clips[name] = _exact_clip(d, name, keys, d.get(c, "fps", "number"),
                                      d.get(c, "loop", "bool"), events, bones)
    for pool in ("streams", "uniques"):
        out = getattr(cfg, pool)
        for i, a in enumerate(dec.items(m, pool, "object")):
            d = dec.at(pool, i)
            skel = d.get(a, "skeleton", "str")
            if skel not in cfg.skeletons:
                raise d.at("skeleton").error(f"unknown skeleton {skel!r} "
                                             f"(known: {sorted(cfg.skeletons)})")
            d.skeleton = cfg.skeletons[skel]
            name = d.get(a, "name", "name")
            speed, phase = d.get(a, "speed", "number", 1.0), d.get(a, "phase", "number", 0.0)
            template = d.get(a, "template", "str", "")
            if pool == "uniques" and ((speed, phase) != (1.0, 0.0) or template):
                raise d.error("uniques keep their own clocks: speed, phase and template "
                              "are for streams")
            try:
                out.append(AnimationDef(name, skel, d.controller(a, "root"), speed, phase,
                                        template))
            except CrowdError as e:
                raise d.error(str(e)) from None
    from ..meshes.lod import check_lod_distances, check_lod_pixels
    for key, check in (("lod_pixels", check_lod_pixels), ("lod_distances", check_lod_distances)):
        if key in m:
            try:
                setattr(cfg, key, check(dec.items(m, key, "number", [])))
            except CrowdError as e:
                raise dec.at(key).error(str(e).split(": ", 1)[1]) from None
    mesh_of = {}
    for i, mesh in enumerate(dec.items(m, "meshes", "object", [])):
        d = dec.at("meshes", i)
        skel = _skeleton_of(mesh, d, cfg)
        if skel in mesh_of:
            raise d.at("skeleton").error(f"a second mesh for skeleton {skel!r} (the first is "
                                         f"meshes[{mesh_of[skel]}]); give each skeleton one "
                                         "mesh with its LOD levels")
        mesh_of[skel] = i
        levels = [_decode_level(lv, d.at("levels", j), skel, cfg)
                  for j, lv in enumerate(d.items(mesh, "levels", "object"))]
        if not levels:
            raise d.at("levels").error("a mesh needs at least one level")
        cfg.meshes[skel] = levels
        for v, lvs in enumerate(d.items(mesh, "variants", "list", [])):
            dv = d.at("variants", v)
            if not lvs:
                raise dv.error("a mesh variant needs at least one level")
            for j, lv in enumerate(lvs):
                if not isinstance(lv, dict):
                    raise dv.at(j).error(f"must be an object, got {json.dumps(lv)[:60]}")
            cfg.variants.setdefault(skel, []).append(
                [_decode_level(lv, dv.at(j), skel, cfg) for j, lv in enumerate(lvs)])
    for i, prop in enumerate(dec.items(m, "props", "object", [])):
        d = dec.at("props", i)
        skel = _skeleton_of(prop, d, cfg)
        try:
            cfg.add_prop(Prop(d.get(prop, "name", "name"), skel, d.get(prop, "bone", "int"),
                              _decode_level(d.get(prop, "mesh", "object"), d.at("mesh"), skel,
                                            cfg)))
        except CrowdError as e:
            raise d.error(str(e)) from None
    agents = dec.get(m, "agents", "object")
    d = dec.at("agents")
    n = d.get(agents, "count", "int")
    for key, kinds, width in _AGENTS:
        setattr(cfg, f"agent_{key}",
                d.array(agents, key, kinds, (n,) if width == 1 else (n, width)))
    if agents.get("scale") is not None:
        cfg.agent_scale = d.array(agents, "scale", "f", (n,))
    if agents.get("palette") is not None:
        cfg.agent_palette = d.array(agents, "palette", "f", (n, PALETTE_COLUMNS, 3))
        mats = dec.get(m, "palette_materials", "object", {})
        cfg.palette_materials = {k: tuple(dec.at("palette_materials").items(mats, k, "str"))
                                 for k in mats}
    if agents.get("variant") is not None:
        cfg.agent_variant = d.array(agents, "variant", "iu", (n,)).astype(np.int16)
    if agents.get("props") is not None:
        cfg.agent_props = d.array(agents, "props", "iu", (n,)).astype(np.uint8)
    cfg.show = _decode_show(m, dec)
    _decode_look(m, dec, cfg)
    return cfg


def _exact_skeleton(d, name, names, parents, bind, inv):
    """Build through the constructor (which validates; unit float32 quaternions are
    kept bit for bit), naming the field on error."""
    try:
        return Skeleton(name, names, parents, bind, inv)
    except CrowdError as e:
        raise d.error(str(e)) from None


def _timing(a) -> dict:
    """A stream's speed and phase, written only when they are not the defaults (files
    of streams without timing variation read and hash as before)."""
    return {**({"speed": a.speed} if a.speed != 1.0 else {}),
            **({"phase": a.phase} if a.phase != 0.0 else {}),
            **({"template": a.template} if a.template else {})}


def _exact_clip(d, name, keys, fps, loop, events, bones):
    try:
        return Clip(name, keys, fps, loop, tuple(events), bones)
    except CrowdError as e:
        raise d.error(str(e)) from None


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
    manifest, arrays = _encode_config(config)
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
        manifest, arrays = _encode_config(config)
    except _LocatedError as e:
        raise CrowdError(f"{path}: {e}") from None
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise CrowdError(f"{path}: directory {directory} does not exist")
    tmp = []
    try:
        fd, tmp_npz = tempfile.mkstemp(prefix=f".{os.path.basename(npz_path)}.",
                                       suffix=".tmp", dir=directory)
        tmp.append(tmp_npz)
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
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
            return _decode_config(manifest, dec)
        except _LocatedError as e:
            raise CrowdError(str(e)) from None
