"""Agent placement policy on plain arrays (crowd_addon.core.placement): seeded offsets
and streams, colours, headings, per-point values. (Reading the points and attributes
from Blender geometry is tested in tests/blender/test_agents.py.)"""

import numpy as np
import pytest

from crowd_addon.core.errors import CrowdError
from crowd_addon.core.placement import (SOURCE_SEED, AgentSet, PlacementPolicy,
                                        place_agents, z_angle)

STREAMS = ["idle", "cheer", "sit"]


def grid(nx, ny):
    """Points of an nx x ny grid (1 m apart) at z = 0, base headings 0."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1), np.zeros(x.size)


def place(policy=PlacementPolicy(), points=grid(20, 20), weights=(1, 1, 1), m=30, seed=4,
          forward="NEG_Y", attribute=None):
    pos, heading = points
    return place_agents("agent source 'seats'", pos, heading, policy, streams=STREAMS,
                        stream_weights=list(weights), max_offset=m, seed=seed,
                        forward_axis=forward, attribute=attribute)


def test_offsets_are_seeded_and_within_range():
    a1, a2, a3 = place(seed=9), place(seed=9), place(seed=10)
    assert a1.count == 400 and a1.offsets.dtype == np.int32
    assert a1.offsets.min() >= 0 and a1.offsets.max() <= 29
    assert len(np.unique(a1.offsets)) == 30                  # uniform: every offset used
    np.testing.assert_array_equal(a1.offsets, a2.offsets)
    np.testing.assert_array_equal(a1.streams, a2.streams)
    np.testing.assert_array_equal(a1.colors, a2.colors)
    assert (a1.offsets != a3.offsets).any()
    a = place(PlacementPolicy(offset_mode="NORMAL", offset_mean=20.0, offset_std=2.0))
    assert a.offsets.min() >= 0 and a.offsets.max() <= 29
    assert abs(a.offsets.mean() - 20.0) < 0.5


def test_streams_by_weight_and_by_name():
    a = place(points=grid(30, 30), weights=(0.0, 3.0, 1.0))
    assert set(np.unique(a.streams)) == {1, 2}
    share = (a.streams == 1).mean()
    assert 0.7 < share < 0.8
    assert (place(PlacementPolicy(stream_mode="FIXED", stream_name="sit")).streams == 2).all()
    with pytest.raises(CrowdError, match="agent source 'seats': unknown stream 'dance'"):
        place(PlacementPolicy(stream_mode="FIXED", stream_name="dance"))
    with pytest.raises(CrowdError, match="agent source 'seats': agents: stream weights"):
        place(weights=(0, 0, 0))


def test_random_colours_vary_around_the_base():
    still = PlacementPolicy(color=(0.2, 0.4, 0.6), color_variation=0.0)
    np.testing.assert_allclose(place(still, grid(10, 10)).colors, [[0.2, 0.4, 0.6]] * 100,
                               atol=1e-6)
    c = place(PlacementPolicy(color=(0.2, 0.4, 0.6), color_variation=0.5), grid(10, 10)).colors
    base = np.array([0.2, 0.4, 0.6])
    assert (np.abs(c - base) <= 0.5 * np.maximum(base, 1 - base) + 1e-6).all()
    assert c.std(0).min() > 0.05


def test_headings_fixed_toward_a_target_and_wrapped():
    pos, _ = grid(5, 4)
    base = np.full(len(pos), 3.0)
    a = place(PlacementPolicy(heading=0.5), (pos, base))
    np.testing.assert_allclose(a.headings, 3.5 - 2 * np.pi, atol=1e-6)    # into [-pi, pi)
    target = (2.0, 20.0, 0.0)
    for forward, facing in (("NEG_Y", (0, -1)), ("POS_X", (1, 0)), ("NEG_X", (-1, 0))):
        h = place(PlacementPolicy(heading_mode="TARGET", target=target), (pos, base),
                  forward=forward).headings.astype(np.float64)
        c, s = np.cos(h), np.sin(h)
        turned = np.stack([c * facing[0] - s * facing[1], s * facing[0] + c * facing[1]], 1)
        to_target = np.array(target[:2]) - pos[:, :2]
        to_target /= np.linalg.norm(to_target, axis=1, keepdims=True)
        np.testing.assert_allclose(turned, to_target, atol=1e-5)
    with pytest.raises(CrowdError, match="heading faces a target but none is chosen"):
        place(PlacementPolicy(heading_mode="TARGET"))


def test_per_point_values_come_from_the_attribute_callback():
    pos, base = grid(4, 3)
    values = {"heading": np.linspace(-1, 1, 12), "stream": np.arange(12) % 3,
              "offset": np.arange(12) % 30, "Col": np.full((12, 4), 0.25)}
    asked = []

    def attribute(name, kind):
        asked.append((name, kind))
        return values[name]

    policy = PlacementPolicy(heading_mode="ATTRIBUTE", stream_mode="ATTRIBUTE",
                             offset_mode="ATTRIBUTE", color_mode="ATTRIBUTE")
    a = place(policy, (pos, base + 0.25), attribute=attribute)
    assert asked == [("heading", "float"), ("stream", "int"), ("offset", "int"),
                     ("Col", "color")]
    np.testing.assert_allclose(a.headings, values["heading"] + 0.25, atol=1e-6)
    np.testing.assert_array_equal(a.streams, values["stream"])
    np.testing.assert_array_equal(a.offsets, values["offset"])
    np.testing.assert_allclose(a.colors, 0.25)
    values["stream"] = np.array([0] * 5 + [3] + [0] * 6)
    with pytest.raises(CrowdError, match=r"attribute 'stream' gives stream 3 at point 5; "
                                         r"streams are 0..2"):
        place(PlacementPolicy(stream_mode="ATTRIBUTE"), (pos, base), attribute=attribute)
    values["offset"] = np.array([0] * 7 + [30] + [0] * 4)
    with pytest.raises(CrowdError, match=r"agent source 'seats': point 7: offset 30 is "
                                         r"outside 0..29.*\(attribute 'offset'\)"):
        place(PlacementPolicy(offset_mode="ATTRIBUTE"), (pos, base), attribute=attribute)
    with pytest.raises(CrowdError, match="this source has no point attributes"):
        place(PlacementPolicy(color_mode="ATTRIBUTE"), (pos, base))


def test_agent_sets_concatenate_and_z_angles():
    a, b = place(points=grid(2, 2)), place(points=grid(3, 1), seed=4 + SOURCE_SEED)
    both = AgentSet.concatenate([a, b])
    assert both.count == 7 and both.positions.shape == (7, 3)
    np.testing.assert_array_equal(both.offsets, np.concatenate([a.offsets, b.offsets]))
    assert AgentSet.concatenate([]).count == 0
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(0.7), -np.sin(0.7)], [np.sin(0.7), np.cos(0.7)]]
    assert z_angle(turn) == pytest.approx(0.7)
