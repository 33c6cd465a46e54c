"""Chunks of one shot, exported apart, joined into one stage (``crowd stitch``).

A long shot can be exported in chunks: ``crowd export --frames A-B --snapshots DIR``
starts each chunk from the snapshot before it (docs/snapshots.md), so chunks can run
in separate processes or on separate machines. :func:`stitch` joins the chunks'
stages into one that reads back as the export of the whole range would:

- streams and uniques: one layer each. Its time samples are the chunks' samples in
  frame order, each frame taken from the first chunk that has it (the history frames
  that chunks share are equal: the same simulation);
- an agent that plays the same ``(stream, offset)`` in every chunk keeps a shared
  offset animation of the joined stream;
- every other agent gets one value-clip set: the chunks' pieces one after another. A
  chunk in which it was static is one stream piece. Blends are read from the chunks'
  blend banks where they are; they are not copied;
- agent transforms: time samples over the whole shot for an agent that moved in any
  chunk;
- event tags: the chunks' lists of each stream joined.

Value clips rather than sublayers: a sublayer cannot give an attribute's samples for
only part of the time (the strongest layer's samples win at every time), while clips
switch layers at given times, which is what the export already does for agents.

The stitched stage reads the chunks' character layers and blend banks: keep the chunk
files where they are (relative paths, so the stitched shot and its chunks can move
together). It registers itself with each chunk (``<chunk>.layers/readers/``,
usd/references.py), so re-exporting a chunk in place keeps the layer version the
stitched stage reads until no stage reads it. Checked before anything is written,
each problem named: every chunk is a crowd export of the same configuration
(``configDigest``), agents, layout and samples per frame; their frame ranges follow
each other with no gap or overlap.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
from pxr import Sdf, Tf, UsdUtils, Vt

from ..core.base.errors import CrowdError
from .agents import ROOT
from .clips import PRIM, manifest_layer
from .export import PER_AGENT as _PER_AGENT, per_agent_settings
from .files import ExportFiles
from .layers import attribute, define, new_layer
from .references import register_reader

__all__ = ["stitch", "StitchResult"]

_CHANNELS = ("translations", "rotations", "scales")
_XFORM = ("xformOp:translate", "xformOp:rotateZ")
_SAME = ("M", "NT", "fps", "seed", "streams", "uniques", "agents", "layout", "substeps",
         "version", "configDigest")
_PAIR = 1 << 20                               # (stream, offset) as one int
_T = Sdf.ValueTypeNames


@dataclass(frozen=True)
class StitchResult:
    """What a stitch wrote: ``path`` (the main layer), ``layers_dir``, ``files``
    (relative path -> bytes), ``frames`` (first, last), ``chunks`` (the chunks' main
    layers, in frame order), ``agents``, ``shared_agents`` (on a shared offset
    animation), ``clip_agents`` (on value clips), ``moving_agents``, ``seconds``."""

    path: str
    layers_dir: str
    files: dict
    frames: tuple
    chunks: list
    agents: int
    shared_agents: int
    clip_agents: int
    moving_agents: int
    seconds: float

    @property
    def bytes(self) -> int:
        return int(sum(self.files.values()))


class _Chunk:
    """One chunk's main layer, its agents sublayer, and where their assets are."""

    def __init__(self, path):
        self.path = os.path.abspath(os.fspath(path))
        self.dir = os.path.dirname(self.path)
        if not os.path.isfile(self.path):
            raise CrowdError(f"{path}: no such chunk")
        self.layer = _open(self.path, path)
        crowd = dict(self.layer.customLayerData).get("crowd")
        if not isinstance(crowd, dict) or crowd.get("writer") != "crowd_addon.usd":
            raise CrowdError(f"{path}: not a crowd export (no customLayerData crowd written "
                             "by crowd_addon.usd)")
        missing = [k for k in ("firstFrame", "lastFrame", *_SAME, *_PER_AGENT)
                   if k not in crowd]
        if missing:
            raise CrowdError(f"{path}: its crowd settings lack {missing} (exported by an "
                             "older version? export the chunk again)")
        self.settings = crowd
        self.first, self.last = int(crowd["firstFrame"]), int(crowd["lastFrame"])
        self.layers_root = f"{os.path.splitext(self.path)[0]}.layers"
        self.own = None
        for sub in self.layer.subLayerPaths:
            self.own = _open(self.resolve(sub), path)
            self.own_dir = os.path.dirname(self.own.realPath)
        agents = self.layer.GetPrimAtPath(f"/{ROOT}/Agents")
        self.names = list(agents.nameChildren.keys()) if agents else []
        #: per agent (in :attr:`names` order) the stream and offset it plays the whole
        #: chunk (-1: it changes), and whether it moves: what the export recorded
        self.stream, self.offset, self.moves = (
            np.asarray(crowd[k], np.int64).reshape(-1) for k in _PER_AGENT)
        if any(a.size != len(self.names) for a in (self.stream, self.offset, self.moves)):
            raise CrowdError(f"{path}: its per-agent arrays ({', '.join(_PER_AGENT)}) do "
                             f"not hold one value for each of its {len(self.names)} agents")
        self._offsets = {}                   # offset animation path -> what it plays
        self._targets = {}                   # agent name -> its animation source

    def resolve(self, asset, base=None) -> str:
        return os.path.normpath(os.path.join(base or self.dir, asset))

    def agent(self, name) -> Sdf.PrimSpec:
        return self.layer.GetPrimAtPath(f"/{ROOT}/Agents/{name}")

    def target(self, name) -> Sdf.Path:
        """Agent ``name``'s ``skel:animationSource`` target."""
        found = self._targets.get(name)
        if found is None:
            rel = self.agent(name).relationships["skel:animationSource"]
            found = self._targets[name] = rel.targetPathList.explicitItems[0]
        return found

    def source(self, name):
        """What agent ``name`` plays: ``("static", stream layer, prim name, offset)`` or
        ``("clips", its clip set dict, its joints)``."""
        target = self.target(name)
        if self.own is not None and target.HasPrefix(f"/{ROOT}/AgentAnimations"):
            spec = self.own.GetPrimAtPath(target)
            return ("clips", dict(spec.GetInfo("clips")["default"]),
                    spec.attributes["joints"].default)
        found = self._offsets.get(target)
        if found is None:
            ref = self.layer.GetPrimAtPath(target).referenceList.prependedItems[0]
            found = self._offsets[target] = (
                "static", self.resolve(ref.assetPath), target.GetParentPath().name,
                int(round(ref.layerOffset.offset)))
        return found

    def static_sources(self, which) -> dict:
        """``{(stream, offset): source}`` (:meth:`source`'s static form) of each pair the
        agents at positions ``which`` play the whole chunk. A stream's layer and scope
        are looked up once, from one of its agents; every offset of it lies beside."""
        stream, offset = self.stream[which], self.offset[which]
        streams, first = np.unique(stream, return_index=True)
        layer = {int(k): self.source(self.names[int(which[i])])[1:3]
                 for k, i in zip(streams.tolist(), first.tolist())}
        pairs = np.unique(stream * _PAIR + offset)
        return {(k // _PAIR, k % _PAIR): ("static", *layer[k // _PAIR], k % _PAIR)
                for k in pairs.tolist()}


def _open(real, shown):
    try:
        layer = Sdf.Layer.FindOrOpen(real)
    except Tf.ErrorException as e:
        raise CrowdError(f"{shown}: not a readable USD layer: {e}") from None
    if layer is None:
        raise CrowdError(f"{shown}: not a readable USD layer")
    return layer


def _check(chunks):
    if not chunks:
        raise CrowdError("stitch: no chunks given")
    first = chunks[0]
    for c in chunks[1:]:
        for key in _SAME:
            if c.settings[key] != first.settings[key]:
                raise CrowdError(f"stitch: {c.path} has {key} = {c.settings[key]!r}, "
                                 f"{first.path} {first.settings[key]!r}: chunks must come "
                                 "from one crowd configuration, exported alike")
        if c.names != first.names:
            raise CrowdError(f"stitch: {c.path} does not export the same agents as "
                             f"{first.path}")
    for a, b in zip(chunks, chunks[1:]):
        if b.first != a.last + 1:
            what = "overlap" if b.first <= a.last else "leave a gap"
            raise CrowdError(f"stitch: chunks {a.path} (frames {a.first}-{a.last}) and "
                             f"{b.path} (frames {b.first}-{b.last}) {what}: each chunk "
                             "must start the frame after the one before ends")


def stitch(chunks, path, progress=None) -> StitchResult:
    """Join the chunk exports ``chunks`` (their main layers, any order) into one stage
    at ``path`` (``.usdc``, ``.usd`` or ``.usda``; layers in ``<stem>.layers/vN``).

    ``progress(stage, done, total)`` after each unit of work. All or nothing, like an
    export: on any error (CrowdError naming the chunk and the problem) nothing is
    written and a previous stitch at ``path`` is left as it was.
    """
    t0 = time.perf_counter()
    parts = sorted((_Chunk(p) for p in chunks), key=lambda c: c.first)
    _check(parts)
    files = ExportFiles(path)
    if any(os.path.normpath(c.path) == os.path.normpath(files.path) for c in parts):
        raise CrowdError(f"stitch: the output {path} is one of the chunks; write the "
                         "stitched stage beside them")
    first, last = parts[0], parts[-1]
    fps, n = float(first.settings["fps"]), int(first.settings["substeps"])
    with files:
        # the agents that play one (stream, offset) in every chunk share an offset
        # animation and are touched no further (their prims, copied, already point at
        # it); only the others are read agent by agent
        streams = np.stack([c.stream for c in parts])
        offsets_all = np.stack([c.offset for c in parts])
        shared = (streams[0] >= 0) & (streams == streams[0]).all(0) & \
            (offsets_all == offsets_all[0]).all(0)
        own_at = np.flatnonzero(~shared)
        own_names = [first.names[i] for i in own_at.tolist()]
        sources = {name: [c.source(name) for c in parts] for name in own_names}
        pairs = [c.static_sources(np.flatnonzero(c.stream >= 0)) for c in parts]
        merged = {}                          # chunk stream/unique layer -> merged asset
        joints = {}                          # merged asset -> joints
        groups = _animation_layers(parts, sources, pairs)
        for j, ((kind, name), found) in enumerate(groups.items()):
            layer = _joined(found, files.format, fps)
            files.save(layer, f"{kind}/{name}")
            joints[f"{kind}/{name}"] = layer.GetAttributeAtPath(f"/{PRIM}.joints").default
            for _, real in found:
                merged[real] = f"{kind}/{name}"
            if progress is not None:
                progress(kind, j + 1, len(groups))

        static_at = np.flatnonzero(shared)
        static = first.static_sources(static_at) if static_at.size else {}

        main = new_layer(files.format, fps, first.first, last.last,
                         default_prim=ROOT, comment="crowd shot stitched from chunks by "
                                                    "crowd_addon.usd")
        main.customLayerData = {"crowd": {
            **_shot_settings(parts), "firstFrame": first.first, "lastFrame": last.last,
            "chunks": Vt.StringArray([_relative(c.path, files.directory) for c in parts]),
            **per_agent_settings(np.where(shared, streams[0], -1),
                                 np.where(shared, offsets_all[0], -1),
                                 np.stack([c.moves for c in parts]).any(0))}}
        crowd = Sdf.PrimSpec(main, ROOT, Sdf.SpecifierDef, "Xform")
        Sdf.CopySpec(first.layer, f"/{ROOT}/Agents", main, f"/{ROOT}/Agents")
        _rebase(main, first, files)          # before anything of ours is in the layer
        if own_names:
            files.save(manifest_layer(files.format, fps), "manifest")
            own = new_layer(files.format, fps, first.first, last.last,
                            comment="animations of agents that change: value clips over "
                                    "the stitched chunks")
            root = Sdf.PrimSpec(own, ROOT, Sdf.SpecifierOver)
            scope = define(root, "AgentAnimations", "Scope")
            with Sdf.ChangeBlock():
                for name in own_names:
                    clips, agent_joints = _clip_set(parts, sources[name], merged, files, n)
                    prim = define(scope, name, "SkelAnimation")
                    attribute(prim, "joints", _T.TokenArray,
                              agent_joints if agent_joints is not None
                              else joints[clips.pop("_stream")], uniform=True)
                    clips.pop("_stream", None)
                    prim.SetInfo("clips", {"default": clips})
            files.save(own, "agents")
            main.subLayerPaths.append(files.asset_path("agents"))
        if progress is not None:
            progress("agent animations", len(own_names), len(own_names))

        _offset_animations(crowd, static, merged, files)
        moving = _agents(main, parts, own_names)
        files.save(main)
        if progress is not None:
            progress("layout", len(first.names), len(first.names))
        for c in parts:                      # before the commit: no moment unprotected
            if os.path.isdir(c.layers_root):
                register_reader(c.layers_root, files.path)
        files.commit()
    return StitchResult(
        path=files.path, layers_dir=files.layers_dir, files=dict(files.written),
        frames=(first.first, last.last), chunks=[c.path for c in parts],
        agents=len(first.names), shared_agents=int(static_at.size), clip_agents=len(own_names),
        moving_agents=moving, seconds=time.perf_counter() - t0)


def _animation_layers(parts, sources, pairs) -> dict:
    """``{(kind, name): [(chunk, layer file)]}`` of the stream and unique layers the
    chunks read, in chunk order (kind ``streams`` or ``uniques``, name the file stem):
    those of the (stream, offset) pairs agents play a whole chunk (``pairs``, per chunk)
    and of the clip sets of the agents in ``sources``."""
    out = {}
    for k, c in enumerate(parts):
        found = {s[1] for s in pairs[k].values()}
        for per_chunk in sources.values():
            s = per_chunk[k]
            if s[0] == "static":
                found.add(s[1])
            else:
                base = c.own_dir
                found.update(c.resolve(a.path, base) for a in s[1]["assetPaths"])
        for real in sorted(found):
            kind = os.path.basename(os.path.dirname(real))
            if kind in ("streams", "uniques"):
                stem = os.path.splitext(os.path.basename(real))[0]
                out.setdefault((kind, stem), []).append((c, real))
    return out


def _joined(sources, fmt, fps):
    """One animation layer with the samples of ``sources`` (chunk, layer file) in frame
    order: everything of the first, then of each next only the times after those
    already there (a chunk's history frames repeat the one before's)."""
    layers = [(c, _open(real, real)) for c, real in sources]
    start = min(l.startTimeCode for _, l in layers)
    end = max(l.endTimeCode for _, l in layers)
    first = layers[0][1]
    out = new_layer(fmt, fps, start, end, default_prim=PRIM, comment=first.comment)
    Sdf.CopySpec(first, f"/{PRIM}", out, f"/{PRIM}")
    prim = out.GetPrimAtPath(f"/{PRIM}")
    events = _events(prim)
    covered = layers[0][0].last
    with Sdf.ChangeBlock():
        for c, layer in layers[1:]:
            for channel in _CHANNELS:
                path = prim.path.AppendProperty(channel)
                have = out.ListTimeSamplesForPath(path)
                after = have[-1] if have else float("-inf")
                for t in layer.ListTimeSamplesForPath(path):
                    if t > after:
                        out.SetTimeSample(path, t, layer.QueryTimeSample(path, t))
            more = [e for e in _events(layer.GetPrimAtPath(f"/{PRIM}")) if e[1] > covered]
            events += more
            covered = c.last
    if events:
        data = dict(prim.customData)
        crowd = dict(data.get("crowd", {}))
        crowd["eventNames"] = Vt.StringArray([e[0] for e in events])
        crowd["eventFrames"] = Vt.DoubleArray([e[1] for e in events])
        data["crowd"] = crowd
        prim.customData = data
    return out


def _events(prim) -> list:
    crowd = dict(prim.customData).get("crowd", {}) if prim else {}
    return list(zip(list(crowd.get("eventNames", [])),
                    [float(f) for f in crowd.get("eventFrames", [])]))


def _shot_settings(parts) -> dict:
    """The first chunk's settings, with the shot's repetition metric: the mean of the
    chunks' (each measures the same number of frames), or none when a chunk lacks it
    or measured with other neighbours."""
    out = {k: v for k, v in parts[0].settings.items()
           if k not in ("repetition", "repetitionK", *_PER_AGENT)}
    values = [c.settings.get("repetition") for c in parts]
    ks = {c.settings.get("repetitionK") for c in parts}
    if None not in values and len(ks) == 1:
        out.update(repetition=sum(values) / len(values), repetitionK=ks.pop())
    return out


def _relative(real, directory) -> str:
    rel = os.path.relpath(real, directory).replace(os.sep, "/")
    return rel if rel.startswith(".") else f"./{rel}"


def _clip_set(parts, sources, merged, files, n) -> tuple:
    """The value-clip set of one agent over all chunks, and its joints (None when no
    chunk gave it its own animation: then ``clips["_stream"]`` names a stream layer
    whose joints it has)."""
    h = 0.5 / n
    assets, active, times = [], [], []
    agent_joints, stream = None, None

    def index(asset):
        if asset not in assets:
            assets.append(asset)
        return float(assets.index(asset))

    for c, s in zip(parts, sources):
        if s[0] == "static":
            _, real, _, o = s
            stream = merged[real]
            i = index(files.layer_path(stream))
            a, b = c.first - h, c.last + 1 - h
            active.append((a, i))
            times += [(a, a - o), (b, b - o)]
            continue
        clips, agent_joints = s[1], s[2]
        remap = []
        for asset in clips["assetPaths"]:
            real = c.resolve(asset.path, c.own_dir)
            remap.append(index(files.layer_path(merged[real]) if real in merged
                               else _relative(real, files.layers_dir)))
        active += [(t, remap[int(i)]) for t, i in clips["active"]]
        times += [(t, u) for t, u in clips["times"]]
    out = {"assetPaths": Sdf.AssetPathArray(assets), "primPath": f"/{PRIM}",
           "active": Vt.Vec2dArray(active), "times": Vt.Vec2dArray(times),
           "manifestAssetPath": Sdf.AssetPath(files.layer_path("manifest"))}
    if agent_joints is None:
        out["_stream"] = stream
    return out, agent_joints


def _offset_animations(crowd, static, merged, files) -> dict:
    """Offset animations of the agents static over the whole shot: ``{(stream asset,
    offset): path}``."""
    streams = define(crowd, "Streams", "Scope")
    out = {}
    for _, real, scope_name, o in sorted(set(static.values()), key=lambda s: (s[2], s[3])):
        key = (merged[real], o)
        if key in out:
            continue
        scope = streams.nameChildren.get(scope_name) or define(streams, scope_name, "Scope")
        prim = define(scope, f"offset_{o}", "SkelAnimation")
        prim.referenceList.Prepend(Sdf.Reference(files.asset_path(merged[real]),
                                                 layerOffset=Sdf.LayerOffset(o, 1.0)))
        out[key] = prim.path
    return out


def _agents(main, parts, own_names) -> int:
    """Point each copied agent prim with clips at its animation, and join the
    transforms of agents that moved. Returns how many moved. A shared agent's prim,
    copied from the first chunk, already points where the stitched stage keeps its
    offset animation (``/Crowd/Streams/<stream>/offset_<o>``, as every export)."""
    first = parts[0]
    moved = 0
    with Sdf.ChangeBlock():
        for name in own_names:
            _point(main, name, Sdf.Path(f"/{ROOT}/AgentAnimations/{name}"))
        for i in np.flatnonzero(np.stack([c.moves for c in parts]).any(0)).tolist():
            name = first.names[i]
            _join_moves(main, Sdf.Path(f"/{ROOT}/Agents/{name}"), parts, name)
            moved += 1
    return moved


def _point(main, name, target):
    prim = main.GetPrimAtPath(f"/{ROOT}/Agents/{name}")
    prim.relationships["skel:animationSource"].targetPathList.explicitItems = [target]


def _rebase(main, first, files):
    """The asset paths of the agents copied from ``first`` (their characters),
    relative to the stitched stage's folder: one C++ walk over the layer, not an
    edit per agent."""
    if os.path.normpath(first.dir) == os.path.normpath(files.directory):
        return
    rebased = {}

    def rebase(asset):
        if asset not in rebased:
            rebased[asset] = _relative(first.resolve(asset), files.directory)
        return rebased[asset]
    UsdUtils.ModifyAssetPaths(main, rebase)


def _join_moves(main, path, parts, name):
    """Time samples of an agent's transform over the whole shot (some chunk has
    some): each chunk's, or its value at the chunk's first and last frame where that
    chunk has none."""
    agent = f"/{ROOT}/Agents/{name}"
    for op in _XFORM:
        dst = path.AppendProperty(op)
        for t in main.ListTimeSamplesForPath(dst):
            main.EraseTimeSample(dst, t)
        for c in parts:
            src = Sdf.Path(f"{agent}.{op}")
            samples = c.layer.ListTimeSamplesForPath(src)
            if samples:
                for t in samples:
                    main.SetTimeSample(dst, t, c.layer.QueryTimeSample(src, t))
            else:
                value = c.layer.GetAttributeAtPath(src).default
                for t in sorted({float(c.first), float(c.last)}):
                    main.SetTimeSample(dst, t, value)
