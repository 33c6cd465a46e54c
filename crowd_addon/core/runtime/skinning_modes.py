"""Where local poses become skinning rows: two small types, chosen per crowd.

* :class:`CpuSkinning` (``Crowd(config, skinning="cpu")``): the CPU keeps the pose
  texture of skinning rows (each bone's top three matrix rows, paper Eq. 1) and
  writes the rows that changed: the new history slice, the uniques and the blended
  transition slots. Renderers upload them as they are.
* :class:`GpuSkinning` (``skinning="gpu"``, paper s.4.5): the CPU only evaluates the
  streams and uniques into a *local-pose* texture of the same geometry (the history
  and unique poses are views of it; slot rows hold each transition's StartP) and a
  compute shader turns rows into skinning rows and blends the slots;
  :meth:`GpuSkinning.take_batch` lists the rows it must write. Writers that need
  only local poses (the USD export) use this mode with no GPU at all.

Both give exact skinning rows on demand (:meth:`rows`) for tests and read-backs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base import pose as sqt
from ..base.errors import CrowdError
from .pose_storage import LOCAL_IDENTITY, PoseStorage

__all__ = ["CpuSkinning", "GpuSkinning", "SkinningBatch", "SKINNING_MODES", "skinning_mode"]


@dataclass(frozen=True)
class SkinningBatch:
    """Pose texture rows the GPU writes (:class:`GpuSkinning`); all ``(n,)``.

    Row ``rows[i]`` of the pose texture becomes the skinning rows of the local pose
    ``blend(local[rows[i]], local[sources[i]], weights[i])`` (``local`` = the local-pose
    texture) of skeleton ``skeletons[i]``. A stream or unique row is its own source
    with weight 1; a transition slot row blends its StartP towards the target's row
    by ``S`` (paper s.4.5).

    ``rows``, ``sources`` int32 logical rows; ``weights`` float32; ``skeletons`` int32
    indices into the crowd's skeletons.
    """

    rows: np.ndarray
    sources: np.ndarray
    weights: np.ndarray
    skeletons: np.ndarray

    def __len__(self) -> int:
        return int(self.rows.size)


class _Mode:
    on_gpu = False
    fill = None

    def storage(self, streams, max_offset, uniques, slots, bones, max_texture_size):
        return PoseStorage(streams, max_offset, uniques, slots, bones, max_texture_size,
                           fill=self.fill)

    def bind(self, crowd):
        """Attach to ``crowd`` (its storage, pools, slots and skinning plans)."""
        if getattr(self, "_crowd", None) is not None:
            raise CrowdError(f"{type(self).__name__}: a skinning mode serves one crowd")
        self._crowd = crowd
        self._stream_groups = _groups(crowd.streams.skeleton)
        self._unique_groups = _groups(crowd.uniques.skeleton)

    def reset(self):
        pass

    def restored(self):
        """After a :mod:`.snapshot` was restored into the pools and slots: rebuild what
        this mode derives from them and mark the whole texture for upload."""
        st = self._crowd.storage
        st.take_dirty_regions()
        st.mark_dirty(0, st.row_count)
        self.reset()

    def _skin(self, groups, poses, out):
        """Skinning rows of ``poses`` (k, B, 10) into ``out`` (k, B, 3, 4), by skeleton."""
        plans = self._crowd.plans
        for k, idx, cont in groups:
            if cont is not None:
                plans[k].rows(poses[cont], out=out[cont])
            else:
                out[idx] = plans[k].rows(poses[idx])

    def _skin_poses(self, poses, skeletons) -> np.ndarray:
        out = np.zeros(poses.shape[:2] + (3, 4), np.float32)
        for k in np.unique(skeletons):
            out[skeletons == k] = self._crowd.plans[k].rows(poses[skeletons == k])
        return out

    def take_batch(self):
        raise CrowdError("skinning batch: this crowd skins on the CPU (create it with "
                         "Crowd(config, skinning='gpu'))")


class CpuSkinning(_Mode):
    """The CPU writes skinning rows (see the module docstring)."""

    name = "cpu"

    def history(self, storage, shape):
        return sqt.identity_pose(shape[:3])

    def unique_poses(self, storage, shape):
        return sqt.identity_pose(shape[:2])

    def roots_stored(self, frame: int):
        c, st = self._crowd, self._crowd.storage
        sl = c.streams.slice(frame)
        self._skin(self._stream_groups, c.streams.history[sl], st.stream_slice(sl))
        st.mark_dirty(sl * c.streams.count, c.streams.count)
        self._skin(self._unique_groups, c.uniques.poses, st.unique_rows())
        st.mark_dirty(st.unique_base, c.uniques.count)

    def blend(self, slots, frame) -> np.ndarray:
        c = self._crowd
        return c.slots.evaluate(slots, frame, c.streams, c.uniques)

    def slots_blended(self):
        c, st = self._crowd, self._crowd.storage
        act = c.slots.active_slots()
        if act.size == 0:
            return
        skel = c.slots.target_skeleton(act, c.streams, c.uniques)
        for k in np.unique(skel):
            s = act[skel == k]
            lo, hi = int(s[0]), int(s[-1]) + 1
            if hi - lo == s.size:
                c.plans[k].rows(c.slots.pose[lo:hi], out=st.slot_rows()[lo:hi])
            else:
                st.slot_rows()[s] = c.plans[k].rows(c.slots.pose[s])
        st.mark_rows_dirty(st.slot_base + act)

    def restored(self):
        """Skin every history slice and the uniques again, and each active slot's pose:
        StartP for a slot that started this frame (as :meth:`slot_starting` leaves
        it), else its blend at this frame (as the last step left it)."""
        c, st = self._crowd, self._crowd.storage
        for sl in range(c.streams.max_offset):
            self._skin(self._stream_groups, c.streams.history[sl], st.stream_slice(sl))
        self._skin(self._unique_groups, c.uniques.poses, st.unique_rows())
        act = c.slots.active_slots()
        new = act[c.slots.t0[act] == c.frame]
        c.slots.evaluate(act[c.slots.t0[act] != c.frame], c.frame, c.streams, c.uniques)
        c.slots.pose[new] = c.slots.start_pose[new]
        self.slots_blended()
        super().restored()

    def slot_starting(self, slots, agents, start_poses):
        """Before ``agents`` enter ``slots``: the slot shows exactly the agent's current
        rows, and its pose is StartP, until the next step blends it."""
        st = self._crowd.storage
        st.rows[st.slot_base + slots] = self._crowd.agent_rows(agents)
        st.mark_rows_dirty(st.slot_base + slots)
        self._crowd.slots.pose[slots] = start_poses

    def slot_poses(self, slots) -> np.ndarray:
        """``(k, B, 10)`` poses of ``slots`` now (blended by the last step)."""
        return self._crowd.slots.pose[slots]

    def rows(self, logical_rows) -> np.ndarray:
        """Skinning rows ``(n, B, 3, 4)`` of logical pose texture rows."""
        return self._crowd.storage.rows[logical_rows]


class GpuSkinning(_Mode):
    """The GPU writes skinning rows from local poses (see the module docstring)."""

    name = "gpu"
    on_gpu = True
    fill = LOCAL_IDENTITY

    def history(self, storage, shape):
        return storage.sqt_view()[:storage.unique_base].reshape(shape)

    def unique_poses(self, storage, shape):
        return storage.sqt_view()[storage.unique_base:storage.slot_base]

    def bind(self, crowd):
        super().bind(crowd)
        streams = crowd.streams
        # row slice * S + s is stream s; unique rows follow
        self._row_skeleton = np.concatenate(
            [np.tile(streams.skeleton, streams.max_offset), crowd.uniques.skeleton]
        ).astype(np.int32)
        self._pending = []

    def reset(self):
        self._pending = [(0, self._crowd.storage.slot_base)]

    def restored(self):
        """Every slot's local-pose row holds its StartP again (the pools' rows are
        written in place by the restore)."""
        st = self._crowd.storage
        sqt.records(st.sqt_view())[st.slot_base:] = sqt.records(self._crowd.slots.start_pose)
        super().restored()

    def roots_stored(self, frame: int):
        c, st = self._crowd, self._crowd.storage
        for start, count in ((c.streams.slice(frame) * c.streams.count, c.streams.count),
                             (st.unique_base, c.uniques.count)):
            st.mark_dirty(start, count)
            if count:
                self._pending.append((start, count))
        if len(self._pending) > 64:          # nobody takes batches (an export): merge
            self._pending = PoseStorage.merged(self._pending)

    def blend(self, slots, frame) -> np.ndarray:
        return self._crowd.slots.weights(slots, frame)       # the GPU blends the poses

    def slots_blended(self):
        pass

    def slot_starting(self, slots, agents, start_poses):
        """StartP goes into the slot's local-pose row; the GPU blends from it."""
        st = self._crowd.storage
        sqt.records(st.sqt_view())[st.slot_base + slots] = sqt.records(
            np.ascontiguousarray(start_poses))
        st.mark_rows_dirty(st.slot_base + slots)

    def slot_poses(self, slots) -> np.ndarray:
        """``(k, B, 10)`` poses of ``slots`` now, blended here on the CPU (the GPU blends
        them for drawing)."""
        c = self._crowd
        return c.slots.blended(slots, c.frame, c.streams, c.uniques)[0]

    def rows(self, logical_rows) -> np.ndarray:
        """Skinning rows ``(n, B, 3, 4)`` of logical rows, skinned here on the CPU (each
        distinct row once): stream and unique rows from their local poses, slot rows
        blended like the GPU does."""
        c, st = self._crowd, self._crowd.storage
        used, inverse = np.unique(np.asarray(logical_rows, np.int64), return_inverse=True)
        is_slot = used >= st.slot_base
        poses = np.empty((used.size, c.bones, sqt.WIDTH), np.float32)
        skel = np.empty(used.size, np.int64)
        poses[~is_slot] = st.sqt_view()[used[~is_slot]]
        skel[~is_slot] = self._row_skeleton[used[~is_slot]]
        if is_slot.any():
            slots = used[is_slot] - st.slot_base
            poses[is_slot] = self.slot_poses(slots)
            skel[is_slot] = c.slots.target_skeleton(slots, c.streams, c.uniques)
        return self._skin_poses(poses, skel)[inverse.reshape(-1)]

    def take_batch(self) -> SkinningBatch:
        """The rows the GPU must write now: every stream and unique row whose local pose
        changed since the last take (the new slice and the uniques after a step;
        everything after a reset) and every active slot. Take it after the upload
        regions are written."""
        c, st = self._crowd, self._crowd.storage
        ranges = PoseStorage.merged(self._pending)
        self._pending = []
        own = np.concatenate([np.arange(a, a + n, dtype=np.int64) for a, n in ranges]) \
            if ranges else np.zeros(0, np.int64)
        act = c.slots.active_slots()
        target = c.slots.target_rows(act, c.frame, c.streams, st.unique_base)
        return SkinningBatch(
            np.concatenate([own, st.slot_base + act]).astype(np.int32),
            np.concatenate([own, target]).astype(np.int32),
            np.concatenate([np.ones(own.size), c.slots.weights(act, c.frame)]
                           ).astype(np.float32),
            np.concatenate([self._row_skeleton[own],
                            c.slots.target_skeleton(act, c.streams, c.uniques)]
                           ).astype(np.int32))


SKINNING_MODES = {"cpu": CpuSkinning, "gpu": GpuSkinning}


def skinning_mode(name: str) -> _Mode:
    """A new skinning mode object for ``name`` (``"cpu"`` or ``"gpu"``)."""
    if name not in SKINNING_MODES:
        raise CrowdError(f"crowd: skinning must be one of {sorted(SKINNING_MODES)}, got "
                         f"{name!r}")
    return SKINNING_MODES[name]()


def _groups(skel_of):
    """(skeleton, indices, contiguous slice or None) per skeleton in ``skel_of``."""
    out = []
    for k in np.unique(skel_of):
        idx = np.flatnonzero(skel_of == k)
        contiguous = idx.size and idx[-1] - idx[0] + 1 == idx.size
        out.append((int(k), idx, slice(int(idx[0]), int(idx[-1]) + 1) if contiguous
                    else None))
    return out

