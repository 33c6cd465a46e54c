"""The shot's layout: shared offset animations, agents, and agents' own animations.

::

    def Xform "Crowd"                                   (defaultPrim)
        def Scope "Streams"                   (in the main layer)
            def Scope "<stream>"
                def SkelAnimation "offset_<O>"   references streams/<stream> with
                                                 layer offset +O (paper's (SI, O))
        def Scope "Agents"                    (in the sublayer layout.<ext>; the
                                              transforms of the agents that move are
                                              time-sampled on overs in the main layer)
            def SkelRoot "agent_<id>" (instanceable, SkelBindingAPI,
                                       references characters/<body>: its skeleton,
                                       mesh variant and props)
                rel skel:animationSource -> an offset animation, or
                                            /Crowd/AgentAnimations/agent_<id>
                xformOp:translate (position), xformOp:rotateZ (heading, degrees),
                xformOp:scale (uniform: the agent's body scale; only when not 1)
                primvars:crowdPalette<c> (constant: the agent's palette colours,
                                          read by the character's palette materials)
                primvars:displayColor (constant: the agent's colour, inherited
                                       by the character's mesh)
                primvars:crowdTint_<look> (constant: each grey or white look's
                                           colour tinted by the agent's, read by
                                           that look's material)
                (the blender layout: not instanceable, and the three kinds of
                primvars are on an over of each of the character's meshes instead,
                one-element arrays, which Blender's USD importer reads)
        def Scope "AgentAnimations"   (in the sublayer agents.<ext>: per agent that
                                       is not static, a SkelAnimation whose value
                                       clips read streams, uniques and blends)

A layer offset ``+O`` maps stage time ``F`` to the stream layer's time ``F - O``: the
stream head ``O`` frames ago, which is what an agent at offset ``O`` shows. Agents
with the same ``(stream, offset)`` share one offset animation, so there are at most
``streams x M`` of them, never one per agent.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Vt

from ..core.meshes.mesh import tinted
from .character import palette_primvar
from .layers import apply_api, attribute, define, relationship

__all__ = ["ROOT", "author_offset_animations", "author_agents", "author_agent_animations",
           "author_moves", "agent_names"]

ROOT = "Crowd"
_T = Sdf.ValueTypeNames
_ORDER = Vt.TokenArray(["xformOp:translate", "xformOp:rotateZ"])
_SCALED = Vt.TokenArray(["xformOp:translate", "xformOp:rotateZ", "xformOp:scale"])
#: agent prims authored per step of the export
_LAYOUT_CHUNK = 4096


def agent_names(ids) -> list:
    """Prim names ``agent_<id>``, zero-padded to the widest id."""
    ids = np.asarray(ids, np.int64)
    width = len(str(int(ids.max()))) if ids.size else 1
    return [f"agent_{i:0{width}d}" for i in ids.tolist()]


def author_offset_animations(root: Sdf.PrimSpec, shot, stream_names, stream_assets) -> dict:
    """One SkelAnimation per ``(stream, offset)`` played by a static agent.

    Returns ``{key: Sdf.Path}`` by the agents' ``(stream, offset)`` key (``Shot.keys``).
    """
    m = shot.max_offset
    keys = np.unique(shot.keys[shot.static])
    streams = define(root, "Streams", "Scope")
    paths, scope = {}, None
    for key in keys.tolist():
        s, o = divmod(key, m)
        if scope is None or scope.name != stream_names[s]:
            scope = define(streams, stream_names[s], "Scope")
        prim = define(scope, f"offset_{o}", "SkelAnimation")
        prim.referenceList.Prepend(Sdf.Reference(stream_assets[s],
                                                 layerOffset=Sdf.LayerOffset(o, 1.0)))
        paths[key] = prim.path
    return paths


def author_agents(root: Sdf.PrimSpec, shot, names, character_assets, sources,
                  meshes_of=None, tints=None):
    """The agent prims: a generator yielding ``("layout", done, total)`` after each
    batch of agents.

    Parameters
    ----------
    root : the ``/Crowd`` prim spec.
    shot : the :class:`~.shot.Shot`.
    names : prim name per exported agent.
    character_assets : asset path per body index (``shot.agent_body``).
    sources : ``skel:animationSource`` target (Sdf.Path) per exported agent.
    meshes_of : None: the agent prims are instanceable and carry their colour
        primvars, which the character's meshes inherit. Else, per body index, the
        names of the character's Mesh prims: the agents are not instanceable and each
        of their meshes carries the primvars as one-element arrays, the only constant
        primvars Blender's USD importer reads (as point attributes, which the Attribute
        nodes it makes of the materials' primvar readers then find).
    tints : per body index, the looks agents' colours tint
        (:func:`~.character.tinted_looks`: ``[(primvar, colour)]``): each agent gets
        the look's colour tinted by its own (:func:`~crowd_addon.core.meshes.mesh.tinted`).
    """
    with Sdf.ChangeBlock():
        parent = define(root, "Agents", "Scope")
    refs = {k: Sdf.Reference(a) for k, a in character_assets.items()}
    degrees = np.degrees(shot.heading.astype(np.float64)).tolist()
    has = (shot.palette >= 0).all(2)                     # (n, 4): palette colours set
    agents = list(zip(names, shot.agent_body.tolist(), sources, shot.position.tolist(),
                      degrees, shot.color.tolist(), shot.scale.tolist(), has.tolist(),
                      shot.palette.tolist(), _tinted(shot, tints or {})))
    for a in range(0, len(agents), _LAYOUT_CHUNK):
        with Sdf.ChangeBlock():
            for name, body, source, position, heading, color, scale, has_c, pal, tint in \
                    agents[a:a + _LAYOUT_CHUNK]:
                prim = define(parent, name, "SkelRoot")
                prim.instanceable = meshes_of is None
                prim.referenceList.Prepend(refs[body])
                apply_api(prim, "SkelBindingAPI")
                relationship(prim, "skel:animationSource", source)
                attribute(prim, "xformOp:translate", _T.Float3, Gf.Vec3f(*position))
                attribute(prim, "xformOp:rotateZ", _T.Double, heading)
                if scale != 1.0:
                    attribute(prim, "xformOp:scale", _T.Float3, Gf.Vec3f(scale, scale, scale))
                attribute(prim, "xformOpOrder", _T.TokenArray,
                          _ORDER if scale == 1.0 else _SCALED, uniform=True)
                colours = [("displayColor", color)]
                colours += [(palette_primvar(c), pal[c]) for c, on in enumerate(has_c) if on]
                colours += tint
                if meshes_of is None:
                    _author_colours(prim, colours, _T.Color3f, Gf.Vec3f)
                else:
                    for mesh in meshes_of[body]:
                        _author_colours(Sdf.PrimSpec(prim, mesh, Sdf.SpecifierOver),
                                        colours, _T.Color3fArray, _one_colour)
        yield "layout", min(a + _LAYOUT_CHUNK, len(agents)), len(agents)


def _author_colours(prim, colours, value_type, value):
    """The primvars ``colours`` (``[(name, (r, g, b))]``) on ``prim``, constant:
    their interpolation is not authored (UsdGeom's fallback; one metadata call fewer
    a primvar of 65k agents). displayColor is an array whatever ``value_type``."""
    for name, rgb in colours:
        if name == "displayColor":
            attribute(prim, "primvars:displayColor", _T.Color3fArray, _one_colour(rgb))
        else:
            attribute(prim, f"primvars:{name}", value_type, value(*rgb))


def _one_colour(*rgb):
    return Vt.Vec3fArray([Gf.Vec3f(*rgb)])


def _tinted(shot, tints) -> list:
    """Per exported agent, ``[(primvar, (r, g, b))]``: each look its body's colours
    tint (``tints``), tinted by the agent's colour; computed per body at once."""
    out = [()] * shot.agent_body.size
    for body, looks in tints.items():
        ids = np.flatnonzero(shot.agent_body == body)
        if not looks or not ids.size:
            continue
        colours = [tinted(rgb, shot.color[ids]).tolist() for _, rgb in looks]
        for i, agent in enumerate(ids.tolist()):
            out[agent] = [(p, c[i]) for (p, _), c in zip(looks, colours)]
    return out


def author_moves(root: Sdf.PrimSpec, shot, names) -> None:
    """The transforms of the agents that move, time-sampled at each shot frame, on an
    ``over`` of each under ``root`` (the main layer's ``/Crowd``): stronger than the
    layout's values, and where a stitch reads them (without opening the layout)."""
    moving = np.flatnonzero(shot.moving)
    if not moving.size:
        return
    parent = Sdf.PrimSpec(root, "Agents", Sdf.SpecifierOver)
    layer = root.layer
    pos, head = shot.agent_transforms(moving)
    degrees = np.degrees(head.astype(np.float64))
    frames = [float(f) for f in shot.frames]
    for j, i in enumerate(moving.tolist()):
        prim = Sdf.PrimSpec(parent, names[i], Sdf.SpecifierOver)
        t_path = attribute(prim, "xformOp:translate", _T.Float3).path
        r_path = attribute(prim, "xformOp:rotateZ", _T.Double).path
        for k, f in enumerate(frames):
            layer.SetTimeSample(t_path, f, Gf.Vec3f(*pos[k, j].tolist()))
            layer.SetTimeSample(r_path, f, float(degrees[k, j]))


def author_agent_animations(layer: Sdf.Layer, shot, names, joints_of, clips):
    """Each non-static agent's ``SkelAnimation`` under ``/Crowd/AgentAnimations`` in
    ``layer``: its joints and its value clips (``clips``, an iterable of one dictionary
    per such agent, :func:`~.clips.clip_sets`), no poses of its own. A generator yielding ``("agent
    animations", done, total)`` after each batch and returning their paths (in agent
    order)."""
    own = np.flatnonzero(~shot.static)
    with Sdf.ChangeBlock():
        crowd = Sdf.PrimSpec(layer, ROOT, Sdf.SpecifierOver)
        parent = define(crowd, "AgentAnimations", "Scope")
    paths = []
    clips = iter(clips)
    for a in range(0, own.size, _LAYOUT_CHUNK):
        with Sdf.ChangeBlock():
            for i in own[a:a + _LAYOUT_CHUNK].tolist():
                prim = define(parent, names[i], "SkelAnimation")
                attribute(prim, "joints", _T.TokenArray,
                          joints_of[int(shot.agent_skeleton[i])], uniform=True)
                prim.SetInfo("clips", next(clips))
                paths.append(prim.path)
        yield "agent animations", min(a + _LAYOUT_CHUNK, own.size), own.size
    return paths
