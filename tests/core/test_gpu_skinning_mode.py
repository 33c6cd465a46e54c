"""Crowd(skinning="gpu"): the CPU uploads local poses, the GPU writes skinning rows.

The oracle is the same crowd skinning and blending on the CPU: the local-pose
texture plus the batch, put through what the compute shader does (in numpy here),
must reproduce the CPU crowd's pose texture rows, and everything an agent shows
(poses, rows, events) must stay the same.
"""

import numpy as np
import pytest

from crowd_addon.core import CrowdConfig, Crowd, CrowdError
from crowd_addon.core.authoring import synthetic
from crowd_addon.core.base import pose as sqt
from crowd_addon.core.runtime.agents import TRANSITION
from crowd_addon.core.runtime.pose_storage import LOCAL_IDENTITY


def make_config():
    cfg = CrowdConfig(max_offset=8, transition_slots=3, fps=30.0, max_texture_size=256)
    fan = cfg.add_skeleton(synthetic.humanoid("fan", bones=24))
    kid = cfg.add_skeleton(synthetic.humanoid("kid", bones=26))
    cfg.add_clip(synthetic.periodic_clip(fan, "walk", events=[("step", 10)]))
    cfg.add_clip(synthetic.periodic_clip(fan, "idle", frames=41, seed=2, events=[("b", 5)]))
    cfg.add_clip(synthetic.periodic_clip(kid, "run", frames=21, seed=5))
    cfg.add_stream("walk", "fan", synthetic_player("walk"))
    cfg.add_stream("idle", "fan", synthetic_player("idle"))
    cfg.add_stream("run", "kid", synthetic_player("run"))
    cfg.add_unique("hero", "fan", synthetic_player("idle", speed=1.5))
    cfg.add_agents(30, streams=np.arange(30) % 2, offsets=np.arange(30) % 8)
    cfg.add_agents(4, streams="run")
    return cfg


def synthetic_player(clip, speed=1.0):
    from crowd_addon.core import ClipPlayer
    return ClipPlayer(clip, speed=speed)


def drive(crowd, log):
    crowd.on_event("*", lambda n, f, ids: log.append((n, f, sorted(ids.tolist()))))
    for i in range(30):
        if i == 2:
            crowd.transition_to_streamed([0, 2, 4, 6, 8], "idle", 6, offset=3)   # 2 queue
        if i == 4:
            crowd.transition_to_unique([1], "hero", 5)
        if i == 9:
            crowd.transition_to_streamed([3], "walk", 7, offset=0)
        crowd.step()
        yield i


class GpuModel:
    """The GPU side in numpy: a pose texture written only from batches, the way
    gpu_shaders/skin_rows_comp.glsl writes it (blend, then the skinning rows)."""

    def __init__(self, crowd):
        self.crowd = crowd
        self.texture = np.full((crowd.storage.row_count, crowd.bones, 3, 4), np.nan, np.float32)
        self.apply()

    def apply(self):
        c = self.crowd
        b = c.view.take_skinning_batch()
        local = c.storage.sqt_view()
        blended = sqt.blend2(local[b.rows], local[b.sources], b.weights)
        for k in np.unique(b.skeletons):
            m = b.skeletons == k
            self.texture[b.rows[m]] = c.plans[k].rows(blended[m])
        return b


def test_gpu_mode_matches_cpu_poses_rows_texture_and_events():
    cpu, gpu = Crowd(make_config()), Crowd(make_config(), skinning="gpu")
    model = GpuModel(gpu)
    ev_cpu, ev_gpu = [], []
    slots_checked = 0
    for _ in zip(drive(cpu, ev_cpu), drive(gpu, ev_gpu)):
        assert np.array_equal(cpu.agents.kind, gpu.agents.kind)
        assert np.array_equal(cpu.agents.ref, gpu.agents.ref)
        np.testing.assert_array_equal(gpu.agent_poses(), cpu.agent_poses())
        np.testing.assert_allclose(gpu.agent_rows(), cpu.agent_rows(), atol=1e-6)
        b = model.apply()
        # each step writes the new history slice, the uniques and the active slots
        sl = gpu.frame % gpu.streams.max_offset
        own = set(range(sl * gpu.streams.count, (sl + 1) * gpu.streams.count)) | set(
            range(gpu.storage.unique_base, gpu.storage.slot_base))
        slots = set((gpu.storage.slot_base + cpu.slots.active_slots()).tolist())
        assert set(b.rows.tolist()) == own | slots
        slots_checked += len(slots)
        # every row an agent reads is what the CPU crowd's pose texture holds
        used = np.unique(cpu.agent_rows_index())
        np.testing.assert_allclose(model.texture[used], cpu.storage.rows[used], atol=2e-6)
        # whole history and unique rows too, not only the rows read now
        np.testing.assert_allclose(model.texture[:gpu.storage.slot_base],
                                   cpu.storage.rows[:cpu.storage.slot_base], atol=2e-6)
    assert slots_checked > 20
    assert ev_cpu == ev_gpu and ev_cpu


def test_stream_rows_are_exact_on_demand():
    cpu, gpu = Crowd(make_config()), Crowd(make_config(), skinning="gpu")
    for _ in zip(drive(cpu, []), drive(gpu, [])):
        pass
    for stream in ("walk", "idle", "run"):
        for offset in (0, 3, 7):
            np.testing.assert_allclose(gpu.stream_rows(stream, offset),
                                       cpu.stream_rows(stream, offset), atol=1e-6)


def test_history_uniques_and_start_poses_live_in_the_local_texture():
    crowd = Crowd(make_config(), skinning="gpu")
    st = crowd.storage
    local = st.rows.reshape(st.row_count, crowd.bones, 12)
    assert np.shares_memory(crowd.streams.history, st.rows)
    assert np.shares_memory(crowd.uniques.poses, st.rows)
    m, s = crowd.streams.max_offset, crowd.streams.count
    for i, _ in enumerate(drive(crowd, [])):
        sl = crowd.frame % m
        np.testing.assert_array_equal(local[sl * s:(sl + 1) * s, :, :10],
                                      crowd.streams.history[sl])
        np.testing.assert_array_equal(local[st.unique_base:st.slot_base, :, :10],
                                      crowd.uniques.poses)
        act = crowd.slots.active_slots()
        np.testing.assert_array_equal(local[st.slot_base + act, :, :10],
                                      crowd.slots.start_pose[act])
        assert not local[..., 10:].any()           # the two pad floats stay zero
        if i == 2:      # the request at i == 2 started three slots at the pose shown then
            assert act.size == 3
    # bones past a skeleton's last bone keep the identity SQT
    fan_rows = local[:crowd.storage.unique_base].reshape(m, s, crowd.bones, 12)[:, 0]
    np.testing.assert_array_equal(fan_rows[:, 24:], np.broadcast_to(LOCAL_IDENTITY.reshape(12),
                                                                     (m, 2, 12)))


def test_uploads_are_local_rows_and_the_batch_covers_them():
    crowd = Crowd(make_config(), skinning="gpu")
    crowd.view.take_upload_regions()
    first = crowd.view.take_skinning_batch()           # after a reset: every history/unique row
    assert len(first) == crowd.storage.slot_base
    assert len(crowd.view.take_skinning_batch()) == 0  # nothing changed, no slot active
    row = crowd.storage.row_bytes
    heads = crowd.streams.count + crowd.uniques.count     # rows every step writes
    crowd.on_event("*", lambda *a: None)
    for i in range(30):
        started = 0
        if i == 2:
            started = crowd.transition_to_streamed([0, 2, 4], "idle", 6, offset=3).started.size
        report = crowd.step()
        started += report.transitions_started
        regs = crowd.view.take_upload_regions()
        # the new slice, the uniques, and a slot's StartP once when it starts
        assert sum(r.nbytes for r in regs) == (heads + started) * row
        assert report.upload_bytes == (heads + report.transitions_started) * row
        b = crowd.view.take_skinning_batch()
        assert len(b) == heads + crowd.slots.active_slots().size
        own = b.rows < crowd.storage.slot_base
        np.testing.assert_array_equal(b.sources[own], b.rows[own])
        assert (b.weights[own] == 1).all()
        assert ((b.weights[~own] >= 0) & (b.weights[~own] <= 1)).all()
    assert crowd.slots.served == 3
    crowd.reset()
    assert len(crowd.view.take_skinning_batch()) == crowd.storage.slot_base


def test_batch_needs_gpu_mode():
    crowd = Crowd(make_config())
    with pytest.raises(CrowdError, match="skinning='gpu'"):
        crowd.view.take_skinning_batch()
    assert not (crowd.agents.kind == TRANSITION).any()
