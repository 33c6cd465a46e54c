"""The transition compute shader (paper s.4.5) against core's CPU transitions.

Two crowds from one configuration get the same requests; one blends its slots on
the CPU, the other (``gpu_transitions=True``) hands them to the GPU. Every frame
the slot rows the shader wrote into the pose texture must equal the CPU crowd's
slot rows. Two skeletons of different sizes exercise the per-slot skeleton and
the end of a shorter skeleton; a small max texture size wraps the rows.
"""

import numpy as np

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig
from crowd_addon.core import synthetic as sy


def config():
    cfg = CrowdConfig(max_offset=8, transition_slots=5, max_texture_size=256)
    fan = cfg.add_skeleton(sy.humanoid("fan", bones=24))
    kid = cfg.add_skeleton(sy.humanoid("kid", bones=27))
    cfg.add_clip(sy.periodic_clip(fan, "walk"))
    cfg.add_clip(sy.periodic_clip(fan, "idle", frames=41, seed=2))
    cfg.add_clip(sy.periodic_clip(kid, "run", frames=21, seed=5))
    cfg.add_clip(sy.periodic_clip(kid, "hop", frames=17, seed=6))
    cfg.add_stream("walk", "fan", ClipPlayer("walk"))
    cfg.add_stream("idle", "fan", ClipPlayer("idle"))
    cfg.add_stream("run", "kid", ClipPlayer("run"))
    for s in range(40):                                   # rows enough to wrap
        cfg.add_stream(f"hop{s}", "kid", ClipPlayer("hop", speed=1 + s / 40))
    cfg.add_unique("hero", "fan", ClipPlayer("idle", speed=1.5))
    cfg.add_agents(20, streams=np.arange(20) % 2, offsets=np.arange(20) % 8)
    cfg.add_agents(6, streams="run", offsets=np.arange(6))
    cfg.add_mesh(sy.humanoid_mesh(fan), lods=())
    cfg.add_mesh(sy.humanoid_mesh(kid), lods=())
    return cfg


def requests(crowd, i):
    if i == 1:
        crowd.transition_to_streamed([0, 2, 4, 6, 8, 10], "idle", 6, offset=3)  # one queues
    if i == 3:
        crowd.transition_to_unique([1], "hero", 5)
    if i == 4:
        crowd.transition_to_streamed([21, 22], "hop3", 4, offset=0)
    if i == 6:
        crowd.transition_to_streamed([3], "walk", 7, offset=0)
    if i == 7:
        crowd.transition_to_streamed([2], "walk", 3)            # re-target mid-blend


def test_gpu_slot_rows_match_cpu_transition_rows(renderer):
    cpu, gpu = Crowd(config()), Crowd(config(), gpu_transitions=True)
    assert gpu.storage.blocks > 1
    r = renderer(gpu)
    st = cpu.storage
    checked = 0
    for i in range(16):
        for crowd in (cpu, gpu):
            requests(crowd, i)
            crowd.step()
        stats = r.sync()
        active = cpu.slots.active_slots()
        np.testing.assert_array_equal(np.sort(gpu.gpu_transition_batch().slots), active)
        assert stats.transitions == active.size
        texture = r.read_pose_texture()
        x, y = st.texel_of_row(st.slot_base + active)
        for slot, xx, yy in zip(active, x, y):
            skel = cpu.skeletons[int(gpu.gpu_transition_batch().skeletons[
                np.flatnonzero(gpu.gpu_transition_batch().slots == slot)[0]])]
            b = skel.bone_count
            got = texture[yy, xx:xx + 3 * b].reshape(b, 3, 4)
            want = st.rows[st.slot_base + slot, :b]
            err = np.abs(got - want).max()
            assert err <= 1e-4 * np.abs(want).max(), (i, slot, err)
            checked += 1
    assert checked > 40


def test_gpu_transition_agents_render_like_the_cpu_crowd(renderer):
    """What is drawn (transform feedback) agrees too, for agents mid-transition."""
    cpu, gpu = Crowd(config()), Crowd(config(), gpu_transitions=True)
    rc, rg = renderer(cpu), renderer(gpu)
    agents = np.array([0, 2, 4])
    for i in range(5):
        for crowd in (cpu, gpu):
            requests(crowd, i)
            crowd.step()
        rc.sync()
        rg.sync()
    a, b = rc.skinned_positions(agents), rg.skinned_positions(agents)
    assert np.abs(a - b).max() <= 1e-4 * np.abs(a).max()
