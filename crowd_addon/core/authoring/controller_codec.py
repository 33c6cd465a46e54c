"""Readers and writers of the built-in controller kinds (docs/config_format.md):
``clip``, ``blend2``, ``mask``, ``layer``, ``blend_space_2d`` and ``state_machine``, a
``to_dict(node, enc)`` and a ``from_dict(d, dec)`` each (:mod:`.codec`).
:data:`BUILT_IN_KINDS` lists them; :mod:`.config_codec` registers them.
"""

from __future__ import annotations

import numpy as np

from ..anim.blends import Blend2, BlendMask, BlendSpace2D, Layer
from ..anim.controllers import ClipPlayer
from ..anim.state_machine import StateMachine, StateTransition
from ..base.errors import CrowdError
from .codec import TYPES, LocatedError

__all__ = ["BUILT_IN_KINDS"]


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
        if len(p) != 2 or not all(TYPES["number"][0](v) for v in p):
            raise dec.at("points", i).error("a point must be [x, y] numbers")
    return BlendSpace2D(dec.controllers(d, "children"),
                        np.array(points, np.float64).reshape(-1, 2),
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
        except LocatedError:
            raise
        except CrowdError as e:
            raise td.error(str(e)) from None
    return StateMachine(states, trans, dec.get(d, "initial", "str", None, nullable=True))


#: The built-in kinds, ``(kind, class, to_dict, from_dict)`` each, as
#: :func:`~.codec.register_kind` takes them.
BUILT_IN_KINDS = (("clip", ClipPlayer, _clip_to, _clip_from),
                  ("blend2", Blend2, _blend2_to, _blend2_from),
                  ("mask", BlendMask, _mask_to, _mask_from),
                  ("layer", Layer, _layer_to, _layer_from),
                  ("blend_space_2d", BlendSpace2D, _space_to, _space_from),
                  ("state_machine", StateMachine, _sm_to, _sm_from))
