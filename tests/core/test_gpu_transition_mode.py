"""Crowd(gpu_transitions=True): the CPU hands the slot blends to the GPU.

The oracle is the same crowd blending on the CPU: the local-pose texture plus the
batch must reproduce exactly the CPU's transition poses, and everything an agent
shows (poses, rows, events, upload accounting) must stay the same.
"""

import numpy as np
import pytest

from crowd_addon.core import CrowdConfig, Crowd, CrowdError, synthetic
from crowd_addon.core import pose as sqt
from crowd_addon.core.agents import TRANSITION
from crowd_addon.core.pose_storage import pack_local_poses


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


def gpu_blend(crowd):
    """What the compute shader does, in numpy: blend StartP -> target rows by S."""
    b = crowd.gpu_transition_batch()
    loc = crowd.local_storage
    start = loc.rows[loc.slot_base + b.slots]
    target = loc.rows[b.target_rows]
    unpack = lambda r: np.concatenate([r[..., 0, :3], r[..., 1, :], r[..., 2, :3]], -1)  # noqa
    return b, sqt.blend2(unpack(start), unpack(target), b.weights)


def test_gpu_mode_matches_cpu_blends_rows_and_events():
    cpu, gpu = Crowd(make_config()), Crowd(make_config(), gpu_transitions=True)
    ev_cpu, ev_gpu = [], []
    checked = 0
    for _ in zip(drive(cpu, ev_cpu), drive(gpu, ev_gpu)):
        assert np.array_equal(cpu.agent_kind, gpu.agent_kind)
        assert np.array_equal(cpu.agent_ref, gpu.agent_ref)
        np.testing.assert_array_equal(gpu.agent_poses(), cpu.agent_poses())
        np.testing.assert_array_equal(gpu.agent_rows(), cpu.agent_rows())
        batch, blended = gpu_blend(gpu)
        assert set(batch.slots.tolist()) == set(cpu.slots.active_slots().tolist())
        np.testing.assert_array_equal(blended, cpu.slots.pose[batch.slots])
        # the CPU texture's slot rows are exactly what the GPU must write
        for s, k, pose in zip(batch.slots, batch.skeletons, blended):
            rows = cpu.plans[k].rows(pose[None])[0]
            np.testing.assert_allclose(cpu.storage.rows[cpu.storage.slot_base + s], rows,
                                       atol=1e-6)
            target = gpu.slots.target_ref[s] + (gpu.S if gpu.slots.target_kind[s] != 0 else 0)
            assert gpu.skeletons[k].name == gpu.config.streams[0].skeleton if target < gpu.S \
                else gpu.config.uniques[0].skeleton
        checked += batch.slots.size
        # stream slices and unique rows are identical in both textures
        np.testing.assert_array_equal(gpu.storage.rows[:gpu.storage.slot_base],
                                      cpu.storage.rows[:cpu.storage.slot_base])
    assert checked > 20
    assert ev_cpu == ev_gpu and ev_cpu


def test_local_texture_mirrors_history_uniques_and_start_poses():
    crowd = Crowd(make_config(), gpu_transitions=True)
    loc = crowd.local_storage
    assert (loc.width, loc.height, loc.blocks) == (crowd.storage.width, crowd.storage.height,
                                                  crowd.storage.blocks)
    for i, _ in enumerate(drive(crowd, [])):
        sl = crowd.frame % crowd.M
        np.testing.assert_array_equal(loc.stream_slice(sl), pack_local_poses(crowd.history[sl]))
        np.testing.assert_array_equal(loc.unique_rows(), pack_local_poses(crowd.unique_poses))
        act = crowd.slots.active_slots()
        np.testing.assert_array_equal(loc.slot_rows()[act],
                                      pack_local_poses(crowd.slots.start_pose[act]))
        if i == 2:      # the request at i == 2 started three slots at the pose shown then
            assert act.size == 3


def test_uploads_in_gpu_mode_skip_slot_rows_but_carry_local_rows():
    crowd = Crowd(make_config(), gpu_transitions=True)
    crowd.take_upload_regions()
    crowd.take_local_upload_regions()
    row = crowd.storage.row_bytes
    base = crowd.storage.slot_base
    crowd.on_event("*", lambda *a: None)
    for i in range(30):
        started = 0
        if i == 2:
            started = crowd.transition_to_streamed([0, 2, 4], "idle", 6, offset=3).started.size
        report = crowd.step()
        started += report.transitions_started
        regs, local = crowd.take_upload_regions(), crowd.take_local_upload_regions()
        slot_rows = sum(min(r.rows[1], crowd.storage.row_count) - max(r.rows[0], base)
                        for r in regs if r.rows[1] > base)
        # slot rows go up once, when a slot starts (its first pose); never per frame
        assert slot_rows == started
        per_texture = (crowd.S + crowd.U + started) * row
        assert sum(r.nbytes for r in regs) == per_texture
        assert sum(r.nbytes for r in local) == per_texture
        # the step's report counts what the step wrote (not a request's first pose)
        stepped = (crowd.S + crowd.U + report.transitions_started) * row
        assert report.upload_bytes == 2 * stepped
    assert crowd.slots.served == 3


def test_batch_and_local_regions_need_gpu_mode():
    crowd = Crowd(make_config())
    with pytest.raises(CrowdError, match="gpu_transitions=True"):
        crowd.gpu_transition_batch()
    with pytest.raises(CrowdError, match="gpu_transitions=True"):
        crowd.take_local_upload_regions()
    assert crowd.local_storage is None and not (crowd.agent_kind == TRANSITION).any()
