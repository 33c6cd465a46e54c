"""A crowd's configuration: what the user authors (paper s.4.1 ``UserConfig``).

``CrowdConfig = (skeletons, clips, StreamPool, UniquePool, NT, M, agents, ...)``.
It is plain data; :func:`validate_config` checks it (``Crowd`` calls it before
building the runtime).
:mod:`.config_io` saves and loads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from ..runtime.agents import assign_offsets, assign_streams, check_offsets
from ..meshes.bodies import MAX_PROPS
from ..anim.controllers import Controller
from ..base.errors import CrowdError
from ..meshes.lod import DEFAULT_LOD_PIXELS
from .show import Show
from ..runtime.transitions import WHEN_FULL

__all__ = ["AnimationDef", "CrowdConfig", "validate_config", "WHEN_FULL", "MAX_TREE_DEPTH",
           "USD_LAYOUTS", "MAX_SUBSTEPS"]

#: What a transition request does when every slot is busy: wait, or switch at once.
#: How a USD export lays its agents out (docs/usd_export.md): ``instanced`` (renderers
#: share each character's prototype) or ``blender`` (not instanceable, which Blender's
#: USD importer needs to animate them). Here so that the command line and the panel
#: offer the choice without importing pxr.
USD_LAYOUTS = ("instanced", "blender")
#: The most samples per frame a crowd keeps for writers (``Crowd(..., substeps=N)``).
MAX_SUBSTEPS = 16
#: Palette colours an agent carries (one per palette material of its character, at
#: most this many: the GPU packs them in one texel).
PALETTE_COLUMNS = 4
#: The longest pose history M (frames): offsets travel to the GPU in 16 bits.
MAX_OFFSET = 65535
#: The deepest controller tree (levels below the root) a crowd accepts.
MAX_TREE_DEPTH = 64


@dataclass
class AnimationDef:
    """A stream (shared, with pose history) or unique animation: a named controller tree.

    A stream plays its tree at ``speed`` times the crowd's rate from ``phase`` crowd
    frames in: at frame ``F`` its root time is ``phase + speed * F`` (speed 1, phase 0:
    the frame itself). Streams generated from one template for timing variation
    (:mod:`.variety`) differ only in these, and name it in ``template`` (empty: the
    stream is its own template). Uniques keep their own clocks (speed 1, phase 0
    only)."""

    name: str
    skeleton: str
    root: Controller
    speed: float = 1.0
    phase: float = 0.0
    template: str = ""

    @property
    def template_name(self) -> str:
        """The authored stream this one was made from (its own name when none)."""
        return self.template or self.name

    def __post_init__(self):
        if not str(self.name).strip():
            raise CrowdError(f"an animation on skeleton {self.skeleton!r} has an empty name "
                             f"({self.name!r}); name each stream and unique")
        speed, phase = float(self.speed), float(self.phase)
        if not (np.isfinite(speed) and speed > 0):
            raise CrowdError(f"stream {self.name!r}: speed must be a finite number > 0, got "
                             f"{self.speed!r}")
        if not np.isfinite(phase):
            raise CrowdError(f"stream {self.name!r}: phase must be finite, got {self.phase!r}")
        self.speed, self.phase = speed, phase


@dataclass
class CrowdConfig:
    """Everything needed to build a crowd.

    Attributes
    ----------
    skeletons : dict name -> Skeleton.
    clips : dict name -> Clip.
    streams : list of AnimationDef (the StreamPool).
    uniques : list of AnimationDef (the UniquePool).
    max_offset : M, frames of pose history per stream (offsets are 0..M-1).
    transition_slots : NT.
    fps : crowd frame rate. Controller times (a clip player's start and speed, layer
        reference frames, transition durations) are frames at this rate; each clip
        plays at its own ``Clip.fps`` (docs/architecture.md, Conventions).
    seed : seed used by the agent helpers.
    when_full : ``"queue"`` or ``"cut"``, default for transition requests when all
        slots are busy.
    max_texture_size : GPU texture limit used to lay out the pose texture.
    start_frame : the frame ``Crowd.reset()`` starts at.
    agent_stream : (N,) int stream per agent, ``-1`` for agents on a unique.
    agent_unique : (N,) int unique per agent, ``-1`` for streamed agents.
    agent_offset : (N,) int offsets (also kept for unique agents: used when they go
        back to a stream without an explicit offset).
    agent_position : (N, 3) float32 world positions (metres); agent_heading : (N,)
        radians about +Z; agent_color : (N, 3) float32 colour variation 0..1;
        agent_scale : (N,) float32 uniform scale of each agent's body (empty: all 1;
        :attr:`scales`); agent_palette : (N, 4, 3) float32 the colour each agent's
        body takes on its character's palette materials (-1: none; empty: none at
        all; :attr:`palette`).
    palette_materials : dict skeleton -> tuple of material names: the materials its
        agents' ``agent_palette`` columns colour, in column order.
    meshes : dict skeleton -> list of ProxyMesh, its body's LOD levels (mesh variant
        0; :meth:`add_mesh`); variants : dict skeleton -> list of such lists, its
        further mesh variants 1, 2, ... (:meth:`add_variant`); props : dict skeleton
        -> list of :class:`~.bodies.Prop` (:meth:`add_prop`); agent_variant : (N,)
        int16 each agent's mesh variant (empty: all 0; :attr:`variant_ids`);
        agent_props : (N,) uint8 the props each agent carries, a bit per prop of its
        character (empty: none; :attr:`prop_masks`). See :mod:`.bodies`.
    show : :class:`~.show.Show`, the cues, reactions and animated parameters the crowd
        runs itself before each step (empty by default).
    look_rigs : dict skeleton -> :class:`~.look_at.LookRig`, how its agents turn their
        heads; look_targets : dict name -> :class:`~.look_at.LookTarget`, the points
        they can look at (a ``look`` cue, ``Crowd.look_at``); look_lag : ``"offset"``
        (each agent sees the target as late as its animation offset) or ``"seeded"``
        (a seeded delay of up to ``look_max_lag`` frames). See :mod:`.look_at`.
    """

    skeletons: dict = field(default_factory=dict)
    clips: dict = field(default_factory=dict)
    streams: list = field(default_factory=list)
    uniques: list = field(default_factory=list)
    max_offset: int = 60
    transition_slots: int = 64
    fps: float = 30.0
    seed: int = 0
    when_full: str = "queue"
    max_texture_size: int = 16384
    start_frame: int = 0
    agent_stream: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    agent_unique: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    agent_offset: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    agent_position: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    agent_heading: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    agent_color: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    agent_scale: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    agent_palette: np.ndarray = field(
        default_factory=lambda: np.zeros((0, PALETTE_COLUMNS, 3), np.float32))
    palette_materials: dict = field(default_factory=dict)
    meshes: dict = field(default_factory=dict)
    variants: dict = field(default_factory=dict)
    props: dict = field(default_factory=dict)
    agent_variant: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int16))
    agent_props: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8))
    lod_pixels: tuple = DEFAULT_LOD_PIXELS
    lod_distances: tuple | None = None
    lod_budget_px: float = 1.0
    show: Show = field(default_factory=Show)
    look_rigs: dict = field(default_factory=dict)
    look_targets: dict = field(default_factory=dict)
    look_lag: str = "offset"
    look_max_lag: int = 12

    # authoring helpers ---------------------------------------------------------
    def add_skeleton(self, skeleton):
        if skeleton.name in self.skeletons:
            raise CrowdError(f"skeleton {skeleton.name!r} already exists")
        self.skeletons[skeleton.name] = skeleton
        return skeleton

    def add_clip(self, clip):
        if clip.name in self.clips:
            raise CrowdError(f"clip {clip.name!r} already exists")
        self.clips[clip.name] = clip
        return clip

    def add_mesh(self, mesh, lods=(0.25, 0.06, "card", "card")):
        """Set ``mesh`` as its skeleton's proxy, with LODs built at ``lods`` triangle
        ratios and, last, ``"card"`` for each far level (:func:`~.levels.parts_lod`: a box
        per body part, then with small parts joined; ``()`` for none), or ready
        :class:`~.mesh.ProxyMesh` levels (of the same skeleton), optionally followed by
        ``"card"`` (the far level of ``mesh``). LOD ``k`` is drawn once the agent is
        shorter than ``lod_pixels[k - 1]`` pixels (:mod:`.lod`).

        Every automatic level is checked over the poses of the skeleton's clips added
        so far at the size it is switched in at (:func:`.lod_check.fit_levels`): each
        decimated level is the lightest of a few tries whose silhouette strays from the
        full mesh's by at most ``lod_budget_px`` (1 pixel; ``inf``: no check); a level
        none of whose tries passes is replaced by the level before it, and a note
        saying so is added to :attr:`lod_notes` (the bake and the CLI print them).
        Levels an artist made are kept as made."""
        levels = self._levels(mesh, lods)
        self.meshes[mesh.skeleton] = levels
        return levels

    def add_variant(self, mesh, lods=(0.25, 0.06, "card", "card")):
        """Add ``mesh`` as a further mesh variant of its skeleton (after the body of
        :meth:`add_mesh`, which must be set); ``lods`` as for :meth:`add_mesh`. Returns
        the variant's index."""
        if not self.meshes.get(mesh.skeleton):
            raise CrowdError(f"mesh variant {mesh.name!r}: skeleton {mesh.skeleton!r} has no "
                             "body yet (add_mesh first: it is variant 0)")
        names = [lv[0].name for lv in self.mesh_variants(mesh.skeleton)]
        if mesh.name in names:
            raise CrowdError(f"mesh variant {mesh.name!r}: skeleton {mesh.skeleton!r} has a "
                             f"variant of that name already ({names})")
        self.variants.setdefault(mesh.skeleton, []).append(self._levels(mesh, lods))
        return len(names)

    def mesh_variants(self, skeleton: str) -> list:
        """The LOD level lists of ``skeleton``'s mesh variants, variant 0 first (empty
        when it has no mesh)."""
        first = self.meshes.get(skeleton)
        return [first, *self.variants.get(skeleton, [])] if first else []

    def add_prop(self, prop):
        """Add a :class:`~.bodies.Prop` to its skeleton; returns its index (its bit in
        ``agent_props``)."""
        if prop.skeleton not in self.skeletons:
            raise CrowdError(f"prop {prop.name!r}: unknown skeleton {prop.skeleton!r} "
                             f"(known: {sorted(self.skeletons)})")
        self._check_mesh(prop.mesh, f"prop {prop.name!r}: ")
        have = self.props.setdefault(prop.skeleton, [])
        if prop.name in [p.name for p in have]:
            raise CrowdError(f"prop {prop.name!r}: skeleton {prop.skeleton!r} has a prop of "
                             "that name already")
        if len(have) >= MAX_PROPS:
            raise CrowdError(f"prop {prop.name!r}: skeleton {prop.skeleton!r} has "
                             f"{MAX_PROPS} props already, the most a character has")
        have.append(prop)
        return len(have) - 1

    def _levels(self, mesh, lods) -> list:
        from ..meshes.levels import CARD, parts_lod
        from ..meshes.mesh import ProxyMesh
        self._check_mesh(mesh)
        ready = [m for m in lods if isinstance(m, ProxyMesh)]
        if not ready:
            return self._fitted(mesh, tuple(lods))
        else:
            lods = list(lods)
            rest = lods[len(ready):]
            if not all(isinstance(m, ProxyMesh) for m in lods[:len(ready)]) \
                    or not (rest == [] or (len(rest) == 1 and isinstance(rest[0], str)
                                           and rest[0] == CARD)):
                raise CrowdError(f"mesh {mesh.name!r}: LODs are either triangle ratios or "
                                 f"ready meshes, then optionally {CARD!r} (last), got "
                                 f"{[getattr(m, 'name', m) for m in lods]}")
            for k, level in enumerate(ready, start=1):
                if level.skeleton != mesh.skeleton:
                    raise CrowdError(f"mesh {mesh.name!r}: LOD {k} {level.name!r} is for "
                                     f"skeleton {level.skeleton!r}, not {mesh.skeleton!r}")
                self._check_mesh(level, f"mesh {mesh.name!r}: LOD {k}: ")
            # levels an artist made are kept as made: the silhouette check judges the
            # automatic ones
            return [mesh, *ready] + ([parts_lod(mesh)] if rest else [])

    @property
    def lod_notes(self) -> list:
        """What the silhouette check of :meth:`add_mesh` and :meth:`add_variant` refused
        (one line per level; not saved: loading checks nothing again)."""
        return self.__dict__.setdefault("_lod_notes", [])

    def _fitted(self, mesh, lods) -> list:
        """``mesh``'s automatic levels, each the lightest that passes the silhouette check
        at its switch size (:func:`.lod_check.fit_levels`)."""
        from ..meshes.lod import switch_pixels
        from ..meshes.lod_check import clip_poses, fit_levels
        sk = self.skeletons[mesh.skeleton]
        levels, notes = fit_levels(mesh, lods, sk, clip_poses(sk, self.clips.values()),
                                   switch_pixels(self), float(self.lod_budget_px))
        self.lod_notes.extend(f"mesh {mesh.name!r}: {n}" for n in notes)
        return levels

    def _check_mesh(self, mesh, what=""):
        if mesh.skeleton not in self.skeletons:
            raise CrowdError(f"{what}mesh {mesh.name!r}: unknown skeleton {mesh.skeleton!r} "
                             f"(known: {sorted(self.skeletons)})")
        bones = self.skeletons[mesh.skeleton].bone_count
        if int(mesh.bone_indices.max()) >= bones:
            raise CrowdError(f"{what}mesh {mesh.name!r}: uses bone "
                             f"{int(mesh.bone_indices.max())} but skeleton {mesh.skeleton!r} "
                             f"has {bones} bones")

    def add_stream(self, name, skeleton, root, speed=1.0, phase=0.0, template=""):
        self.streams.append(AnimationDef(str(name), str(skeleton), root, speed, phase,
                                         str(template)))
        return len(self.streams) - 1

    def add_unique(self, name, skeleton, root):
        self.uniques.append(AnimationDef(str(name), str(skeleton), root))
        return len(self.uniques) - 1

    def without_agents(self) -> "CrowdConfig":
        """A copy of this configuration without its agents: every per-agent array
        (``agent_*``) empty, the rest shared."""
        empty = CrowdConfig()
        return replace(self, **{f.name: getattr(empty, f.name) for f in fields(self)
                                if f.name.startswith("agent_")})

    @property
    def agent_count(self) -> int:
        return int(self.agent_offset.shape[0])

    @property
    def palette(self) -> np.ndarray:
        """(N, 4, 3) float32 palette colours per agent: :attr:`agent_palette`, or -1
        (none) when it is empty."""
        p = np.asarray(self.agent_palette, np.float32).reshape(-1, PALETTE_COLUMNS, 3)
        return p if p.shape[0] else np.full((self.agent_count, PALETTE_COLUMNS, 3), -1.0,
                                            np.float32)

    @property
    def variant_ids(self) -> np.ndarray:
        """(N,) int16 mesh variant per agent: :attr:`agent_variant`, or zeros."""
        v = np.asarray(self.agent_variant, np.int16).reshape(-1)
        return v if v.size else np.zeros(self.agent_count, np.int16)

    @property
    def prop_masks(self) -> np.ndarray:
        """(N,) uint8 props per agent (a bit each): :attr:`agent_props`, or zeros."""
        m = np.asarray(self.agent_props, np.uint8).reshape(-1)
        return m if m.size else np.zeros(self.agent_count, np.uint8)

    @property
    def scales(self) -> np.ndarray:
        """(N,) float32 scale per agent: :attr:`agent_scale`, or ones when it is empty."""
        s = np.asarray(self.agent_scale, np.float32).reshape(-1)
        return s if s.size else np.ones(self.agent_count, np.float32)

    def add_agents(self, count, streams=None, stream_weights=None, offsets="uniform",
                   offset_mean=None, offset_std=None, positions=None, headings=None,
                   colors=None, seed=None, scales=None, palette=None, variants=None,
                   props=None):
        """Append ``count`` streamed agents.

        ``streams``: None (all streams, drawn with ``stream_weights``), an int, a
        name, or an array of stream indices per agent. ``offsets``: ``"uniform"``,
        ``"normal"`` or an array. ``variants``: each agent's mesh variant, ``props``
        the props it carries (a bit per prop of its character; :mod:`.bodies`); None:
        variant 0 and no props. Returns the new agents' ids.
        """
        seed = self.seed + self.agent_count if seed is None else seed
        names = [s.name for s in self.streams]
        if streams is None:
            st = assign_streams(count, len(self.streams), stream_weights, seed)
        elif isinstance(streams, (str, int, np.integer)):
            idx = names.index(streams) if isinstance(streams, str) and streams in names \
                else streams
            if isinstance(idx, str) or not 0 <= int(idx) < len(names):
                raise CrowdError(f"agents: unknown stream {streams!r}")
            st = np.full(count, int(idx), np.int32)
        else:
            st = np.asarray(streams, np.int32)
            if st.shape != (count,):
                raise CrowdError(f"agents: {st.shape} streams for {count} agents")
        if isinstance(offsets, str):
            off = assign_offsets(count, self.max_offset, offsets, seed + 1, offset_mean,
                                 offset_std)
        else:
            off = assign_offsets(count, self.max_offset, "given", offsets=offsets)
        pos = np.zeros((count, 3), np.float32) if positions is None else \
            np.asarray(positions, np.float32).reshape(count, 3)
        head = np.zeros(count, np.float32) if headings is None else \
            np.asarray(headings, np.float32).reshape(count)
        if colors is None:
            col = np.random.default_rng(seed + 2).uniform(0.35, 1.0, (count, 3))
        else:
            col = np.asarray(colors, np.float32).reshape(count, 3)
        first = self.agent_count
        if scales is not None or np.asarray(self.agent_scale).size:
            old = self.scales
            new = np.ones(count, np.float32) if scales is None else \
                np.asarray(scales, np.float32).reshape(count)
            self.agent_scale = np.concatenate([old, new]).astype(np.float32)
        for name, given, dtype in (("agent_variant", variants, np.int16),
                                   ("agent_props", props, np.uint8)):
            if given is not None or np.asarray(getattr(self, name)).size:
                old = self.variant_ids if name == "agent_variant" else self.prop_masks
                arr = np.zeros(count, np.int64) if given is None else \
                    np.asarray(given).reshape(count)
                top = np.iinfo(dtype).max
                if arr.size and not (np.issubdtype(arr.dtype, np.integer)
                                     and 0 <= arr.min() and arr.max() <= top):
                    raise CrowdError(f"agents: {name[6:]} must be integers in 0..{top}, got "
                                     f"{arr.dtype} {arr.min()}..{arr.max()}")
                new = arr.astype(dtype)
                setattr(self, name, np.concatenate([old, new]).astype(dtype))
        if palette is not None or np.asarray(self.agent_palette).size:
            old = self.palette
            new = np.full((count, PALETTE_COLUMNS, 3), -1.0, np.float32) if palette is None \
                else np.asarray(palette, np.float32).reshape(count, PALETTE_COLUMNS, 3)
            self.agent_palette = np.concatenate([old, new]).astype(np.float32)
        self.agent_stream = np.concatenate([self.agent_stream, st]).astype(np.int32)
        self.agent_unique = np.concatenate([self.agent_unique,
                                            np.full(count, -1, np.int32)]).astype(np.int32)
        self.agent_offset = np.concatenate([self.agent_offset, off]).astype(np.int32)
        self.agent_position = np.concatenate([self.agent_position, pos]).astype(np.float32)
        self.agent_heading = np.concatenate([self.agent_heading, head]).astype(np.float32)
        self.agent_color = np.concatenate([self.agent_color, col]).astype(np.float32)
        return np.arange(first, first + count)


class _ClipLookup:
    """What a controller may look up while it is validated: ``skeleton`` (the tree's),
    ``fps`` (the crowd's) and :meth:`clip`, which also checks that the clip's bones
    are the skeleton's and records the clips looked up (``used``)."""

    def __init__(self, cfg, skeleton, used):
        self.cfg, self.skeleton, self.fps = cfg, skeleton, float(cfg.fps)
        self.used = used

    def clip(self, name):
        """The clip ``name``; CrowdError when it does not exist or its bone names (or,
        without names, its bone count) do not match the skeleton."""
        try:
            clip = self.cfg.clips[name]
        except KeyError:
            raise CrowdError(f"unknown clip {name!r} (known: {sorted(self.cfg.clips)})") \
                from None
        clip.bone_order(self.skeleton)
        self.used.setdefault(name, None)
        return clip


def validate_config(cfg: CrowdConfig) -> dict:
    """Raise :class:`CrowdError` naming the first thing wrong with ``cfg``: sizes, names,
    every controller of every stream and unique (clips they play must exist and have
    the bones of the skeleton that plays them, see ``Clip.bone_order``), agent arrays
    and references.

    Returns the clips each skeleton plays: ``{skeleton name: [clip names]}`` (first use
    first), what ``Crowd`` prepares its clip bank for."""
    if not cfg.skeletons:
        raise CrowdError("crowd: needs at least one skeleton")
    if not cfg.streams and not cfg.uniques:
        raise CrowdError("crowd: needs at least one stream or unique animation")
    for what, value, least in (("max offset M", cfg.max_offset, 1),
                               ("transition slots NT", cfg.transition_slots, 0)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                or value < least:
            raise CrowdError(f"crowd: {what} must be a whole number >= {least}, got "
                             f"{value!r}")
    if cfg.max_offset > MAX_OFFSET:
        raise CrowdError(f"crowd: max offset M must be at most {MAX_OFFSET} frames, got "
                         f"{cfg.max_offset}")
    if not (np.isfinite(cfg.fps) and cfg.fps > 0):
        raise CrowdError(f"crowd: fps must be positive, got {cfg.fps}")
    if cfg.when_full not in WHEN_FULL:
        raise CrowdError(f"crowd: when_full must be one of {WHEN_FULL}, got "
                         f"{cfg.when_full!r}")
    for name, sk in cfg.skeletons.items():
        if sk.name != name:
            raise CrowdError(f"crowd: skeleton stored as {name!r} is named {sk.name!r}")
    for name, clip in cfg.clips.items():
        if clip.name != name:
            raise CrowdError(f"crowd: clip stored as {name!r} is named {clip.name!r}")
    uses = _validate_animations(cfg)
    _validate_agents(cfg)
    _check_looks(cfg)
    return uses


def _check_looks(cfg):
    """Look rigs bind to their skeletons' bones; look targets are named as keyed."""
    from ..runtime.look_at import LookChain, LookRig, LookTarget, agent_lags
    for name, rig in cfg.look_rigs.items():
        if name not in cfg.skeletons:
            raise CrowdError(f"look rig: unknown skeleton {name!r} (known: "
                             f"{sorted(cfg.skeletons)})")
        if not isinstance(rig, LookRig):
            raise CrowdError(f"look rig of skeleton {name!r}: must be a LookRig, got "
                             f"{type(rig).__name__}")
        LookChain(rig, cfg.skeletons[name])
    for name, target in cfg.look_targets.items():
        if not isinstance(target, LookTarget) or target.name != name:
            raise CrowdError(f"look target {name!r}: must be a LookTarget of that name")
    agent_lags(np.zeros(1), cfg.look_lag, cfg.look_max_lag)


def _validate_animations(cfg):
    seen = set()
    uses = {}
    for pool, defs in (("stream", cfg.streams), ("unique", cfg.uniques)):
        for d in defs:
            if d.name in seen:
                raise CrowdError(f"crowd: duplicate animation name {d.name!r}")
            seen.add(d.name)
            if d.skeleton not in cfg.skeletons:
                raise CrowdError(f"{pool} {d.name!r}: unknown skeleton {d.skeleton!r}")
            speed, phase = float(d.speed), float(d.phase)
            if not (np.isfinite(speed) and speed > 0 and np.isfinite(phase)):
                raise CrowdError(f"{pool} {d.name!r}: speed must be finite and > 0 and "
                                 f"phase finite, got speed {d.speed!r}, phase {d.phase!r}")
            if pool == "unique" and ((speed, phase) != (1.0, 0.0) or d.template):
                raise CrowdError(f"unique {d.name!r}: uniques keep their own clocks; speed, "
                                 f"phase and template are for streams (got {speed:g}, "
                                 f"{phase:g}, {d.template!r})")
            lookup = _ClipLookup(cfg, cfg.skeletons[d.skeleton],
                                 uses.setdefault(d.skeleton, {}))
            stack = [(d.root, 0)]
            while stack:
                node, depth = stack.pop()
                if depth > MAX_TREE_DEPTH:
                    raise CrowdError(f"{pool} {d.name!r}: controllers nested deeper than "
                                     f"{MAX_TREE_DEPTH} levels")
                try:
                    node.validate(lookup)
                except CrowdError as e:
                    raise CrowdError(f"{pool} {d.name!r}: {e}") from None
                stack.extend((c, depth + 1) for c in node.children())
    return {skeleton: list(names) for skeleton, names in uses.items()}


def _validate_agents(cfg):
    n = cfg.agent_offset.shape[0]
    for field_name in ("agent_stream", "agent_unique"):
        if getattr(cfg, field_name).shape != (n,):
            raise CrowdError(f"crowd: {field_name} has shape "
                             f"{getattr(cfg, field_name).shape}, expected ({n},)")
    pal = np.asarray(cfg.agent_palette)
    if pal.size and pal.shape != (n, PALETTE_COLUMNS, 3):
        raise CrowdError(f"crowd: agent_palette must be ({n}, {PALETTE_COLUMNS}, 3) or empty, "
                         f"got {pal.shape}")
    if pal.size and not (np.isfinite(pal).all() and (pal <= 1).all()
                         and ((pal >= 0).all(2) | (pal == -1).all(2)).all()):
        raise CrowdError("crowd: agent_palette colours must be in 0..1 (or -1 -1 -1: none)")
    for skel, names in cfg.palette_materials.items():
        if skel not in cfg.skeletons or len(names) > PALETTE_COLUMNS:
            raise CrowdError(f"crowd: palette_materials: unknown skeleton {skel!r} or more "
                             f"than {PALETTE_COLUMNS} materials ({list(names)})")
    scale = np.asarray(cfg.agent_scale)
    if scale.size and scale.shape != (n,):
        raise CrowdError(f"crowd: agent_scale must be ({n},) or empty, got {scale.shape}")
    bad = np.flatnonzero(~(np.isfinite(scale) & (scale > 0))) if scale.size else []
    if len(bad):
        raise CrowdError(f"agent {int(bad[0])}: agent_scale must be finite and > 0, got "
                         f"{float(scale[bad[0]])!r}")
    for field_name, shape in (("agent_position", (n, 3)), ("agent_heading", (n,)),
                              ("agent_color", (n, 3))):
        arr = np.asarray(getattr(cfg, field_name))
        if arr.shape != shape:
            raise CrowdError(f"crowd: {field_name} must be {shape}, got {arr.shape}")
        finite = np.isfinite(arr)
        bad = np.flatnonzero(~(finite if finite.ndim == 1 else finite.all(axis=1)))
        if bad.size:
            raise CrowdError(f"agent {int(bad[0])}: {field_name} is not finite "
                             f"({arr[bad[0]].tolist()})")
    check_offsets(cfg.agent_offset, int(cfg.max_offset))
    st, un = np.asarray(cfg.agent_stream), np.asarray(cfg.agent_unique)
    both = (st >= 0) == (un >= 0)
    if both.any():
        a = int(np.flatnonzero(both)[0])
        raise CrowdError(f"agent {a}: needs exactly one of a stream or a unique "
                         f"(stream {st[a]}, unique {un[a]})")
    bad = np.flatnonzero(st >= len(cfg.streams))
    if bad.size:
        raise CrowdError(f"agent {int(bad[0])}: unknown stream index {st[bad[0]]} "
                         f"({len(cfg.streams)} streams)")
    bad = np.flatnonzero(un >= len(cfg.uniques))
    if bad.size:
        raise CrowdError(f"agent {int(bad[0])}: unknown unique index {un[bad[0]]} "
                         f"({len(cfg.uniques)} uniques)")
    _validate_bodies(cfg, st, un)


def _validate_bodies(cfg, st, un):
    """Each agent's mesh variant and props exist for its character."""
    n = st.shape[0]
    for name in ("agent_variant", "agent_props"):
        arr = np.asarray(getattr(cfg, name))
        if arr.size and arr.shape != (n,):
            raise CrowdError(f"crowd: {name} must be ({n},) or empty, got {arr.shape}")
    for skel, props in cfg.props.items():
        if skel not in cfg.skeletons or len(props) > MAX_PROPS:
            raise CrowdError(f"crowd: props: unknown skeleton {skel!r} or more than "
                             f"{MAX_PROPS} props")
    for skel in cfg.variants:
        if not cfg.meshes.get(skel):
            raise CrowdError(f"crowd: skeleton {skel!r} has mesh variants but no body "
                             "(variant 0: CrowdConfig.add_mesh)")
    if not (np.asarray(cfg.agent_variant).size or np.asarray(cfg.agent_props).size):
        return
    names = list(cfg.skeletons)
    owner = [names.index(d.skeleton) for d in cfg.streams] or [0]
    own_u = [names.index(d.skeleton) for d in cfg.uniques] or [0]
    skel = np.where(st >= 0, np.asarray(owner)[np.clip(st, 0, None)],
                    np.asarray(own_u)[np.clip(un, 0, None)])
    variant, mask = cfg.variant_ids.astype(np.int64), cfg.prop_masks.astype(np.int64)
    count = np.array([max(1, len(cfg.mesh_variants(k))) for k in names])
    props = np.array([len(cfg.props.get(k, ())) for k in names])
    bad = np.flatnonzero((variant < 0) | (variant >= count[skel]))
    if bad.size:
        a = int(bad[0])
        raise CrowdError(f"agent {a}: mesh variant {int(variant[a])}, but character "
                         f"{names[skel[a]]!r} has variants 0..{count[skel[a]] - 1}")
    bad = np.flatnonzero(mask >> props[skel])
    if bad.size:
        a = int(bad[0])
        raise CrowdError(f"agent {a}: carries props {int(mask[a]):#b}, but character "
                         f"{names[skel[a]]!r} has {props[skel[a]]} props")
