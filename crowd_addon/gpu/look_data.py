"""Look-at on the GPU (core/runtime/look_at.py): the data the shaders read
(``gpu_shaders/looks.glsl``). Each frame a compute pass works out every looking
agent's turns once (``look_turns_comp.glsl``, :data:`~.programs.LOOK_TURNS`) into the
``look_turns`` texture (:data:`~.programs.LOOK_TURN_TEXELS` texels per agent,
block-laid: per chain depth the rows ``[R | t]`` of its turn), and the draws' vertex
stage applies them (``look_at.glsl``).

Three textures the CPU writes, none of them per frame:

* ``looks`` (RGBA32F, two texels per agent, block-laid like the agent texture):
  ``(target, start, blend, stop)`` -- the agent's :class:`~..core.look_at.AgentLooks`
  state, target -1 for none, ``stop`` held at :data:`NEVER` when the look stays -- and
  ``(lag, skeleton, 0, 0)``. Written at the start, then only the rows of agents whose
  state differs after ``looks.version`` moved (a look started or stopped).
* ``look_targets``: the look targets' smoothed paths, known for the whole shot,
  uploaded once: row 0 holds per target ``(first frame, frames, rows, first row)``,
  then each target's frames ``W`` a row from its first row on (``W`` the width).
* ``look_chains``: a row per skeleton: texel 0 ``(K, yaw limit, pitch limit, 0)``,
  texel 1 ``(forward x, y, 0, 0)``, texels ``2 + 2k`` ``(bind pivot xyz, share)`` and
  ``3 + 2k`` ``(bone, 0, 0, 0)`` of chain bone ``k``. Which influences of a vertex the
  look turns rides on the vertex itself (``look_depth``, :func:`.proxies.look_depths`).

The frame goes in ``u_pose_regions.w`` (:meth:`~.frame_plan.FramePlan.pose_regions`),
so a frame uploads nothing for the looks: each agent's weight and where it sees its
target are worked out by the shader from these and the frame.
"""

from __future__ import annotations

import numpy as np

from ..core.base.errors import CrowdError
from ..core.runtime.pose_storage import block_layout
from .programs import LOOK_TURN_TEXELS
from .texture_region import block_image, block_regions

__all__ = ["LookData", "LOOK_TEXELS", "NEVER", "MAX_LOOK_BONES"]

#: RGBA32F texels per agent in the looks texture.
LOOK_TEXELS = 2
#: ``stop`` of a look that stays (float32, beyond any frame)
NEVER = 1.0e30
#: the longest look chain the shader turns (gpu_shaders/looks.glsl, LOOK_BONES)
MAX_LOOK_BONES = 8
_EXACT = 2 ** 24                    # integers a float32 holds exactly
_STAYS = 2 ** 60                    # AgentLooks' stop of a look that stays is beyond


class LookData:
    """The look textures of a crowd (module doc) and their changes.

    ``records`` (N, 2, 4) float32; ``block_rows``, ``blocks``, ``width``, ``height``
    of the looks texture; ``targets_image``, ``chains_image`` (H, W, 4) float32;
    ``turns_size`` (width, height) of the look turns texture the GPU writes.
    """

    def __init__(self, view, max_texture_size: int = 16384):
        n = view.agent_count
        limit = int(max_texture_size)
        self.count = n
        self.block_rows, self.blocks, self.width = block_layout(n, LOOK_TEXELS, limit,
                                                                "looks texture")
        self.height = self.block_rows
        rows, _, width = block_layout(n, LOOK_TURN_TEXELS, limit, "look turns texture")
        self.turns_size = (width, rows)
        lags = np.asarray(view.look_lags, np.int64)
        if lags.size and (lags.min() <= -_EXACT or lags.max() >= _EXACT):
            raise CrowdError("look lags must stay below 2**24 frames on the GPU")
        self.records = np.zeros((n, LOOK_TEXELS, 4), np.float32)
        self.records[:, 1, 0] = lags
        self.records[:, 1, 1] = view.agent_skeleton
        self._state = None
        self._version = None
        #: frames [first, end) within which some agent's look may weigh above 0
        self._window = (0.0, 0.0)
        self.targets_image = _targets_image(view.look_targets, limit)
        self.chains_image = _chains_image(view.look_chains, limit)
        self.update(view)

    def active(self, frame) -> bool:
        """Whether some agent may look at ``frame`` (a look's weight is 0 before its
        start and from its stop plus its blend on): draws of a frame where none does
        can leave the look out of the vertex stage (``LOOKS 0``), which llvmpipe
        otherwise runs for every vertex, looking or not (masked SIMD lanes)."""
        return self._window[0] <= float(frame) < self._window[1]

    def looking(self, frame) -> np.ndarray:
        """``(N,)`` bool: the agents whose look may weigh above 0 at ``frame`` (its
        start up to its stop plus its blend), for drawing them apart."""
        s, f = self._state, float(frame)
        return (s[:, 0] >= 0) & (s[:, 1] <= f) & \
            (f < s[:, 3].astype(np.float64) + np.maximum(s[:, 2], 0.0))

    def texture_image(self) -> np.ndarray:
        """The whole looks texture ``(height, width, 4)`` float32."""
        return block_image(self.records, self.block_rows, self.blocks)

    def update(self, view, max_regions: int | None = 1024) -> list:
        """Regions of the looks texture to write: none unless ``looks.version`` moved
        since the last call, then the rows of the agents whose state differs."""
        looks = view.looks
        if looks.version == self._version:
            return []
        self._version = looks.version
        stays = looks.stop >= _STAYS
        state = np.stack([looks.target.astype(np.float64), looks.start.astype(np.float64),
                          looks.blend.astype(np.float64),
                          np.where(stays, NEVER, looks.stop.astype(np.float64))], 1)
        on = looks.target >= 0
        if on.any():
            frames = np.r_[looks.start[on], looks.stop[on & ~stays]]
            if np.abs(frames).max(initial=0) >= _EXACT:
                raise CrowdError("look frames must stay below 2**24 on the GPU")
        self._window = (float(state[on, 1].min()), float((state[on, 3] + np.maximum(
            state[on, 2], 0.0)).max())) if on.any() else (0.0, 0.0)
        state = state.astype(np.float32)
        changed = np.arange(self.count) if self._state is None \
            else np.flatnonzero((state != self._state).any(1))
        self._state = state
        if changed.size == 0:
            return []
        self.records[changed, 0] = state[changed]
        return block_regions(self.records, changed, self.block_rows, max_regions)


def _targets_image(targets, limit: int) -> np.ndarray:
    """Row 0: per target ``(first, frames, rows, first row)``; then the paths."""
    paths = [np.asarray(t.smoothed(), np.float32) for t in targets]
    width = max(1, len(paths), min(limit, max((p.shape[0] for p in paths), default=1)))
    if len(paths) > limit:
        raise CrowdError(f"{len(paths)} look targets exceed the max texture size {limit}")
    rows = [-(-p.shape[0] // width) for p in paths]
    height = 1 + sum(rows)
    if height > limit:
        raise CrowdError(f"look targets' paths need {height} texture rows, the max "
                         f"texture size is {limit}")
    img = np.zeros((height, width, 4), np.float32)
    row = 1
    for t, (target, p, r) in enumerate(zip(targets, paths, rows)):
        if abs(target.first) >= _EXACT:
            raise CrowdError(f"look target {target.name!r}: first frame must stay below "
                             f"2**24 on the GPU")
        img[0, t] = (target.first, p.shape[0], r, row)
        flat = np.zeros((r * width, 4), np.float32)
        flat[:p.shape[0], :3] = p
        img[row:row + r] = flat.reshape(r, width, 4)
        row += r
    return img


def _chains_image(chains, limit: int) -> np.ndarray:
    """A row per skeleton (module doc); K = 0 for a skeleton without a look rig."""
    k_max = max((c.index.size for c in chains if c is not None), default=0)
    if k_max > MAX_LOOK_BONES:
        raise CrowdError(f"a look chain of {k_max} bones: the GPU turns at most "
                         f"{MAX_LOOK_BONES}")
    width = 2 + 2 * k_max
    if width > limit or len(chains) > limit:
        raise CrowdError(f"look chains texture {width} x {len(chains)} exceeds the max "
                         f"texture size {limit}")
    img = np.zeros((max(1, len(chains)), width, 4), np.float32)
    for s, c in enumerate(chains):
        if c is None:
            continue
        k = c.index.size
        img[s, 0, :3] = (k, c.rig.yaw_limit, c.rig.pitch_limit)
        img[s, 1, :2] = c.forward[:2]
        for i in range(k):
            img[s, 2 + 2 * i] = (*c.pivots[i], c.shares[i])
            img[s, 3 + 2 * i, 0] = c.index[i]
    return img
