"""Recording -> UsdSkel export (docs/usd_export.md): the entry point.

:func:`export_crowd` writes a :class:`~crowd_addon.core.shots.recording.Recording` (a shot
simulated once by :func:`crowd_addon.core.shots.recorder.record`; nothing here runs a
crowd) as::

    shot.usdc                         offset animations, the transforms of agents that
                                      move; the shot's settings (main layer)
    shot.layers/vN/layout.usdc        the agents (sublayer of the main layer)
    shot.layers/vN/characters/*.usdc  one SkelRoot + Skeleton + Mesh per body (a character,
                                      or its mesh variant and props)
    shot.layers/vN/streams/*.usdc     one baked SkelAnimation per stream used
    shot.layers/vN/agents.usdc        own animations of agents that are not static
                                      (sublayer of the main layer; only if any)

An *animation-only* export (``animation_only=True``, a chunk of a shot after its first,
docs/snapshots.md) writes no layout, characters or offset animations: only what a
stitch reads from such a chunk (streams, uniques, blend banks, the agents' own
animations, the moving agents' transforms and the per-agent arrays). It is not a stage
to look at on its own.

:func:`export_steps` is the same export one unit of work per ``next()`` (a stream
layer, a batch of agents' own animations, the layout...), for a caller that must stay
responsive (one step stays well under a second at 65,000 agents); closing it early
cancels the export. :func:`check_export` checks a
configuration, an output and an agent count before a shot is recorded.

All or nothing: see :mod:`.files`.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
from pxr import Sdf, Vt

from ..core.meshes.bodies import crowd_bodies, prop_names
from ..core.authoring.config import USD_LAYOUTS, validate_config
from ..core.authoring.config_io import config_digest
from ..core.base.errors import CrowdError
from ..core.shots.recorder import check_frames
from ..core.shots.recording import Recording
from ..core.variety.repetition import RepetitionSettings, recording_repetition_steps
from .agents import (ROOT, agent_names, author_agent_animations, author_moves,
                     author_offset_animations, layout_layer)
from .animation import author_animation
from .character import character_layer, joint_tokens, tinted_looks
from .clips import PRIM, bank_layer, bank_layout, clip_sets, manifest_layer
from .files import ExportFiles
from .layers import new_layer
from .naming import unique_identifiers
from .shot import AIM, STREAM, UNIQUE, Shot

__all__ = ["export_crowd", "export_steps", "check_export", "check_layout", "ExportResult",
           "FORMAT_VERSION", "LAYOUTS"]

FORMAT_VERSION = "1.1"
LAYOUTS = USD_LAYOUTS
#: the lightest LOD of a character with at least this many triangles is written as its
#: proxy (``purpose = "proxy"``, what usdview draws); the far cards are too crude
PROXY_MIN_TRIANGLES = 32


def check_layout(layout) -> str:
    if layout not in LAYOUTS:
        raise CrowdError(f"export: layout must be one of {', '.join(LAYOUTS)}, got "
                         f"{layout!r}")
    return layout


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote.

    Attributes
    ----------
    path : the main layer (absolute path); layers_dir : its folder of layers.
    files : dict, file (relative to the main layer's directory) -> bytes.
    frames : (first, last) shot frames.
    agents : agents exported; shared_agents : those on a shared offset animation;
        clip_agents : those that change what they play, on value clips (none is baked
        over the whole shot); blend_frames : the frames in the banks (their blends,
        and their aim frames), the only
        poses written per agent; moving_agents : those whose transform is
        time-sampled.
    offset_animations, stream_animations, characters : prims/layers written
        (``characters``: character layers, one per body).
    seconds : dict ``simulate`` (the recording's), ``author``, ``write``, ``total``
        (wall clock).
    substeps : samples written per frame (the recording's).
    events : ``[name, frame, agents]`` per event tag fired for exported agents in the
        shot, in firing order (what the crowd's callbacks heard).
    started_from : the frame of the snapshot the simulation started from (``--snapshots``;
        None: it ran from the crowd's start frame); snapshot : the snapshot file the
        export left at its last frame (None without a snapshot folder).
    look_agents : exported agents that look at something in the shot (each on value
        clips); aim_frames : their looking frames (of blend_frames), each its own pose.
    repetition : the exported agents' repetition metric over the shot
        (:meth:`~crowd_addon.core.variety.repetition.Repetition.as_dict`; None when not
        measured).
    """

    path: str
    layers_dir: str
    files: dict
    frames: tuple
    agents: int
    shared_agents: int
    clip_agents: int
    blend_frames: int
    moving_agents: int
    offset_animations: int
    stream_animations: int
    characters: int
    seconds: dict
    events: list
    substeps: int = 1
    started_from: int | None = None
    snapshot: str | None = None
    repetition: dict | None = None
    look_agents: int = 0
    aim_frames: int = 0

    @property
    def bytes(self) -> int:
        return int(sum(self.files.values()))


def export_crowd(recording, path, agents=None, progress=None, layout="instanced",
                 camera=None, repetition=RepetitionSettings(),
                 animation_only=False, before_commit=None) -> ExportResult:
    """Write ``recording`` to UsdSkel in one call (:func:`export_steps` to the end).

    Parameters
    ----------
    recording : a :class:`~crowd_addon.core.shots.recording.Recording`.
    path : main layer, ``.usdc``/``.usd`` (binary) or ``.usda`` (text).
    agents : None (all) or N, the first N agents (ids ``0 .. N-1``); more than the
        recording has is an error.
    progress : optional ``progress(stage, done, total)``: ``characters``, ``streams``,
        ``uniques``, ``blends``, ``agent animations``, ``layout`` (not with
        ``animation_only``).
    layout : ``"instanced"`` (default: agents are instanceable, so renderers share
        each character's prototype) or ``"blender"`` (agents are not instanceable:
        Blender's USD importer animates them only then; and their colour primvars are
        authored on each of their meshes, where that importer reads them);
        :data:`LAYOUTS`.
    camera : the :class:`~crowd_addon.core.base.camera.Camera` the repetition metric is
        measured from (default: one framing the exported agents).
    repetition : :class:`~crowd_addon.core.variety.repetition.RepetitionSettings` of the
        metric (stage ``repetition``, one step a frame measured), or None to skip it.
    animation_only : write only what a stitch reads from a chunk after the shot's
        first (no layout, characters or offset animations; see the module's notes).
    before_commit : optional callable, called once everything is written and only
        the commit is left (usd/files.py: the renames that put the export in place);
        an exception from it stops the export as below (``crowd demo`` puts its
        stage in place only when its frames are done).

    Raises
    ------
    CrowdError naming the thing at fault; nothing is written then, and a previous
    export at ``path`` is left as it was. An exception raised by ``progress`` stops
    the export the same way.
    """
    steps = export_steps(recording, path, agents, layout, camera, repetition, animation_only,
                         before_commit)
    try:
        while True:
            try:
                report = next(steps)
            except StopIteration as stop:
                return stop.value
            if progress is not None:
                progress(*report)
    finally:
        steps.close()


def export_steps(recording, path, agents=None, layout="instanced", camera=None,
                 repetition=RepetitionSettings(), animation_only=False, before_commit=None):
    """The export of :func:`export_crowd` as a generator yielding ``(stage, done,
    total)`` after each unit of work and returning the :class:`ExportResult`
    (``StopIteration.value``), ``before_commit`` as there. The recording, ``path``,
    ``agents`` and ``layout`` are checked when it is called (CrowdError). Closed before it is done, it removes its
    temporary files: nothing is written, a previous export is left as it was."""
    if not isinstance(recording, Recording):
        raise CrowdError(f"export: expected a Recording (crowd_addon.core.shots.recording), got "
                         f"{type(recording).__name__}")
    check_layout(layout)
    ids = _agent_ids(agents, recording.agent_count)
    meshes = _bodies(recording.config, recording.agent_skeleton, ids)
    # an animation-only chunk is not measured: the stitched shot takes the repetition
    # metric of the chunks that were (the first)
    measure = None if repetition is None or animation_only else recording_repetition_steps(
        recording, _view_projection(recording, ids, camera, repetition), agents=ids,
        settings=repetition)
    return _steps(recording, ids, meshes, ExportFiles(path), layout, measure,
                  bool(animation_only), before_commit)


def _view_projection(rec, ids, camera, settings) -> np.ndarray:
    """The repetition metric's camera: ``camera``'s, or one framing the agents ``ids``
    at the settings' aspect."""
    from ..core.base.camera import frame_positions
    if camera is None:
        camera = frame_positions(rec.position[ids], settings.width / settings.height)
    return camera.view_projection


def check_export(config, path, agents=None, layout="instanced", frames=None) -> None:
    """Check, before recording ``config``'s shot, what :func:`export_steps` would
    refuse: the output (extension, folder, writable), the agent count, the layout and
    a proxy mesh for every exported agent's character; with ``frames`` (first, last),
    that they start at or after the crowd's start frame, as the recording needs.
    ``config`` None (a .blend's, known only once baked): the output and the layout
    only. Raises CrowdError."""
    check_layout(layout)
    if config is not None:
        validate_config(config)
    with ExportFiles(path):
        pass
    if config is None:
        return
    if frames is not None:
        check_frames(*frames, config.start_frame)
    ids = _agent_ids(agents, config.agent_count)
    names = list(config.skeletons)
    st = np.asarray(config.agent_stream, np.int64)
    un = np.asarray(config.agent_unique, np.int64)
    of_stream = np.array([names.index(d.skeleton) for d in config.streams] + [0], np.int64)
    of_unique = np.array([names.index(d.skeleton) for d in config.uniques] + [0], np.int64)
    _bodies(config, np.where(st >= 0, of_stream[st], of_unique[un]), ids)


def _steps(rec, ids, meshes, files, layout, measure, animation_only, before_commit):
    t0 = time.perf_counter()
    out = _Output(files)
    with files:
        shot = Shot(rec, ids)
        if animation_only:
            joints_of, char_assets, tints, meshes_of = _joints(rec, meshes), {}, {}, {}
        else:
            joints_of, char_assets, tints, meshes_of = _write_characters(out, rec, meshes)
            yield "characters", len(meshes), len(meshes)
        stream_names, stream_assets = yield from _write_streams(out, rec, shot, joints_of)
        clip_assets = yield from _write_clip_layers(out, rec, shot, joints_of, stream_names,
                                                    stream_assets)
        names = agent_names(ids)
        own_paths = yield from _write_own_animations(out, shot, names, joints_of, clip_assets)
        measured = None if measure is None else (yield from _staged("repetition", measure))
        if not animation_only:          # an animation-only chunk has no layout
            yield "layout", 0, ids.size
        layer = new_layer(files.format, rec.fps, rec.first, rec.last, default_prim=ROOT,
                          comment="crowd shot written by crowd_addon.usd")
        layer.customLayerData = {"crowd": _settings(rec, shot, layout, measured, stream_assets,
                                                    animation_only)}
        if own_paths:
            layer.subLayerPaths.append(files.asset_path("agents"))
        offsets = {}
        with Sdf.ChangeBlock():
            root = Sdf.PrimSpec(layer, ROOT, Sdf.SpecifierDef, "Xform")
            if not animation_only:
                offsets = author_offset_animations(root, shot, stream_names, stream_assets)
            author_moves(root, shot, names)
        if not animation_only:
            agents = yield from layout_layer(
                shot, names, char_assets, _sources(shot, offsets, own_paths), files.format,
                rec.fps, meshes_of=meshes_of if layout == "blender" else None, tints=tints)
            out.save(agents, "layout")
            layer.subLayerPaths.append(files.asset_path("layout"))
        out.save(layer)
        if before_commit is not None:
            before_commit()
        files.commit()
    author = time.perf_counter() - t0 - out.write
    seconds = {"simulate": rec.seconds, "author": author, "write": out.write,
               "total": rec.seconds + author + out.write}
    return ExportResult(
        path=files.path, layers_dir=files.layers_dir, files=dict(files.written),
        frames=(rec.first, rec.last), agents=int(ids.size),
        shared_agents=int(shot.static.sum()), clip_agents=int((~shot.static).sum()),
        blend_frames=int(sum(b.frames for b in clip_assets[1])),
        moving_agents=int(shot.moving.sum()), offset_animations=len(offsets),
        stream_animations=len(stream_assets), characters=len(char_assets),
        seconds=seconds, events=_events(rec, ids), substeps=int(rec.substeps),
        repetition=None if measured is None else measured.as_dict(),
        look_agents=int(shot.looking.sum()),
        aim_frames=int((shot.pieces.end - shot.pieces.start)[shot.pieces.kind == AIM].sum()))


def _staged(stage, steps):
    """Yield ``(stage, done, total)`` for each ``(done, total)`` of the generator
    ``steps``; returns what it returns."""
    while True:
        try:
            done, total = next(steps)
        except StopIteration as stop:
            return stop.value
        yield stage, done, total


def _events(rec, ids) -> list:
    out = []
    for name, frame, agents in rec.events:
        n = int(np.isin(agents, ids).sum())
        if n:
            out.append([str(name), int(frame), n])
    return out


class _Output:
    """The export's files and the time spent writing them."""

    def __init__(self, files):
        self.files, self.write = files, 0.0

    def save(self, layer, name=None):
        t = time.perf_counter()
        self.files.save(layer, name)
        self.write += time.perf_counter() - t


def _write_characters(out, rec, bodies) -> tuple:
    """One layer per body in ``bodies`` (``{body index: Body}``: its mesh variant's full
    mesh, its lightest LOD as a proxy, and its props), named after the skeleton (plus
    the variant and props, for a body with them), and a copy of each texture their
    looks use (``textures/``, so the export stands on its own on another machine);
    returns ``(joints_of, asset_of, tints_of, meshes_of)`` (``asset_of``: from the
    layout layer), keyed by skeleton index and
    by body index (``tints_of[b]``: the looks agents' colours tint, :func:`tinted_looks`;
    ``meshes_of[b]``: the names of the character's Mesh prims)."""
    cfg = rec.config
    skeleton_names = list(cfg.skeletons)
    ids = sorted(bodies)
    file_names = unique_identifiers([_body_file(cfg, bodies[b]) for b in ids], casefold=True)
    parts = [(cfg.mesh_variants(skeleton_names[bodies[b].skeleton])[bodies[b].variant],
              [cfg.props[skeleton_names[bodies[b].skeleton]][j] for j in bodies[b].prop_ids])
             for b in ids]
    textures = _copy_textures(out.files, [m for levels, props in parts
                                          for m in (levels[0], *(p.mesh for p in props))])
    joints_of, asset_of, tints_of, meshes_of = {}, {}, {}, {}
    for b, name, (levels, props) in zip(ids, file_names, parts):
        k = bodies[b].skeleton
        proxies = [m for m in levels[1:] if m.triangle_count >= PROXY_MIN_TRIANGLES]
        palette = cfg.palette_materials.get(skeleton_names[k], ())
        layer, joints_of[k] = character_layer(
            cfg.skeletons[skeleton_names[k]], levels[0], out.files.format, rec.fps, name,
            textures, proxies[-1] if proxies else None, palette, props, bodies[b].variant)
        out.save(layer, f"characters/{name}")
        asset_of[b] = out.files.layer_path(f"characters/{name}")
        tints_of[b] = tinted_looks([*levels[0].looks, *(look for p in props
                                                         for look in p.mesh.looks)],
                                   palette)
        meshes_of[b] = [c.name for c in layer.GetPrimAtPath(f"/{name}").nameChildren
                        if c.typeName == "Mesh"]
    return joints_of, asset_of, tints_of, meshes_of


def _joints(rec, bodies) -> dict:
    """``{skeleton index: joints}`` of the skeletons of ``bodies``, as their character
    layers name them (an animation-only export writes no character layers)."""
    cfg = rec.config
    skeletons = list(cfg.skeletons.values())
    return {b.skeleton: joint_tokens(skeletons[b.skeleton]) for b in bodies.values()}


def _body_file(cfg, body) -> str:
    """A body's character layer name: its skeleton's, then its mesh variant's (variants
    past the first) and its props' names."""
    skeleton = list(cfg.skeletons)[body.skeleton]
    parts = [skeleton]
    if body.variant:
        parts.append(cfg.mesh_variants(skeleton)[body.variant][0].name)
    return "_".join(parts + prop_names(cfg, skeleton, body.props))


def _write_streams(out, rec, shot, joints_of):
    """One layer per stream an agent plays (a step each); returns ``(prim names of all
    streams, {stream: asset path})``."""
    names = unique_identifiers(rec.stream_names, casefold=True)
    p = shot.pieces
    used = np.union1d(shot.stream[shot.static], p.ref[p.kind == STREAM]).tolist()
    assets = {}
    for j, s in enumerate(used):
        out.save(_stream_layer(rec, shot, s, joints_of[int(rec.stream_skeleton[s])],
                               out.files.format),
                 f"streams/{names[s]}")
        assets[s] = out.files.asset_path(f"streams/{names[s]}")
        yield "streams", j + 1, len(used)
    return names, assets


def _write_clip_layers(out, rec, shot, joints_of, stream_names, stream_assets):
    """What the agents that change read through value clips, besides the streams: a
    layer per unique played (a step each), the blend banks (a step per batch of
    blends) and the clips' manifest. Returns ``({key: asset path relative to the
    agents layer}, [BankLayout])`` (nothing when every agent is static)."""
    if shot.static.all():
        return {}, []
    files, p = out.files, shot.pieces
    assets = {("stream", s): files.layer_path(f"streams/{stream_names[s]}")
              for s in stream_assets}
    uniques = np.unique(p.ref[p.kind == UNIQUE]).tolist()
    names = unique_identifiers(rec.unique_names, casefold=True)
    banks = bank_layout(shot)
    skeleton_names = unique_identifiers(list(rec.config.skeletons), casefold=True)
    for j, u in enumerate(uniques):
        times = rec.times
        layer = new_layer(files.format, rec.fps, times[0], times[-1], default_prim=PRIM,
                          comment=f"crowd unique {rec.unique_names[u]!r}: its pose at "
                                  "each shot frame")
        with Sdf.ChangeBlock():
            prim = Sdf.PrimSpec(layer, PRIM, Sdf.SpecifierDef, "SkelAnimation")
            author_animation(prim, joints_of[int(rec.unique_skeleton[u])],
                             _samples(rec.unique_poses, rec.unique_subposes, u), times)
        out.save(layer, f"uniques/{names[u]}")
        assets["unique", u] = files.layer_path(f"uniques/{names[u]}")
        yield "uniques", j + 1, len(uniques)
    blends, done = sum(b.pieces.size for b in banks), 0
    for bank in banks:
        name = f"blends/{skeleton_names[bank.skeleton]}_{bank.part}"
        writing = bank_layer(shot, bank, joints_of[bank.skeleton], files.format,
                             skeleton_names[bank.skeleton])
        while True:
            try:
                n = next(writing)
            except StopIteration as stop:
                out.save(stop.value, name)
                break
            yield "blends", done + n, blends
        done += bank.pieces.size
        assets[bank.key] = files.layer_path(name)
    out.save(manifest_layer(files.format, rec.fps), "manifest")
    assets["manifest"] = files.layer_path("manifest")
    return assets, banks


def _write_own_animations(out, shot, names, joints_of, clip_assets):
    """The sublayer of the animations of agents that change (none if every agent is
    static), a step per batch of agents; returns their prim paths."""
    if shot.static.all():
        return []
    assets, banks = clip_assets
    layer = new_layer(out.files.format, shot.fps, shot.first, shot.last,
                      comment="animations of agents that change: value clips")
    paths = yield from author_agent_animations(layer, shot, names, joints_of,
                                               clip_sets(shot, assets, banks))
    out.save(layer, "agents")
    return paths


def _copy_textures(files, meshes) -> dict:
    """Copy every texture of the meshes' looks into ``textures/``; returns look
    texture -> its asset path from a character layer."""
    sources = list(dict.fromkeys(look.texture for m in meshes for look in m.looks
                                 if look.texture and m.uvs is not None))
    stems = [os.path.splitext(os.path.basename(p)) for p in sources]
    names = unique_identifiers([stem for stem, _ in stems], casefold=True)
    out = {}
    for source, name, (_, ext) in zip(sources, names, stems):
        files.copy(os.path.abspath(source), f"textures/{name}{ext.lower()}")
        out[source] = f"../textures/{name}{ext.lower()}"
    return out


def _agent_ids(agents, count) -> np.ndarray:
    if count == 0:
        raise CrowdError("export: the crowd has no agents")
    if agents is None:
        return np.arange(count, dtype=np.int64)
    if isinstance(agents, bool) or not isinstance(agents, (int, np.integer)) or agents < 1:
        raise CrowdError(f"export: agents must be a count >= 1, got {agents!r}")
    if agents > count:
        raise CrowdError(f"export: {agents} agents requested but the crowd has {count}")
    return np.arange(int(agents), dtype=np.int64)


def _bodies(config, agent_skeleton, ids) -> dict:
    """``{body index: Body}`` of the bodies agents ``ids`` use (indices among the
    bodies of all agents, :func:`~crowd_addon.core.meshes.bodies.crowd_bodies`), checked:
    each has a mesh, and the textures its looks name are files."""
    skeleton_names = list(config.skeletons)
    bodies, agent_body = crowd_bodies(config, agent_skeleton)
    used = np.unique(agent_body[ids]).tolist()
    for b in used:
        if not bodies[b].levels:
            raise CrowdError(f"export: skeleton {skeleton_names[bodies[b].skeleton]!r} has "
                             "no proxy mesh (CrowdConfig.add_mesh); its agents cannot be "
                             "drawn")
    for b in used:
        for mesh in bodies[b].levels[:1]:
            for look in mesh.looks:
                if look.texture and not os.path.isfile(look.texture):
                    raise CrowdError(f"export: look {look.name!r} of mesh {mesh.name!r} "
                                     f"uses texture {look.texture!r}, which is not a file")
    return {b: bodies[b] for b in used}


def _samples(whole, sub, i) -> np.ndarray:
    """``(frames * N, B, 10)`` poses of animation ``i``: each frame's pose from
    ``whole`` (frames, count, B, 10), then its sub-frame samples from ``sub`` (frames,
    N - 1, count, B, 10)."""
    if sub is None or sub.shape[1] == 0:
        return whole[:, i]
    both = np.concatenate([whole[:, None, i], sub[:, :, i]], axis=1)
    return both.reshape((-1,) + whole.shape[2:])


def _stream_layer(rec, shot, s, joints, fmt):
    n = rec.substeps
    frames = (rec.stream_frames[:, None] + np.arange(n) / n).reshape(-1)
    name = rec.stream_names[s]
    layer = new_layer(fmt, rec.fps, frames[0], frames[-1], default_prim=PRIM,
                      comment=f"crowd stream {name!r}: the head's pose at each frame")
    events = shot.stream_events(s)
    with Sdf.ChangeBlock():
        prim = Sdf.PrimSpec(layer, PRIM, Sdf.SpecifierDef, "SkelAnimation")
        prim.customData = {"crowd": {
            "stream": name, "streamIndex": int(s),
            "eventNames": Vt.StringArray([n for n, _ in events]),
            "eventFrames": Vt.DoubleArray([float(f) for _, f in events])}}
        author_animation(prim, joints, _samples(rec.stream_poses, rec.stream_subposes, s),
                         frames)
    return layer


def _sources(shot, offsets, own_paths) -> list:
    keys = shot.keys
    own = iter(own_paths)
    return [offsets[int(k)] if st else next(own)
            for k, st in zip(keys.tolist(), shot.static.tolist())]


#: what an export records per agent in its settings (:func:`per_agent_settings`)
PER_AGENT = ("agentStream", "agentOffset", "agentMoves", "agentPosition", "agentHeading")


def per_agent_settings(stream, offset, moves, position, heading) -> dict:
    """The per-agent arrays a crowd export records in its settings (``agentStream``,
    ``agentOffset``: the stream and offset each agent plays the whole shot, -1 where it
    changes; ``agentMoves``: 1 where it moves; ``agentPosition`` (float3) and
    ``agentHeading`` (radians): where it stands at the first frame), what
    :func:`~.stitch.stitch` reads."""
    ints = {k: Vt.IntArray.FromNumpy(np.ascontiguousarray(v, np.int32))
            for k, v in zip(PER_AGENT, (stream, offset, np.asarray(moves, np.int32)))}
    return {**ints,
            "agentPosition": Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(position,
                                                                          np.float32)),
            "agentHeading": Vt.FloatArray.FromNumpy(np.ascontiguousarray(heading,
                                                                         np.float32))}


def _event_settings(rec, written) -> dict:
    """The tags of the written streams, as their layers hold them, in three arrays
    (``eventStream``, ``eventName``, ``eventFrame``): what a stitch joins without
    opening every chunk's stream layers."""
    s, names, frames = rec.stream_events
    keep = np.isin(np.asarray(s, np.int64), np.fromiter(written, np.int64, len(written)))
    return {"eventStream": Vt.IntArray.FromNumpy(np.ascontiguousarray(s[keep], np.int32)),
            "eventName": Vt.StringArray([str(n) for n in np.asarray(names)[keep]]),
            "eventFrame": Vt.DoubleArray([float(f) for f in np.asarray(frames)[keep]])}


def _settings(rec, shot, layout, measured=None, stream_assets=None,
              animation_only=False) -> dict:
    cfg = rec.config
    seen = {} if measured is None or measured.value is None else {
        "repetition": float(measured.value), "repetitionK": measured.settings.k}
    return {**seen, "M": int(rec.max_offset), "NT": int(cfg.transition_slots), "fps": float(rec.fps),
            "seed": int(cfg.seed), "streams": len(rec.stream_names),
            "uniques": len(rec.unique_names), "agents": int(shot.agents.size),
            "firstFrame": int(rec.first), "lastFrame": int(rec.last),
            "writer": "crowd_addon.usd", "version": FORMAT_VERSION, "layout": layout,
            "substeps": int(rec.substeps), "configDigest": config_digest(cfg),
            "animationOnly": bool(animation_only),
            # each stream's layer (asset path from the main layer; "": not written)
            "streamLayers": Vt.StringArray([(stream_assets or {}).get(s, "")
                                            for s in range(len(rec.stream_names))]),
            **_event_settings(rec, stream_assets or {}),
            **per_agent_settings(shot.stream, shot.offset, shot.moving, shot.position,
                                 shot.heading)}
