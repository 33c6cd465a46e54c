"""A crowd's configuration: what the user authors (paper s.4.1 ``UserConfig``).

``CrowdConfig = (skeletons, clips, StreamPool, UniquePool, NT, M, agents, ...)``.
It is plain data; :func:`validate_config` checks it (``Crowd`` calls it before
building the runtime). Its builders of bodies (meshes and their LOD levels, mesh
variants, props) are :mod:`.config_bodies`'s and of agents :mod:`.config_agents`'s
(mixins it inherits). :mod:`.config_io` saves and loads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from ..runtime.agents import check_offsets
from ..meshes.bodies import MAX_PROPS
from ..anim.controllers import Controller
from ..base.errors import CrowdError
from ..meshes.lod import DEFAULT_LOD_PIXELS
from .show import Show
from ..runtime.transitions import WHEN_FULL
from .config_agents import PALETTE_COLUMNS, AgentsMixin
from .config_bodies import BodiesMixin

__all__ = ["AnimationDef", "CrowdConfig", "validate_config", "MAX_TREE_DEPTH", "USD_LAYOUTS",
           "MAX_SUBSTEPS"]

#: How a USD export lays its agents out (docs/usd_export.md): ``instanced`` (renderers
#: share each character's prototype) or ``blender`` (not instanceable, which Blender's
#: USD importer needs to animate them). Here so that the command line and the panel
#: offer the choice without importing pxr.
USD_LAYOUTS = ("instanced", "blender")
#: The most samples per frame a crowd keeps for writers (``Crowd(..., substeps=N)``).
MAX_SUBSTEPS = 16
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
class CrowdConfig(BodiesMixin, AgentsMixin):
    """Everything needed to build a crowd.

    Meshes, mesh variants and props are added with the methods of
    :class:`~.config_bodies.BodiesMixin` (:meth:`add_mesh`, :meth:`add_variant`,
    :meth:`add_prop`), agents with those of :class:`~.config_agents.AgentsMixin`
    (:meth:`add_agents`).

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
