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
from pxr import Gf, Sdf

from ..core.meshes.mesh import tinted
from .character import palette_primvar
from .layers import attribute, define, layer_from_text
from .references import COMPOSITION_ONLY

__all__ = ["ROOT", "author_offset_animations", "layout_layer", "author_agent_animations",
           "author_moves", "agent_names"]

ROOT = "Crowd"
_T = Sdf.ValueTypeNames
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


def layout_layer(shot, names, character_assets, sources, fmt, fps, meshes_of=None,
                 tints=None):
    """The layout layer: the agent prims. A generator yielding ``("layout", done,
    total)`` after each batch of agents and returning the layer.

    The agents are written as text and read in by USD's own parser in one call:
    authoring 65,000 agents spec by spec through Python costs ~3x more (~70 us an
    agent, docs/performance.md). Every value is written exactly (a float32 as the
    shortest text of its float64 value, which reads back to the same float32).

    Parameters
    ----------
    shot : the :class:`~.shot.Shot`.
    names : prim name per exported agent (identifiers).
    character_assets : asset path per body index (``shot.agent_body``), from the layer.
    sources : ``skel:animationSource`` target (Sdf.Path) per exported agent.
    fmt, fps : the layer's format and frame rate (:func:`~.layers.new_layer`).
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
    instanced = meshes_of is None
    head = {body: (f'            {"instanceable = true" if instanced else "instanceable = false"}'
                   f'\n            prepend apiSchemas = ["SkelBindingAPI"]'
                   f'\n            prepend references = @{asset}@')
            for body, asset in character_assets.items()}
    order = {False: '["xformOp:translate", "xformOp:rotateZ"]',
             True: '["xformOp:translate", "xformOp:rotateZ", "xformOp:scale"]'}
    degrees = np.degrees(shot.heading.astype(np.float64)).tolist()
    has = (shot.palette >= 0).all(2)                     # (n, 4): palette colours set
    agents = list(zip(names, shot.agent_body.tolist(), sources, shot.position.tolist(),
                      degrees, shot.color.tolist(), shot.scale.tolist(), has.tolist(),
                      shot.palette.tolist(), _tinted(shot, tints or {})))
    text = ['#usda 1.0\n\nover "Crowd"\n{\n    def Scope "Agents"\n    {\n']
    for a in range(0, len(agents), _LAYOUT_CHUNK):
        for name, body, source, position, heading, color, scale, has_c, pal, tint in \
                agents[a:a + _LAYOUT_CHUNK]:
            scaled = scale != 1.0
            colours = [("displayColor", color)]
            colours += [(palette_primvar(c), pal[c]) for c, on in enumerate(has_c) if on]
            colours += tint
            text.append(
                f'        def SkelRoot "{name}" (\n{head[body]}\n        )\n        {{\n'
                f'            rel skel:animationSource = <{source}>\n'
                f'            float3 xformOp:translate = {_vec(position)}\n'
                f'            double xformOp:rotateZ = {heading!r}\n'
                + (f'            float3 xformOp:scale = {_vec((scale,) * 3)}\n'
                   if scaled else '')
                + f'            uniform token[] xformOpOrder = {order[scaled]}\n')
            if instanced:
                text += [_colour_line(c, rgb, "            ", c != "displayColor")
                         for c, rgb in colours]
            else:
                lines = "".join(_colour_line(c, rgb, "                ", False)
                                for c, rgb in colours)
                text += [f'            over "{mesh}"\n            {{\n{lines}            }}\n'
                         for mesh in meshes_of[body]]
            text.append('        }\n')
        yield "layout", min(a + _LAYOUT_CHUNK, len(agents)), len(agents)
    text.append('    }\n}\n')
    layer = layer_from_text("".join(text), fmt, fps, shot.first, shot.last,
                            comment="the shot's agents, written by crowd_addon.usd")
    layer.customLayerData = {"crowd": {"writer": "crowd_addon.usd", "part": COMPOSITION_ONLY}}
    return layer


def _vec(xyz) -> str:
    return f"({xyz[0]!r}, {xyz[1]!r}, {xyz[2]!r})"


def _colour_line(name, rgb, indent, single) -> str:
    """A constant colour primvar: ``color3f`` (``single``) or a one-element
    ``color3f[]`` (displayColor is an array whatever the layout)."""
    if single:
        return f"{indent}color3f primvars:{name} = {_vec(rgb)}\n"
    return f"{indent}color3f[] primvars:{name} = [{_vec(rgb)}]\n"


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
