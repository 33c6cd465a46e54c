"""The manifest's ``show`` and ``look`` sections (docs/config_format.md): a
:class:`~.show.Show`'s cues, reactions and tracks, and a configuration's look rigs,
look targets and lag, written with an :class:`~.codec.Encoder` and read back with a
:class:`~.codec.Decoder`.
"""

from __future__ import annotations

import json

from ..base.errors import CrowdError
from .codec import REQUIRED, TYPES
from .show import Action, Cue, Reaction, Show, Sweep, Track

__all__ = ["encode_show", "decode_show", "encode_look", "decode_look"]


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


def encode_show(show: Show, enc) -> dict:
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
    return {k: d.get(obj, k, kind, REQUIRED if default is None else default)
            for k, kind, default in spec}


def _built(d, make):
    try:
        return make()
    except CrowdError as e:
        raise d.error(str(e)) from None


def decode_show(m: dict, dec) -> Show:
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
        if offset not in ("keep", "random") and not TYPES["int"][0](offset):
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


def encode_look(cfg, enc) -> dict:
    return {"lag": cfg.look_lag, "max_lag": int(cfg.look_max_lag),
            "rigs": {sk: {"bones": list(r.bones), "shares": list(r.shares),
                          "yaw_limit": r.yaw_limit, "pitch_limit": r.pitch_limit,
                          "forward": list(r.forward)} for sk, r in cfg.look_rigs.items()},
            "targets": [{"name": t.name, "first": t.first, "smoothing": t.smoothing,
                         "positions": enc.at("targets", i).array(t.positions, "positions")}
                        for i, t in enumerate(cfg.look_targets.values())]}


def decode_look(m: dict, dec, cfg):
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
