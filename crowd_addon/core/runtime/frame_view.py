"""The read-only view of a crowd's current frame that renderers and writers use.

``crowd.view`` (a :class:`FrameView`) is everything ``gpu/``, ``usd/`` and the demo
read from a running :class:`~crowd_addon.core.shots.crowd.Crowd`: sizes, the pose texture's
layout and changes, the skinning mode, agents and what changed about them, poses on
demand and the event tags the streams crossed. Arrays it returns are read-only views
or fresh copies; nothing here changes the simulation except the two ``take_*`` calls,
which hand over (and so clear) what changed since the last take: a crowd has one GPU
reader (:attr:`FrameView.takes` lets a renderer tell when another took them).
"""

from __future__ import annotations

import numpy as np

from .agents import TRANSITION
from ..base.errors import CrowdError

__all__ = ["FrameView"]


class FrameView:
    """Read-only access to a crowd's current frame (see the module docstring)."""

    def __init__(self, crowd):
        self._crowd = crowd
        #: how many takes handed over changes (:meth:`take_upload_regions`,
        #: :meth:`take_skinning_batch` returning rows): a renderer that finds more than
        #: its own knows another reader took rows it never saw
        self.takes = 0

    # ------------------------------------------------------------------- sizes
    @property
    def frame(self) -> int:
        """The last evaluated frame (int)."""
        return self._crowd.frame

    @property
    def fps(self) -> float:
        return self._crowd.fps

    @property
    def config(self):
        """The :class:`~crowd_addon.core.authoring.config.CrowdConfig` the crowd was built from
        (meshes, LOD distances, start frame); treat it as read-only."""
        return self._crowd.config

    @property
    def layout(self):
        """The pose texture's geometry (:class:`~.pose_storage.PoseLayout`): streams,
        max offset, uniques, slots, bones, rows, texture size, region bases."""
        return self._crowd.storage.layout

    @property
    def skinning(self):
        """The skinning mode (:class:`~.skinning_modes.CpuSkinning` or
        :class:`~.skinning_modes.GpuSkinning`): its ``on_gpu`` says whether the
        uploads are local poses the GPU must skin (with :meth:`take_skinning_batch`)
        or finished skinning rows."""
        return self._crowd.skinning

    @property
    def skeletons(self) -> tuple:
        """The crowd's skeletons, in ``config.skeletons`` order."""
        return tuple(self._crowd.skeletons)

    @property
    def stream_names(self) -> tuple:
        return tuple(self._crowd.streams.names)

    @property
    def unique_names(self) -> tuple:
        return tuple(self._crowd.uniques.names)

    @property
    def stream_skeleton(self) -> np.ndarray:
        """(S,) int64 skeleton index of each stream."""
        return self._crowd.streams.skeleton.copy()

    @property
    def unique_skeleton(self) -> np.ndarray:
        """(U,) int64 skeleton index of each unique animation."""
        return self._crowd.uniques.skeleton.copy()

    @property
    def ring_slice(self) -> int:
        """History slice the current frame was written to (``frame mod M``)."""
        return self._crowd.streams.slice(self._crowd.frame)

    # ------------------------------------------------------------------ agents
    @property
    def agent_count(self) -> int:
        return self._crowd.agents.count

    @property
    def agents(self):
        """The :class:`~.agents.AgentState`; its arrays (kind, ref, offset, position,
        heading, color, scale) are read-only views."""
        return self._crowd.agents

    @property
    def agent_skeleton(self) -> np.ndarray:
        """(N,) int64 skeleton index of each agent (that of the animation it was
        configured with; transitions never change it)."""
        return self._crowd.agent_skeleton.copy()

    @property
    def bodies(self) -> tuple:
        """The :class:`~.bodies.Body` s the agents are drawn with (mesh variant and
        props; :mod:`.bodies`), in :func:`~.bodies.crowd_bodies` order."""
        return self._crowd.bodies[0]

    @property
    def agent_body(self) -> np.ndarray:
        """(N,) int64 each agent's index in :attr:`bodies`."""
        return self._crowd.bodies[1].copy()

    def agent_changes(self, cursor: int):
        """Agents changed since ``cursor`` (:class:`~.agents.AgentChanges`; start with 0)."""
        return self._crowd.agents.changes_since(cursor)

    # ------------------------------------------------------------------- looks
    @property
    def looks(self):
        """The agents' looks (:class:`~.looks.AgentLooks`: per agent ``target``,
        ``start``, ``blend``, ``stop``; read-only). They change only when a look starts
        or stops; ``looks.version`` counts those changes."""
        return self._crowd.looks

    @property
    def look_targets(self) -> tuple:
        """The look targets (:class:`~.look_at.LookTarget`, immutable), in the order
        ``looks.target`` indexes them; ``target.smoothed()`` is the path agents read."""
        return self._crowd.look.targets

    @property
    def look_chains(self) -> tuple:
        """Per skeleton its :class:`~.look_at.LookChain` (None: no look rig)."""
        return self._crowd.look.chains

    @property
    def look_lags(self) -> np.ndarray:
        """(N,) int64 frames each agent reads its look target late (a copy)."""
        return np.array(self._crowd.look.lags, np.int64)

    # -------------------------------------------------------------------- poses
    @property
    def substeps(self) -> int:
        """Samples per frame the crowd keeps (``Crowd(..., substeps=N)``)."""
        return self._crowd.substeps

    def stream_poses(self, frame: int | None = None, sub: int = 0) -> np.ndarray:
        """``(S, B, 10)`` float32 local poses of every stream head at ``frame`` (default
        the current one; one of the last M frames), or at ``frame + sub / substeps``, a
        copy."""
        f = self._crowd.frame if frame is None else int(frame)
        if sub:
            return self._crowd.sub_stream_poses(f, sub)
        return self._crowd.streams.head_poses(f, self._crowd.frame)

    def unique_poses(self, sub: int = 0) -> np.ndarray:
        """``(U, B, 10)`` float32 current poses of the unique animations (at ``frame +
        sub / substeps`` with ``sub``), a copy."""
        if sub:
            return self._crowd.sub_unique_poses(sub)
        return self._crowd.uniques.poses.copy()

    def agent_poses(self, agents=None, sub: int = 0) -> np.ndarray:
        """``(n, B, 10)`` float32 local poses the agents show now (at ``frame + sub /
        substeps`` with ``sub``)."""
        return self._crowd.agent_poses(agents, sub)

    def agent_rows(self, agents=None) -> np.ndarray:
        """``(n, B, 3, 4)`` float32 skinning rows the agents are drawn with now."""
        return self._crowd.agent_rows(agents)

    def agent_rows_index(self, agents=None) -> np.ndarray:
        """``(n,)`` int64 logical pose texture row each agent reads now."""
        return self._crowd.agent_rows_index(agents)

    def transitions(self, agents) -> dict:
        """The transition of each of ``agents`` (k,) that is blending now, as arrays
        (k,): ``start_pose`` (k, B, 10) float32 StartP, ``t0`` int64 start frame,
        ``length`` int64 L in frames, ``target_kind`` int8, ``target_ref`` int64,
        ``target_offset`` int64. An agent not in a transition is an error."""
        c = self._crowd
        agents = c.agents.ids(agents)
        other = agents[c.agents.kind[agents] != TRANSITION]
        if other.size:
            raise CrowdError(f"agent {int(other[0])} is not in a transition")
        return c.slots.describe(c.agents.ref[agents])

    def stream_events(self, since_frame: int):
        """Event tags the stream heads crossed at frames ``>= since_frame`` (at most the
        last M frames are kept): ``(stream (k,) int64, name (k,) object, frame (k,)
        int64)`` in crossing order."""
        return self._crowd.streams.events_since(since_frame)

    # -------------------------------------------------------------- GPU uploads
    def texture_image(self) -> np.ndarray:
        """The whole CPU-side texture ``(height, width, 4)`` float32 (pose rows, or local
        poses when the GPU skins), for a renderer's first upload."""
        return self._crowd.storage.texture_image()

    def take_upload_regions(self) -> list:
        """:class:`~.pose_storage.TextureRegion` rectangles of the CPU-side texture
        written since the last take (which they clear)."""
        regions = self._crowd.storage.take_dirty_regions()
        self.takes += bool(regions)
        return regions

    def take_skinning_batch(self):
        """The pose rows the GPU must write now (:class:`~.skinning_modes.SkinningBatch`)
        with GPU skinning; rows pending since the last take. An error on the CPU mode."""
        batch = self._crowd.skinning.take_batch()
        self.takes += bool(len(batch))
        return batch
