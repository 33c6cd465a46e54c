"""Agent placement policy on plain arrays (crowd_addon.core.authoring.placement): seeded offsets,
characters and streams, colours, headings, per-point values. (Reading the points and
attributes from Blender geometry is tested in tests/blender/test_agents.py.)"""

import numpy as np
import pytest

from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.authoring.placement import (CHARACTER_SEED, SOURCE_SEED, AgentSet,
                                                  CharacterStreams, PlacementPolicy,
                                                  place_agents, z_angle)

STREAMS = ["idle", "cheer", "sit"]
#: two characters: a fan with three streams and a kid with two
CAST = (CharacterStreams("fan", ("idle", "cheer", "sit"), (1.0, 1.0, 1.0), weight=3.0),
        CharacterStreams("kid", ("jump", "run"), (1.0, 3.0), weight=1.0))


def grid(nx, ny):
    """Points of an nx x ny grid (1 m apart) at z = 0, base headings 0."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1), np.zeros(x.size)


def place(policy=PlacementPolicy(), points=grid(20, 20), weights=(1, 1, 1), m=30, seed=4,
          forward="NEG_Y", attribute=None, characters=None):
    pos, heading = points
    cast = (CharacterStreams("fan", tuple(STREAMS), tuple(weights)),) if characters is None \
        else characters
    return place_agents("agent source 'seats'", pos, heading, policy, characters=cast,
                        max_offset=m, seed=seed, forward_axis=forward, attribute=attribute)


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
    with pytest.raises(CrowdError, match="agent source 'seats': character 'fan': agents: "
                                         "stream weights"):
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
                                         r"character 'fan' has streams 0..2"):
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


def test_characters_by_weight_are_seeded_and_keep_to_their_streams():
    a = place(points=grid(40, 40), characters=CAST)
    b = place(points=grid(40, 40), characters=CAST)
    np.testing.assert_array_equal(a.characters, b.characters)
    np.testing.assert_array_equal(a.streams, b.streams)
    assert a.characters.dtype == np.int32 and set(np.unique(a.characters)) == {0, 1}
    assert 0.72 < (a.characters == 0).mean() < 0.78                # weights 3 : 1
    # the crowd's streams are the fan's (0..2) then the kid's (3, 4)
    fan, kid = a.characters == 0, a.characters == 1
    assert set(np.unique(a.streams[fan])) == {0, 1, 2}
    assert set(np.unique(a.streams[kid])) == {3, 4}
    assert 0.7 < (a.streams[kid] == 4).mean() < 0.8                 # the kid's weights 1 : 3
    other = place(points=grid(40, 40), characters=CAST, seed=5)
    assert (other.characters != a.characters).any()
    # one character draws its streams as a crowd without characters did
    solo = place(points=grid(40, 40))
    assert (solo.characters == 0).all()
    np.testing.assert_array_equal(
        solo.streams, np.random.default_rng(4).choice(3, size=1600, p=[1 / 3] * 3))
    assert CHARACTER_SEED != SOURCE_SEED


def test_characters_by_attribute_or_by_name():
    pos, base = grid(4, 3)
    values = {"character": np.arange(12) % 2, "stream": np.arange(12) % 2}
    attribute = (lambda name, kind: values[name])
    a = place(PlacementPolicy(character_mode="ATTRIBUTE", stream_mode="ATTRIBUTE"),
              (pos, base), attribute=attribute, characters=CAST)
    np.testing.assert_array_equal(a.characters, values["character"])
    # stream index within the character: fan's stream k is k, kid's is 3 + k
    np.testing.assert_array_equal(a.streams, values["stream"] + 3 * values["character"])
    kid = place(PlacementPolicy(character_mode="FIXED", character_name="kid",
                                stream_mode="FIXED", stream_name="run"), characters=CAST)
    assert (kid.characters == 1).all() and (kid.streams == 4).all()
    values["character"] = np.array([0] * 9 + [2] + [0] * 2)
    with pytest.raises(CrowdError, match=r"agent source 'seats': attribute 'character' gives "
                                         r"character 2 at point 9; characters are 0..1 "
                                         r"\(\['fan', 'kid'\]\)"):
        place(PlacementPolicy(character_mode="ATTRIBUTE"), (pos, base), attribute=attribute,
              characters=CAST)
    values["character"] = np.ones(12, int)
    values["stream"] = np.array([0] * 4 + [2] + [0] * 7)
    with pytest.raises(CrowdError, match=r"attribute 'stream' gives stream 2 at point 4; "
                                         r"character 'kid' has streams 0..1 "
                                         r"\(\['jump', 'run'\]\)"):
        place(PlacementPolicy(character_mode="ATTRIBUTE", stream_mode="ATTRIBUTE"),
              (pos, base), attribute=attribute, characters=CAST)


def test_a_character_or_stream_that_does_not_fit_is_named():
    with pytest.raises(CrowdError, match=r"agent source 'seats': unknown character 'dog' "
                                         r"\(characters: \['fan', 'kid'\]\)"):
        place(PlacementPolicy(character_mode="FIXED", character_name="dog"), characters=CAST)
    with pytest.raises(CrowdError, match=r"agent source 'seats': stream 'cheer' is not a "
                                         r"stream of character 'kid' \(it is a stream of "
                                         r"'fan'; 'kid' has \['jump', 'run'\]\)"):
        place(PlacementPolicy(character_mode="FIXED", character_name="kid",
                              stream_mode="FIXED", stream_name="cheer"), characters=CAST)
    with pytest.raises(CrowdError, match="stream 'cheer' is not a stream of character 'kid'"):
        place(PlacementPolicy(stream_mode="FIXED", stream_name="cheer"), characters=CAST)
    with pytest.raises(CrowdError, match=r"character weights must be non-negative with a "
                                         r"positive sum \(\{'fan': 0.0, 'kid': 0.0\}\)"):
        place(characters=tuple(CharacterStreams(c.name, c.streams, c.stream_weights, 0.0)
                               for c in CAST))
    mute = (CAST[0], CharacterStreams("ghost", (), (), 1.0))
    with pytest.raises(CrowdError, match="character 'ghost' has no streams"):
        place(characters=mute)
    # a character without streams is fine as long as no agent is it
    assert (place(PlacementPolicy(character_mode="FIXED", character_name="fan"),
                  characters=mute).characters == 0).all()
    with pytest.raises(CrowdError, match="there are no characters"):
        place(characters=())


def test_each_kind_of_draw_has_a_random_stream_of_its_own():
    """Speed streams, palette colours, mesh variants and props are drawn from separate
    seeds: over 4,000 agents no two of them are correlated (a draw sharing another's
    seed and method would repeat it: correlation 1)."""
    from crowd_addon.core.authoring.placement import Palette
    from crowd_addon.core.variety.timing import Timing
    colours = tuple((i / 8, 0.5, 0.5) for i in range(8))
    cast = (CharacterStreams(
        "fan", ("idle",), (1.0,), timings=(Timing(0.6, 1.4, 8),),
        palettes=tuple(Palette(f"m{j}", colours) for j in range(3)),
        variant_weights=(1.0,) * 8, prop_shares=(0.5, 0.5)),)
    a = place(points=grid(80, 50), characters=cast)
    draws = {"speed": a.streams, "variant": a.variants, "prop0": a.props & 1,
             "prop1": a.props >> 1 & 1,
             **{f"palette{j}": a.palette[:, j, 0] for j in range(3)}}
    names = list(draws)
    for i, p in enumerate(names):
        assert len(np.unique(draws[p])) > 1, p
        for q in names[i + 1:]:
            r = np.corrcoef(draws[p].astype(float), draws[q].astype(float))[0, 1]
            assert abs(r) < 0.08, (p, q, r)
