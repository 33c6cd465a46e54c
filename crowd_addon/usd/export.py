"""Crowd -> UsdSkel export (docs/usd_export.md): the entry point.

:func:`export_crowd` takes a core :class:`~crowd_addon.core.config.CrowdConfig` (from
``config_io.load_config``, or from a Blender scene converted by ``blender/``) or an
already built :class:`~crowd_addon.core.crowd.Crowd`, runs it over the shot and
writes::

    shot.usdc                      layout: offset animations, agents (main layer)
    shot.layers/characters/*.usdc  one SkelRoot + Skeleton + Mesh per character
    shot.layers/streams/*.usdc     one baked SkelAnimation per stream used
    shot.layers/agents.usdc        own animations of agents that are not static
                                   (sublayer of the main layer; only if any)

All or nothing: see :mod:`.files`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from pxr import Sdf, Vt

from ..core.config import CrowdConfig
from ..core.crowd import Crowd
from ..core.errors import CrowdError
from .agents import (ROOT, agent_names, author_agent_animations, author_agents,
                     author_offset_animations)
from .animation import author_animation
from .character import character_layer
from .files import ExportFiles
from .layers import new_layer
from .naming import unique_identifiers
from .recorder import agent_skeletons, record_shot

__all__ = ["export_crowd", "ExportResult", "FORMAT_VERSION"]

FORMAT_VERSION = "1.0"


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote.

    Attributes
    ----------
    path : the main layer (absolute path); layers_dir : its folder of layers.
    files : dict, file (relative to the main layer's directory) -> bytes.
    frames : (first, last) shot frames.
    agents : agents exported; shared_agents : those on a shared offset animation;
        baked_agents : those with their own animation; moving_agents : those whose
        transform is time-sampled.
    offset_animations, stream_animations, characters : prims/layers written.
    seconds : dict ``simulate``, ``author``, ``write``, ``total`` (wall clock).
    """

    path: str
    layers_dir: str
    files: dict
    frames: tuple
    agents: int
    shared_agents: int
    baked_agents: int
    moving_agents: int
    offset_animations: int
    stream_animations: int
    characters: int
    seconds: dict

    @property
    def bytes(self) -> int:
        return int(sum(self.files.values()))


def export_crowd(source, path, frames, agents=None, on_frame=None,
                 progress=None) -> ExportResult:
    """Export a crowd shot to UsdSkel.

    Parameters
    ----------
    source : CrowdConfig (a Crowd is built from it) or Crowd (advanced in place; reset
        to its start first if it is already past the shot's first frame).
    path : main layer, ``.usdc``/``.usd`` (binary) or ``.usda`` (text).
    frames : ``(first, last)`` integer frames, inclusive,
        ``config.start_frame <= first <= last``.
    agents : None (all) or N, the first N agents (ids ``0 .. N-1``); more than the
        crowd has is an error.
    on_frame : optional ``on_frame(crowd, frame)``, called before each step with the
        frame about to be evaluated (from the crowd's start on): the simulation
        driving the crowd (transitions, triggers, parameters, agent moves).
    progress : optional ``progress(stage, done, total)``.

    Raises
    ------
    CrowdError naming the thing at fault; nothing is written then, and a previous
    export at ``path`` is left as it was.
    """
    t0 = time.perf_counter()
    crowd = _crowd(source)
    first, last = _frame_range(frames, crowd)
    ids = _agent_ids(agents, crowd)
    meshes = _meshes(crowd, ids)
    files = ExportFiles(path)
    with files:
        shot = record_shot(crowd, ids, first, last, on_frame, progress)
        out = _Output(files, progress, time.perf_counter() - t0)
        joints_of, char_assets = _write_characters(out, crowd, meshes)
        stream_names, stream_assets = _write_streams(out, crowd, shot, joints_of)
        names = agent_names(ids)
        own_paths = _write_own_animations(out, shot, names, joints_of)
        layer = new_layer(files.format, crowd.fps, first, last, default_prim=ROOT,
                          comment="crowd shot written by crowd_addon.usd")
        layer.customLayerData = {"crowd": _settings(crowd, shot)}
        if own_paths:
            layer.subLayerPaths.append(files.asset_path("agents"))
        with Sdf.ChangeBlock():
            root = Sdf.PrimSpec(layer, ROOT, Sdf.SpecifierDef, "Xform")
            offsets = author_offset_animations(root, shot, stream_names, stream_assets)
            author_agents(root, shot, names, char_assets, _sources(shot, offsets, own_paths))
        _report(progress, "layout", ids.size, ids.size)
        out.save(layer)
        files.commit()
    total = time.perf_counter() - t0
    seconds = {"simulate": out.simulate, "author": total - out.simulate - out.write,
               "write": out.write, "total": total}
    return ExportResult(
        path=files.path, layers_dir=files.layers_dir, files=dict(files.written),
        frames=(first, last), agents=int(ids.size),
        shared_agents=int(shot.static.sum()), baked_agents=int((~shot.static).sum()),
        moving_agents=int(shot.moving.sum()), offset_animations=len(offsets),
        stream_animations=len(stream_assets), characters=len(char_assets),
        seconds=seconds)


class _Output:
    """The export's files, progress callback and time spent writing files."""

    def __init__(self, files, progress, simulate_seconds):
        self.files, self.progress = files, progress
        self.simulate, self.write = simulate_seconds, 0.0

    def save(self, layer, name=None):
        t = time.perf_counter()
        self.files.save(layer, name)
        self.write += time.perf_counter() - t


def _write_characters(out, crowd, meshes) -> tuple:
    """One layer per skeleton in ``meshes``; returns ``(joints_of, asset_of)`` keyed by
    skeleton index."""
    cfg = crowd.config
    skeleton_names = list(cfg.skeletons)
    ids = sorted(meshes)
    file_names = unique_identifiers([skeleton_names[k] for k in ids], casefold=True)
    joints_of, asset_of = {}, {}
    for k, name in zip(ids, file_names):
        layer, joints_of[k] = character_layer(cfg.skeletons[skeleton_names[k]], meshes[k],
                                              out.files.format, crowd.fps, name)
        out.save(layer, f"characters/{name}")
        asset_of[k] = out.files.asset_path(f"characters/{name}")
    _report(out.progress, "characters", len(ids), len(ids))
    return joints_of, asset_of


def _write_streams(out, crowd, shot, joints_of) -> tuple:
    """One layer per stream a static agent plays; returns ``(prim names of all
    streams, {stream: asset path})``."""
    names = unique_identifiers(crowd.names[:crowd.S], casefold=True)
    used = np.unique(shot.stream[shot.static]).tolist()
    assets = {}
    for j, s in enumerate(used):
        out.save(_stream_layer(shot, s, crowd.names[s], names[s],
                               joints_of[int(shot.stream_skeleton[s])], out.files.format),
                 f"streams/{names[s]}")
        assets[s] = out.files.asset_path(f"streams/{names[s]}")
        _report(out.progress, "streams", j + 1, len(used))
    return names, assets


def _write_own_animations(out, shot, names, joints_of) -> list:
    """The sublayer of agents' own animations (none if every agent is static)."""
    if shot.static.all():
        return []
    layer = new_layer(out.files.format, shot.fps, shot.first, shot.last,
                      comment="own animations of agents that are not static")
    with Sdf.ChangeBlock():
        paths = author_agent_animations(layer, shot, names, joints_of, out.progress)
    out.save(layer, "agents")
    return paths


def _report(progress, stage, done, total):
    if progress is not None:
        progress(stage, done, total)


def _crowd(source) -> Crowd:
    if isinstance(source, Crowd):
        return source
    if isinstance(source, CrowdConfig):
        return Crowd(source)
    raise CrowdError(f"export: expected a CrowdConfig or a Crowd, got "
                     f"{type(source).__name__}")


def _frame_range(frames, crowd) -> tuple:
    try:
        first, last = frames
    except (TypeError, ValueError):
        raise CrowdError(f"export: frames must be (first, last), got {frames!r}") from None
    for f in (first, last):
        if isinstance(f, bool) or not isinstance(f, (int, np.integer)):
            raise CrowdError(f"export: frames must be whole numbers, got {frames!r}")
    first, last = int(first), int(last)
    if last < first:
        raise CrowdError(f"export: frame range {first}-{last} is empty (last < first)")
    start = int(crowd.config.start_frame)
    if first < start:
        raise CrowdError(f"export: frame range {first}-{last} starts before the crowd's "
                         f"start frame {start}")
    return first, last


def _agent_ids(agents, crowd) -> np.ndarray:
    if crowd.N == 0:
        raise CrowdError("export: the crowd has no agents")
    if agents is None:
        return np.arange(crowd.N, dtype=np.int64)
    if isinstance(agents, bool) or not isinstance(agents, (int, np.integer)) or agents < 1:
        raise CrowdError(f"export: agents must be a count >= 1, got {agents!r}")
    if agents > crowd.N:
        raise CrowdError(f"export: {agents} agents requested but the crowd has "
                         f"{crowd.N}")
    return np.arange(int(agents), dtype=np.int64)


def _meshes(crowd, ids) -> dict:
    """Proxy mesh (LOD 0) per skeleton index the exported agents use."""
    cfg = crowd.config
    skeleton_names = list(cfg.skeletons)
    out = {}
    for k in np.unique(agent_skeletons(crowd, ids)).tolist():
        levels = cfg.meshes.get(skeleton_names[k])
        if not levels:
            raise CrowdError(f"export: skeleton {skeleton_names[k]!r} has no proxy mesh "
                             "(CrowdConfig.add_mesh); its agents cannot be drawn")
        out[k] = levels[0]
    return out


def _stream_layer(shot, s, name, prim_name, joints, fmt):
    frames = shot.stream_frames
    layer = new_layer(fmt, shot.fps, frames[0], frames[-1], default_prim=prim_name,
                      comment=f"crowd stream {name!r}: the head's pose at each frame")
    events = shot.stream_events[s]
    with Sdf.ChangeBlock():
        prim = Sdf.PrimSpec(layer, prim_name, Sdf.SpecifierDef, "SkelAnimation")
        prim.customData = {"crowd": {
            "stream": name, "streamIndex": int(s),
            "eventNames": Vt.StringArray([n for n, _ in events]),
            "eventFrames": Vt.DoubleArray([float(f) for _, f in events])}}
        author_animation(prim, joints, shot.stream_poses[:, s], frames)
    return layer


def _sources(shot, offsets, own_paths) -> list:
    keys = shot.stream * shot.max_offset + shot.offset
    own = iter(own_paths)
    return [offsets[int(k)] if st else next(own)
            for k, st in zip(keys.tolist(), shot.static.tolist())]


def _settings(crowd, shot) -> dict:
    cfg = crowd.config
    return {"M": int(crowd.M), "NT": int(crowd.NT), "fps": float(crowd.fps),
            "seed": int(cfg.seed), "streams": int(crowd.S), "uniques": int(crowd.U),
            "agents": int(shot.agents.size), "firstFrame": int(shot.first),
            "lastFrame": int(shot.last), "writer": "crowd_addon.usd",
            "version": FORMAT_VERSION}
