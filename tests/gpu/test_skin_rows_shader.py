"""The skinning-rows compute shader (paper s.4.5) against core's CPU skinning.

Two crowds from one configuration get the same requests; one skins and blends on
the CPU, the other (``skinning="gpu"``) uploads local poses and hands the rest to
the GPU. Every frame the rows the shader wrote into the pose texture (the new
history slice, the unique, the transition slots) must equal the CPU crowd's rows.
Two skeletons of different sizes exercise the per-row skeleton and the end of a
shorter skeleton; a small max texture size wraps the rows.
"""

import numpy as np

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig
from crowd_addon.core.authoring import synthetic as sy


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


def row_skeleton(crowd, row):
    """Skeleton of a history or unique row (slice-major stream rows, then uniques)."""
    lay = crowd.view.layout
    if row < lay.unique_base:
        return crowd.view.stream_skeleton[row % lay.streams]
    return crowd.view.unique_skeleton[row - lay.unique_base]


def _row(texture, st, row, bones):
    x, y = st.texel_of_row(row)
    return texture[y, x:x + 3 * bones].reshape(bones, 3, 4)


def _close(got, want):
    return np.abs(got - want).max() <= 1e-4 * np.abs(want).max()


def test_gpu_rows_match_cpu_slice_unique_and_transition_rows(renderer):
    cpu, gpu = Crowd(config()), Crowd(config(), skinning="gpu")
    assert gpu.storage.blocks > 1
    r = renderer(gpu)
    st = cpu.storage
    texture = r.read_pose_texture()             # after the renderer's first batch
    for row in range(st.slot_base):             # the whole history and the unique
        b = gpu.skeletons[row_skeleton(gpu, row)].bone_count
        assert _close(_row(texture, st, row, b), st.rows[row, :b]), row
    checked = 0
    for i in range(16):
        for crowd in (cpu, gpu):
            requests(crowd, i)
            crowd.step()
        stats = r.sync()
        active = cpu.slots.active_slots()
        np.testing.assert_array_equal(gpu.slots.active_slots(), active)
        S = gpu.streams.count
        assert stats.skinned_rows == S + gpu.uniques.count + active.size
        texture = r.read_pose_texture()
        sl = gpu.view.ring_slice
        for row in [*range(sl * S, (sl + 1) * S), st.unique_base]:
            b = gpu.skeletons[row_skeleton(gpu, row)].bone_count
            assert _close(_row(texture, st, row, b), st.rows[row, :b]), (i, row)
        for slot in active:
            kind, ref = gpu.slots.target_kind[slot], gpu.slots.target_ref[slot]
            k = (gpu.view.stream_skeleton if kind == 0 else gpu.view.unique_skeleton)[ref]
            b = gpu.skeletons[k].bone_count
            got = _row(texture, st, st.slot_base + slot, b)
            assert _close(got, st.rows[st.slot_base + slot, :b]), (i, slot)
            checked += 1
    assert checked > 40


def test_gpu_skinned_agents_render_like_the_cpu_crowd(renderer):
    """What is drawn (transform feedback) agrees too, for agents mid-transition."""
    cpu, gpu = Crowd(config()), Crowd(config(), skinning="gpu")
    rc, rg = renderer(cpu), renderer(gpu)
    agents = np.array([0, 2, 4, 20, 21, 25])
    for i in range(5):
        for crowd in (cpu, gpu):
            requests(crowd, i)
            crowd.step()
        rc.sync()
        rg.sync()
    a, b = rc.skinned_positions(agents[:3]), rg.skinned_positions(agents[:3])
    assert np.abs(a - b).max() <= 1e-4 * np.abs(a).max()
    a, b = rc.skinned_positions(agents[3:]), rg.skinned_positions(agents[3:])
    assert np.abs(a - b).max() <= 1e-4 * np.abs(a).max()
