"""The manifest of a :class:`~.config.CrowdConfig` (docs/config_format.md):
:func:`encode_config` turns a configuration into the manifest (pure JSON) and its
arrays, :func:`decode_config` reads them back: the settings, skeletons, clips, the
streams' and uniques' controller trees (through :mod:`.codec`'s registry, where this
module registers :mod:`.controller_codec`'s built-in kinds), meshes and their levels,
props, agents, and the show and looks (:mod:`.show_codec`). :data:`FORMAT` and
:data:`VERSION` name the format; the files are :mod:`.config_io`'s.
"""

from __future__ import annotations

import json

import numpy as np

from ..base import pose as sqt
from ..anim.clip import Clip
from ..base.errors import CrowdError
from ..base.skeleton import Skeleton
from ..meshes.bodies import Prop
from ..meshes.mesh import Look, ProxyMesh
from ..runtime.transitions import WHEN_FULL
from .codec import REQUIRED, TYPES, Decoder, Encoder, join, register_kind
from .config import AnimationDef, CrowdConfig
from .config_agents import PALETTE_COLUMNS
from .controller_codec import BUILT_IN_KINDS
from .show_codec import decode_look, decode_show, encode_look, encode_show

__all__ = ["FORMAT", "VERSION", "encode_config", "decode_config"]

FORMAT = "crowd_addon.config"
VERSION = (1, 4)            # (major, minor): readers accept any minor of their major

for _k, _c, _t, _f in BUILT_IN_KINDS:
    register_kind(_k, _c, _t, _f)


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


def encode_config(cfg: CrowdConfig) -> tuple:
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
    m["show"] = encode_show(cfg.show, enc.at("show"))
    if cfg.look_rigs or cfg.look_targets:    # files without looks as before
        m["look"] = encode_look(cfg, enc.at("look"))
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
        return {str(k): _plain(v, join(path, str(k))) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v, join(path, i)) for i, v in enumerate(obj)]
    raise CrowdError(f"{path}: cannot save a value of type {type(obj).__name__}: {obj!r:.60}")


def decode_config(m: dict, dec: Decoder) -> CrowdConfig:
    cfg = CrowdConfig()
    sd = dec.at("settings")
    settings = dec.get(m, "settings", "object")
    for key, kind, default in _SETTINGS:
        setattr(cfg, key, sd.get(settings, key, kind, REQUIRED if default is None else default))
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
            if len(ev) != 2 or not isinstance(ev[0], str) or not TYPES["number"][0](ev[1]):
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
    cfg.show = decode_show(m, dec)
    decode_look(m, dec, cfg)
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
