"""The per-agent instance texture: its contents, and per-frame updates limited to the
agents whose reference or placement changed."""

import numpy as np

from crowd_addon.core import TRANSITION
from crowd_addon.gpu.instances import InstanceData, pack_colors
from crowd_addon.gpu.texture_region import block_regions


def test_records_hold_each_agents_placement_reference_and_colour(h):
    crowd = h.Crowd(h.make_config(agents=40))
    inst = InstanceData(crowd.view, max_texture_size=16)
    assert (inst.width, inst.height) == (9, 16)           # three column blocks
    rec = inst.records
    np.testing.assert_array_equal(rec[:, 0, :3], crowd.agents.position)
    np.testing.assert_array_equal(rec[:, 0, 3], crowd.agents.heading)
    a = crowd.agents
    kind_offset = a.kind.astype(np.int64) * 65536 + a.offset      # int8 kind: widen first
    np.testing.assert_array_equal(rec[:, 1, :3], np.c_[kind_offset, a.ref, a.scale])
    assert len(set(a.scale.tolist())) == 40                # every agent its own scale
    rgb = rec[:, 1, 3].astype(np.int64)
    decoded = np.stack([rgb >> 16, (rgb >> 8) & 255, rgb & 255], 1) / 255
    np.testing.assert_allclose(decoded, crowd.agents.color, atol=0.5 / 255 + 1e-7)
    image = inst.texture_image()
    np.testing.assert_array_equal(image[37 % 16, 3 * (37 // 16):3 * (37 // 16) + 3], rec[37])
    np.testing.assert_array_equal(rec[:, 2], -1.0)          # no palettes


def test_pack_colors_is_exact_in_float32():
    c = np.array([[1.0, 1.0, 1.0], [0.0, 0.5, 1.0], [2.0, -1.0, 0.2]])
    np.testing.assert_array_equal(pack_colors(c), [16777215, 128 * 256 + 255, 255 * 65536 + 51])


def test_updates_cover_only_changed_agents(h, renderer):
    crowd = h.Crowd(h.make_config(agents=40, NT=4))
    r = renderer(crowd)
    crowd.step()
    assert r.sync().instance_bytes == 0
    res = crowd.transition_to_streamed([5, 17], "s1", 4)
    assert (crowd.agents.kind[res.started] == TRANSITION).all()
    crowd.step()
    stats = r.sync()
    assert stats.instance_bytes == 2 * 3 * 16          # two agents, three RGBA32F texels
    inst = r.plan.instances
    texture = np.frombuffer(r.textures["agents"].read(), np.float32).reshape(inst.height,
                                                                           inst.width, 4)
    np.testing.assert_array_equal(texture, inst.texture_image())
    np.testing.assert_array_equal(inst.records[[5, 17], 1, 0] // 65536, TRANSITION)


def test_block_regions_cover_exactly_the_changed_rows_with_few_writes():
    rows = np.arange(40 * 3 * 4, dtype=np.float32).reshape(40, 3, 4)
    image_rows, blocks = 16, 3
    for changed, limit in (([1, 2, 3, 9, 20], 16), ([1, 2, 3, 9, 20], 2),
                           ([0, 15, 16, 39], 16)):
        regions = block_regions(rows, changed, image_rows, limit)
        assert len(regions) <= max(limit, blocks)
        covered = set()
        for r in regions:
            b = r.x // 3
            assert r.width == 3 and r.y + r.height <= image_rows
            first = b * image_rows + r.y
            assert r.rows == (first, first + r.height)
            np.testing.assert_array_equal(r.data, rows[first:first + r.height])
            covered |= set(range(*r.rows))
        assert set(changed) <= covered
    assert sum(r.height for r in block_regions(rows, [1, 2, 3, 9, 20], image_rows)) == 5
