"""Chunks of one shot, exported apart, joined into one stage (``crowd stitch``).

A long shot can be exported in chunks: ``crowd export --frames A-B --snapshots DIR``
starts each chunk from the snapshot before it (docs/snapshots.md), so chunks can run
in separate processes or on separate machines. The first chunk is exported whole; the
others need only their animation (``--animation-only``: no agent prims, characters or
offset animations). :func:`stitch` joins them into one stage that reads back as the
export of the whole range would, writing little of its own:

- the agents: the first chunk's layout layer, read where it is (a sublayer), with
  overs for the agents that change what they play and for those that move;
- a stream that agents play at one offset the whole shot: a prim of one ``streams``
  layer holding only value clips over the chunks' layers of it (each chunk's also
  holds the M - 1 frames before it, so an offset never reads across a switch), which
  their shared offset animations reference with the offset, as in every export;
- every other agent: one value-clip set, the chunks' pieces one after another, each
  reading the chunk's own layers (streams, uniques, blend banks); nothing is copied;
- agents that move: their transforms over the whole shot, from each chunk's samples
  or, where it stood still in a chunk, from the place the chunk recorded;
- event tags: the chunks' lists of each stream joined.

What the stitch knows of each agent it reads from the arrays every export records
(stream, offset, moves, place: :data:`~.export.PER_AGENT`), never agent prim by agent
prim. The stitched stage reads the chunks' layers: keep the chunk files where they are
(relative paths, so the stitched shot and its chunks can move together). It registers
itself with each chunk (``<chunk>.layers/readers/``, usd/references.py), so
re-exporting a chunk in place keeps the layer version the stitched stage reads until
no stage reads it. Checked before anything is written, each problem named: every
chunk is a crowd export of the same configuration (``configDigest``), agents, layout
and samples per frame; their frame ranges follow each other with no gap or overlap;
the first holds the agents.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
from pxr import Gf, Sdf, Tf, Vt

from ..core.base.errors import CrowdError
from .agents import ROOT, agent_names
from .clips import PRIM, manifest_layer
from .export import PER_AGENT as _PER_AGENT, per_agent_settings
from .files import ExportFiles
from .layers import attribute, define, new_layer, relationship
from .references import register_reader

__all__ = ["stitch", "StitchResult"]

_XFORM = ("xformOp:translate", "xformOp:rotateZ")
_XFORM_TYPES = (Sdf.ValueTypeNames.Float3, Sdf.ValueTypeNames.Double)
_SAME = ("M", "NT", "fps", "seed", "streams", "uniques", "agents", "layout", "substeps",
         "version", "configDigest")
_PAIR = 1 << 20                               # (stream, offset) as one int
#: what an export records of its streams for a stitch (usd/export.py ``_settings``)
_STREAMS = ("streamLayers", "eventStream", "eventName", "eventFrame")
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
    """One chunk's main layer, its settings, and where its layers are."""

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
        if "chunks" in crowd:
            raise CrowdError(f"{path}: a stitched stage, not a chunk: stitch its chunks "
                             "instead")
        missing = [k for k in ("firstFrame", "lastFrame", *_SAME, *_PER_AGENT,
                               *_STREAMS) if k not in crowd]
        if missing:
            raise CrowdError(f"{path}: its crowd settings lack {missing} (exported by an "
                             "older version? export the chunk again)")
        self.settings = crowd
        self.first, self.last = int(crowd["firstFrame"]), int(crowd["lastFrame"])
        self.layers_root = f"{os.path.splitext(self.path)[0]}.layers"
        self.own = self.layout = None
        for sub in self.layer.subLayerPaths:
            real = self.resolve(sub)
            stem = os.path.splitext(os.path.basename(real))[0]
            if stem == "agents":
                self.own = _open(real, path)
                self.own_dir = os.path.dirname(real)
            elif stem == "layout":
                self.layout = real
        #: per agent the stream and offset it plays the whole chunk (-1: it changes),
        #: whether it moves, and where it stands at the chunk's first frame: what the
        #: export recorded
        self.stream, self.offset, self.moves = (
            np.asarray(crowd[k], np.int64).reshape(-1) for k in _PER_AGENT[:3])
        self.position = np.asarray(crowd["agentPosition"], np.float32).reshape(-1, 3)
        self.heading = np.asarray(crowd["agentHeading"], np.float32).reshape(-1)
        n = int(crowd["agents"])
        if any(a.shape[0] != n for a in (self.stream, self.offset, self.moves,
                                         self.position, self.heading)):
            raise CrowdError(f"{path}: its per-agent arrays ({', '.join(_PER_AGENT)}) do "
                             f"not hold one value for each of its {n} agents")
        self.stream_layers = [self.resolve(a) if a else None for a in crowd["streamLayers"]]
        self._events = (np.asarray(crowd["eventStream"], np.int64).reshape(-1),
                        list(crowd["eventName"]), list(crowd["eventFrame"]))

    def events(self, s) -> list:
        """``(name, frame)`` of the tags stream ``s``'s layer holds, in frame order."""
        at, names, frames = self._events
        return [(names[i], float(frames[i])) for i in np.flatnonzero(at == s).tolist()]

    def resolve(self, asset, base=None) -> str:
        return os.path.normpath(os.path.join(base or self.dir, asset))

    def stream_layer(self, s) -> str:
        """The file of stream ``s``'s layer (CrowdError when the chunk wrote none)."""
        real = self.stream_layers[s] if 0 <= s < len(self.stream_layers) else None
        if real is None:
            raise CrowdError(f"{self.path}: its settings name no layer for stream {s}, "
                             "which an agent plays (export the chunk again)")
        return real

    def source(self, i, name):
        """What agent ``i`` (prim ``name``) plays in this chunk: ``("static", stream
        layer file, offset)`` or ``("clips", its animation's prim spec)``."""
        if self.stream[i] >= 0:
            return ("static", self.stream_layer(int(self.stream[i])), int(self.offset[i]))
        spec = self.own.GetPrimAtPath(f"/{ROOT}/AgentAnimations/{name}") \
            if self.own is not None else None
        if spec is None:
            raise CrowdError(f"{self.path}: agent {name} changes what it plays but has no "
                             "animation of its own (export the chunk again)")
        return ("clips", spec)


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
    if first.layout is None:
        raise CrowdError(f"stitch: {first.path} is the shot's first chunk and holds no "
                         "agents (exported --animation-only): export the first chunk whole")
    fps, n = float(first.settings["fps"]), int(first.settings["substeps"])
    names = agent_names(np.arange(first.stream.size))
    layers = _Layers()
    with files:
        # the agents that play one (stream, offset) in every chunk share an offset
        # animation of a stream layer joined from the chunks' by value clips; only the
        # others are read agent by agent
        streams = np.stack([c.stream for c in parts])
        offsets_all = np.stack([c.offset for c in parts])
        shared = (streams[0] >= 0) & (streams == streams[0]).all(0) & \
            (offsets_all == offsets_all[0]).all(0)
        own_at = np.flatnonzero(~shared)
        static_at = np.flatnonzero(shared)
        used = np.unique(streams[0][static_at]).tolist()
        joined = {}                          # stream -> (scope name, prim in "streams")
        if used:
            files.save(manifest_layer(files.format, fps), "manifest")
            files.save(_joined(parts, used, files, fps, n, layers, joined, progress),
                       "streams")

        main = new_layer(files.format, fps, first.first, last.last,
                         default_prim=ROOT, comment="crowd shot stitched from chunks by "
                                                    "crowd_addon.usd")
        positions = np.stack([c.position for c in parts])
        headings = np.stack([c.heading for c in parts])
        moving = np.stack([c.moves for c in parts]).astype(bool).any(0) | \
            (positions != positions[0]).any((0, 2)) | (headings != headings[0]).any(0)
        main.customLayerData = {"crowd": {
            **_shot_settings(parts), "firstFrame": first.first, "lastFrame": last.last,
            "chunks": Vt.StringArray([_relative(c.path, files.directory) for c in parts]),
            **per_agent_settings(np.where(shared, streams[0], -1),
                                 np.where(shared, offsets_all[0], -1), moving,
                                 first.position, first.heading)}}
        crowd = Sdf.PrimSpec(main, ROOT, Sdf.SpecifierDef, "Xform")
        _offset_animations(crowd, streams[0][static_at], offsets_all[0][static_at], joined,
                           files.asset_path("streams"))
        if own_at.size:
            if not used:
                files.save(manifest_layer(files.format, fps), "manifest")
            own = new_layer(files.format, fps, first.first, last.last,
                            comment="animations of agents that change: value clips over "
                                    "the stitched chunks")
            scope = define(Sdf.PrimSpec(own, ROOT, Sdf.SpecifierOver), "AgentAnimations",
                           "Scope")
            with Sdf.ChangeBlock():
                for i in own_at.tolist():
                    clips, joints = _clip_set(parts, i, names[i], files, n, layers)
                    prim = define(scope, names[i], "SkelAnimation")
                    attribute(prim, "joints", _T.TokenArray, joints, uniform=True)
                    prim.SetInfo("clips", {"default": clips})
            files.save(own, "agents")
            main.subLayerPaths.append(files.asset_path("agents"))
        if progress is not None:
            progress("agent animations", int(own_at.size), int(own_at.size))
        # the agents themselves: the first chunk's layout, read where it is
        main.subLayerPaths.append(_relative(first.layout, files.directory))
        _agents(crowd, parts, names, own_at[first.stream[own_at] >= 0],
                np.flatnonzero(moving))
        files.save(main)
        if progress is not None:
            progress("layout", len(names), len(names))
        for c in parts:                      # before the commit: no moment unprotected
            if os.path.isdir(c.layers_root):
                register_reader(c.layers_root, files.path)
        files.commit()
    return StitchResult(
        path=files.path, layers_dir=files.layers_dir, files=dict(files.written),
        frames=(first.first, last.last), chunks=[c.path for c in parts],
        agents=len(names), shared_agents=int(static_at.size), clip_agents=int(own_at.size),
        moving_agents=int(moving.sum()), seconds=time.perf_counter() - t0)


class _Layers:
    """Chunk layers opened once each (a stream's, for its joints and the customData of
    its prim), and the chunks' asset paths resolved once each."""

    def __init__(self):
        self._open, self._resolved, self._assets, self._joints = {}, {}, {}, {}

    def __call__(self, real) -> Sdf.Layer:
        layer = self._open.get(real)
        if layer is None:
            layer = self._open[real] = _open(real, real)
        return layer

    def joints(self, chunk, s):
        """The joints of stream ``s`` (the same in every chunk): read once, from
        ``chunk``'s layer of it."""
        found = self._joints.get(s)
        if found is None:
            found = self._joints[s] = self(chunk.stream_layer(s)).GetAttributeAtPath(
                f"/{PRIM}.joints").default
        return found

    def resolve(self, chunk, asset) -> str:
        """The file of ``asset``, a path in ``chunk``'s agents layer."""
        key = (chunk.own_dir, asset)
        found = self._resolved.get(key)
        if found is None:
            found = self._resolved[key] = chunk.resolve(asset, chunk.own_dir)
        return found

    def asset(self, real, directory) -> str:
        """``real`` as an asset path relative to ``directory``."""
        key = (real, directory)
        found = self._assets.get(key)
        if found is None:
            found = self._assets[key] = _relative(real, directory)
        return found


def _joined(parts, used, files, fps, n, layers, joined, progress):
    """One layer of the streams of ``used`` over the whole shot, a prim each (named as
    the stream's scope; ``joined[s]`` gets ``(name, its path)``): no samples of its
    own, value clips over the chunks' layers of the stream, each from half a sample
    before its chunk's first frame (each chunk's layer also holds the M - 1 frames
    before it, so every time an offset reads lies in the active one), and the chunks'
    event tags joined (from what each chunk recorded of them)."""
    h = 0.5 / n
    heads = [layers(parts[0].stream_layer(s)) for s in used]
    start = min(l.startTimeCode for l in heads)
    end = parts[-1].last + (n - 1) / n       # each stream layer's last sample
    out = new_layer(files.format, fps, start, end,
                    comment="crowd streams joined over the stitched chunks by value clips")
    active = Vt.Vec2dArray([(start if k == 0 else c.first - h, float(k))
                            for k, c in enumerate(parts)])
    times = Vt.Vec2dArray([(start, start), (end, end)])
    manifest = Sdf.AssetPath(files.layer_path("manifest"))
    with Sdf.ChangeBlock():
        for j, (s, head) in enumerate(zip(used, heads)):
            reals = [c.stream_layer(s) for c in parts]
            name = os.path.splitext(os.path.basename(reals[0]))[0]
            prim = define(out, name, "SkelAnimation")
            attribute(prim, "joints", _T.TokenArray, layers.joints(parts[0], s),
                      uniform=True)
            events, covered = [], float("-inf")
            for c in parts:                  # recorded by each chunk, history repeated
                events += [e for e in c.events(s) if e[1] > covered]
                covered = c.last
            data = dict(head.GetPrimAtPath(f"/{PRIM}").customData)
            crowd = dict(data.get("crowd", {}))
            crowd["eventNames"] = Vt.StringArray([e[0] for e in events])
            crowd["eventFrames"] = Vt.DoubleArray([e[1] for e in events])
            data["crowd"] = crowd
            prim.customData = data
            prim.SetInfo("clips", {"default": {
                "assetPaths": Sdf.AssetPathArray([layers.asset(r, files.layers_dir)
                                                  for r in reals]),
                "primPath": f"/{PRIM}", "active": active, "times": times,
                "manifestAssetPath": manifest}})
            joined[s] = (name, prim.path)
            if progress is not None:
                progress("streams", j + 1, len(used))
    return out


def _shot_settings(parts) -> dict:
    """The first chunk's settings, with the shot's repetition metric: the mean of the
    chunks' that measured it (each measures the same number of frames; an
    animation-only chunk does not), or none when none did or they measured with other
    neighbours."""
    out = {k: v for k, v in parts[0].settings.items()
           if k not in ("repetition", "repetitionK", *_STREAMS, *_PER_AGENT)}
    out["animationOnly"] = False
    measured = [c for c in parts if c.settings.get("repetition") is not None]
    values = [c.settings["repetition"] for c in measured]
    ks = {c.settings.get("repetitionK") for c in measured}
    if values and len(ks) == 1:
        out.update(repetition=sum(values) / len(values), repetitionK=ks.pop())
    return out


def _relative(real, directory) -> str:
    rel = os.path.relpath(real, directory).replace(os.sep, "/")
    return rel if rel.startswith(".") else f"./{rel}"


def _clip_set(parts, i, name, files, n, layers) -> tuple:
    """The value-clip set of agent ``i`` (prim ``name``) over all chunks, and its
    joints. A chunk in which it is static is one piece of that chunk's stream layer;
    otherwise its own clips in that chunk, read where they are."""
    h = 0.5 / n
    assets, active, times = {}, [], []
    joints = None

    def index(real) -> int:
        return assets.setdefault(layers.asset(real, files.layers_dir), len(assets))

    for c in parts:
        s = c.source(i, name)
        if s[0] == "static":
            _, real, o = s
            if joints is None:
                joints = layers.joints(c, int(c.stream[i]))
            a, b = c.first - h, c.last + 1 - h
            active.append(np.array([[a, index(real)]]))
            times.append(np.array([[a, a - o], [b, b - o]]))
            continue
        clips = s[1].GetInfo("clips")["default"]
        if joints is None:                   # one skeleton's: the same in every chunk
            joints = s[1].attributes["joints"].default
        remap = np.array([index(layers.resolve(c, asset.path)) for asset in clips["assetPaths"]],
                         np.float64)
        act = np.array(clips["active"], np.float64).reshape(-1, 2)
        act[:, 1] = remap[act[:, 1].astype(np.int64)]
        active.append(act)
        times.append(np.array(clips["times"], np.float64).reshape(-1, 2))
    return {"assetPaths": Sdf.AssetPathArray(list(assets)), "primPath": f"/{PRIM}",
            "active": Vt.Vec2dArray.FromNumpy(np.concatenate(active)),
            "times": Vt.Vec2dArray.FromNumpy(np.concatenate(times)),
            "manifestAssetPath": Sdf.AssetPath(files.layer_path("manifest"))}, joints


def _offset_animations(crowd, streams, offsets, joined, asset) -> None:
    """One offset animation per ``(stream, offset)`` of the agents static over the
    whole shot, where the first chunk's layout points them
    (``/Crowd/Streams/<stream>/offset_<o>``), referencing the stream's prim in the
    joined streams layer (``asset``)."""
    scope = define(crowd, "Streams", "Scope")
    pairs = np.unique(np.asarray(streams, np.int64) * _PAIR + offsets)
    with Sdf.ChangeBlock():
        for key in pairs.tolist():
            s, o = divmod(key, _PAIR)
            name, path = joined[s]
            parent = scope.nameChildren.get(name) or define(scope, name, "Scope")
            prim = define(parent, f"offset_{o}", "SkelAnimation")
            prim.referenceList.Prepend(Sdf.Reference(asset, path,
                                                     layerOffset=Sdf.LayerOffset(o, 1.0)))


def _agents(crowd, parts, names, repoint, moving) -> None:
    """Overs of the first chunk's agents: those of ``repoint`` (static in the first
    chunk, on value clips here) play their own animation; those of ``moving`` get
    their transforms over the whole shot, each chunk's samples or, where it stood
    still in a chunk, its place there at that chunk's first and last frame."""
    agents = Sdf.PrimSpec(crowd, "Agents", Sdf.SpecifierOver)
    with Sdf.ChangeBlock():
        for i in repoint.tolist():
            prim = Sdf.PrimSpec(agents, names[i], Sdf.SpecifierOver)
            relationship(prim, "skel:animationSource",
                         Sdf.Path(f"/{ROOT}/AgentAnimations/{names[i]}"))
        main = crowd.layer
        for i in moving.tolist():
            prim = agents.nameChildren.get(names[i]) or \
                Sdf.PrimSpec(agents, names[i], Sdf.SpecifierOver)
            dst = [attribute(prim, op, t).path for op, t in zip(_XFORM, _XFORM_TYPES)]
            for c in parts:
                src = [Sdf.Path(f"/{ROOT}/Agents/{names[i]}.{op}") for op in _XFORM]
                if c.moves[i]:
                    for d, p in zip(dst, src):
                        for t in c.layer.ListTimeSamplesForPath(p):
                            main.SetTimeSample(d, t, c.layer.QueryTimeSample(p, t))
                    continue
                values = (Gf.Vec3f(*c.position[i].tolist()),
                          float(np.degrees(np.float64(c.heading[i]))))
                for t in sorted({float(c.first), float(c.last)}):
                    for d, v in zip(dst, values):
                        main.SetTimeSample(d, t, v)
