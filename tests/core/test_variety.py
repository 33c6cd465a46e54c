"""Timing variation (core.variety): a stream's speed and phase, templates made into
speed streams and copies, and agents placed on them.

Oracles: a clip player with the same speed and start (what a stream at a speed and
phase must show, bitwise, events included), the stream's own head a copy's offsets
reach (copies extend the history), and the template's own placement (agents keep
their template, variants only split it)."""

import json

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig, CrowdError
from crowd_addon.core.authoring.config import AnimationDef, validate_config
from crowd_addon.core.authoring.config_io import config_digest, load_config, save_config
from crowd_addon.core.authoring.placement import CharacterStreams, PlacementPolicy, place_agents
from crowd_addon.core.anim.sub_keys import SUB_KEYS, on_grid, sub_key_bytes
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip
from crowd_addon.core.variety.timing import Timing, choose_variants, expand

SK = humanoid("fan", 12)


def one_stream(speed=1.0, phase=0.0, player=None, m=4, substeps=1):
    cfg = CrowdConfig(max_offset=m, transition_slots=2)
    cfg.add_skeleton(SK)
    cfg.add_clip(periodic_clip(SK, "c", frames=40, seed=1, events=[("tap", 5.0)]))
    cfg.add_stream("s", "fan", player or ClipPlayer("c"), speed, phase)
    cfg.add_agents(4, offsets=[0, 1, 3, m - 1])
    return Crowd(cfg, substeps=substeps)


@pytest.mark.parametrize("speed,phase", [(1.25, 4.5), (0.75, -3.0), (2.0, 0.0)])
def test_a_stream_at_a_speed_and_phase_plays_its_tree_so(speed, phase):
    """Root time ``phase + speed * F``: the same as a clip player started at ``phase``
    playing at ``speed``, pose for pose and tag for tag, sub-frame samples too (speeds
    and phases whose times, half frames included, are on the 1/8-frame grid, so the
    grid changes none)."""
    a = one_stream(speed, phase, substeps=2)
    b = one_stream(player=ClipPlayer("c", speed=speed, start=phase), substeps=2)
    heard = [[], []]
    for crowd, log in zip((a, b), heard):
        crowd.on_event("tap", lambda n, f, ids, log=log: log.append((f, ids.tolist())))
    for _ in range(40):
        a.step()
        b.step()
        for k in range(2):
            np.testing.assert_array_equal(a.view.agent_poses(sub=k),
                                          b.view.agent_poses(sub=k))
    assert heard[0] == heard[1] and len(heard[0]) >= 3


@pytest.mark.parametrize("speed,phase", [(1.37, 4.3), (0.6, -3.0), (0.925, 0.0)])
def test_a_stream_at_a_speed_moves_on_the_sub_frame_grid_of_its_resampled_clip(speed,
                                                                              phase):
    """A stream at another speed than 1 plays its clip at ``phase + speed * t`` rounded
    to the nearest 1/8 frame, sub-frame samples too: each pose is the clip's own
    interpolation at that time, bit for bit, and comes from keys resampled once at
    every 1/8 frame (one gather a frame, no interpolation)."""
    a = one_stream(speed, phase, substeps=3)
    clip = a.config.clips["c"]
    sub = a.bank.sub_keys
    assert sub is not None and sub.nbytes == (39 * SUB_KEYS + 1) * SK.bone_count * 40
    assert sub_key_bytes(a.config) == sub.nbytes
    for _ in range(40):
        a.step()
        for k in range(3):
            exact = phase + speed * (a.frame + k / 3)
            t = on_grid(exact)
            assert abs(t - exact) <= 1 / (2 * SUB_KEYS) and (t * SUB_KEYS).is_integer()
            np.testing.assert_array_equal(a.view.agent_poses(sub=k)[0], clip.sample(t))
    plain = one_stream()
    assert plain.bank.sub_keys is None          # speed 1: no resampled keys, no grid


def test_speed_and_phase_round_trip_and_defaults_hash_as_before(tmp_path):
    plain = one_stream().config
    digest = config_digest(plain)
    save_config(plain, tmp_path / "plain.json")
    stream = json.loads((tmp_path / "plain.json").read_text())["streams"][0]
    assert "speed" not in stream and "phase" not in stream
    assert config_digest(load_config(tmp_path / "plain.json")) == digest
    timed = one_stream(1.25, 7.5).config
    timed.streams[0].template = "idle"
    save_config(timed, tmp_path / "timed.json")
    back = load_config(tmp_path / "timed.json")
    assert (back.streams[0].speed, back.streams[0].phase) == (1.25, 7.5)
    assert back.streams[0].template_name == "idle" and plain.streams[0].template_name == "s"
    assert config_digest(back) == config_digest(timed) != digest


def test_bad_speeds_are_named(tmp_path):
    with pytest.raises(CrowdError, match="stream 's': speed must be a finite number > 0"):
        AnimationDef("s", "fan", ClipPlayer("c"), speed=0)
    with pytest.raises(CrowdError, match="phase must be finite"):
        AnimationDef("s", "fan", ClipPlayer("c"), phase=float("inf"))
    cfg = one_stream().config
    cfg.add_unique("u", "fan", ClipPlayer("c"))
    cfg.uniques[0].speed = 2.0
    with pytest.raises(CrowdError, match="unique 'u': uniques keep their own clocks"):
        validate_config(cfg)
    cfg.uniques[0].speed = 1.0
    save_config(cfg, tmp_path / "c.json")
    text = (tmp_path / "c.json").read_text().replace('"name": "u"', '"name": "u", "phase": 2')
    (tmp_path / "c.json").write_text(text)
    with pytest.raises(CrowdError, match=r"uniques\[0\].*own clocks"):
        load_config(tmp_path / "c.json")


def test_a_template_becomes_its_speed_streams_and_copies():
    t = Timing(0.8, 1.2, 4, 2)
    got = expand("idle", t, max_offset=30, origin=10)
    speeds = [0.85, 0.95, 1.05, 1.15]
    assert [g[1] for g in got] == pytest.approx(np.repeat(speeds, 2))
    # the speed nearest 1 (the lower of 0.95 and 1.05), first copy, keeps the name
    assert [g[0] for g in got] == ["idle 0.85x", "idle 0.85x #2", "idle", "idle 0.95x #2",
                                   "idle 1.05x", "idle 1.05x #2", "idle 1.15x",
                                   "idle 1.15x #2"]
    for (_, v, phase), c in zip(got, [0, 1] * 4):
        # at the origin every first copy is where the template is; copy c is c*M ahead
        assert phase + v * 10 == pytest.approx(10 + c * v * 30)
    assert expand("idle", Timing(), 30) == [("idle", 1.0, 0.0)]
    assert [g[0] for g in expand("idle", Timing(copies=3), 30)] == ["idle", "idle #2",
                                                                     "idle #3"]


@pytest.mark.parametrize("timing,message", [
    (Timing(1.2, 0.8), "the speed range must be finite with 0 < min <= max"),
    (Timing(0.0, 1.0), "the speed range"),
    (Timing(1.0, 1.0, 3), "3 speed streams need a speed range"),
    (Timing(0.5, 1.5, 0), "speed streams must be a whole number >= 1"),
    (Timing(0.5, 1.5, 2, 1.5), "copies must be a whole number"),
    (Timing(0.5, 1.5, 32, 16), "32 speeds x 16 copies make 512 streams, more than 256"),
])
def test_bad_timing_is_named(timing, message):
    with pytest.raises(CrowdError, match=f"stream 'idle': {message}"):
        expand("idle", timing, 30)


def test_copies_extend_the_history():
    """Copy 1 at offset O shows what copy 0's head shows M - O frames later: the two
    cover 2 M consecutive poses of the tree."""
    m, v = 5, 1.3
    cfg = CrowdConfig(max_offset=m, transition_slots=0)
    cfg.add_skeleton(SK)
    cfg.add_clip(periodic_clip(SK, "c", frames=60, seed=2))
    for name, speed, phase in expand("s", Timing(v, v, 1, 2), m):
        cfg.add_stream(name, "fan", ClipPlayer("c"), speed, phase)
    cfg.add_agents(m, streams=np.ones(m, int), offsets=np.arange(m))   # copy 1, every O
    cfg.add_agents(1, streams=0, offsets=[0])                            # copy 0's head
    crowd = Crowd(cfg)
    heads, shown = {}, {}
    for _ in range(4 * m):
        crowd.step()
        heads[crowd.frame] = crowd.view.agent_poses([m])[0]
        shown[crowd.frame] = crowd.view.agent_poses(np.arange(m))
    checked = 0
    for f, poses in shown.items():
        for o in range(m):
            if f - o + m in heads:
                np.testing.assert_allclose(poses[o], heads[f - o + m], atol=2e-5)
                checked += 1
    assert checked > 2 * m * m


def test_variants_take_the_nearest_speed_and_any_copy():
    t = Timing(0.5, 1.5, 5, 3)
    v = choose_variants(60000, t, seed=4)
    np.testing.assert_array_equal(v, choose_variants(60000, t, seed=4))
    assert not np.array_equal(v, choose_variants(60000, t, seed=5))
    counts = np.bincount(v, minlength=15)
    assert counts.min() > 0.9 * 4000 and counts.max() < 1.1 * 4000   # uniform speeds
    assert choose_variants(10, Timing(), 1).tolist() == [0] * 10


def test_placement_keeps_each_agent_on_its_template():
    chars = (CharacterStreams("fan", ("idle", "clap"), (1.0, 1.0)),
             CharacterStreams("kid", ("play",)))
    timed = (CharacterStreams("fan", ("idle", "clap"), (1.0, 1.0),
                              timings=(Timing(0.8, 1.2, 3, 2), Timing())),
             CharacterStreams("kid", ("play",), timings=(Timing(copies=4),)))
    pos = np.random.default_rng(0).uniform(-10, 10, (3000, 3))
    args = dict(max_offset=20, seed=9)
    a = place_agents("src", pos, np.zeros(3000), PlacementPolicy(), characters=chars, **args)
    b = place_agents("src", pos, np.zeros(3000), PlacementPolicy(), characters=timed, **args)
    # the crowd's streams: idle x 6, clap, play x 4; the template index of each
    template = np.array([0] * 6 + [1] + [2] * 4)
    np.testing.assert_array_equal(template[b.streams], a.streams)
    np.testing.assert_array_equal(b.offsets, a.offsets)
    np.testing.assert_array_equal(b.characters, a.characters)
    assert set(b.streams[a.streams == 0].tolist()) == set(range(6))
    assert set(b.streams[a.streams == 2].tolist()) == {7, 8, 9, 10}
    again = place_agents("src", pos, np.zeros(3000), PlacementPolicy(), characters=timed,
                         **args)
    np.testing.assert_array_equal(again.streams, b.streams)
    # by attribute: the point's template, its variant drawn
    pick = place_agents("src", pos[:5], np.zeros(5),
                        PlacementPolicy(character_mode="FIXED", character_name="fan",
                                        stream_mode="ATTRIBUTE"),
                        characters=timed, attribute=lambda n, k: np.array([0, 1, 1, 0, 0]),
                        **args)
    assert pick.streams[1] == pick.streams[2] == 6 and set(pick.streams[[0, 3, 4]]) <= set(
        range(6))


def test_spread_offsets_keep_neighbours_on_one_stream_out_of_step():
    """Seats on a grid, three streams: uniform offsets leave neighbours in step, the
    Spread mode none (within M / 17 frames), and the repetition metric of a top view
    drops accordingly; seeded."""
    from crowd_addon.core.variety.repetition import RepetitionSettings, frame_repetition
    from crowd_addon.core.variety.repetition import nearest_neighbours
    from crowd_addon.core.variety.timing import spread_offsets
    rng = np.random.default_rng(0)
    n, m = 4000, 60
    pos = np.zeros((n, 3))
    pos[:, 0], pos[:, 1] = np.arange(n) % 80 * 0.6, np.arange(n) // 80 * 0.9
    st = rng.integers(0, 3, n)
    off = spread_offsets(pos, st, m, seed=3)
    np.testing.assert_array_equal(off, spread_offsets(pos, st, m, seed=3))
    assert off.min() >= 0 and off.max() < m
    nb = nearest_neighbours(pos[:, :2], 8)
    same = st[nb] == st[:, None]
    assert not (same & (np.abs(off[:, None] - off[nb]) <= m // 17)).any()
    uniform = rng.integers(0, m, n)
    assert (same & (np.abs(uniform[:, None] - uniform[nb]) <= m // 17)).any()
    assert np.bincount(off, minlength=m).min() > 0.5 * n / m       # still spread over 0..M-1
    top = np.diag([1 / 30, 1 / 30, -0.001, 1.0])
    top[:2, 3] = -1
    args = (np.zeros(n, np.int8), st)
    look, col = np.zeros(n), np.zeros((n, 3))
    s = RepetitionSettings(k=6)
    spread = frame_repetition(pos, *args, off, look, col, top, s)[0]
    plain = frame_repetition(pos, *args, uniform, look, col, top, s)[0]
    assert spread < plain / 20, (spread, plain)   # screen neighbours are nearly the ground's


def test_placement_spread_mode():
    chars = (CharacterStreams("fan", ("idle", "clap")),)
    pos = np.random.default_rng(1).uniform(0, 30, (500, 3))
    got = place_agents("src", pos, np.zeros(500), PlacementPolicy(offset_mode="SPREAD"),
                       characters=chars, max_offset=30, seed=2)
    from crowd_addon.core.variety.timing import spread_offsets
    np.testing.assert_array_equal(got.offsets, spread_offsets(pos, got.streams, 30, 3))


def test_resampled_entries_give_the_banks_own_floats_on_and_off_the_grid():
    """Entries resampled at sub-frames (core.anim.sub_keys) next to entries that are
    not, sampled together on the grid, off it and at whole frames, with and without an
    output array: the same floats as the bank interpolating every one."""
    from crowd_addon.core.anim.clip import ClipBank
    clips = [periodic_clip(SK, "a", frames=20, seed=1), periodic_clip(SK, "b", frames=30,
                                                                     seed=2)]
    bank, plain = ClipBank(clips), ClipBank(clips)
    bank.resample([0])
    ids = np.array([0, 1, 0, 1, 0])
    for t in (np.array([2.125, 3.25, 5.3, 7.0, 44.5]),        # mixed
              np.array([2.125, 3.0, 5.25, 7.0, 19.875]),      # all on the grid
              np.array([0.3, 1.7, 2.2, 3.9, 4.1])):           # none
        want = plain.sample(ids, t)
        np.testing.assert_array_equal(bank.sample(ids, t), want)
        out = np.empty_like(want)
        np.testing.assert_array_equal(bank.sample(ids, t, out=out), want)


def test_resampled_keys_stop_at_their_memory_cap_and_the_rest_interpolate():
    """Past ``max_bytes`` an entry is not resampled (long clips, many of them): it
    interpolates at the grid times, the same floats."""
    from crowd_addon.core.anim.clip import ClipBank
    from crowd_addon.core.anim.sub_keys import SubKeys
    clips = [periodic_clip(SK, "a", frames=20, seed=1), periodic_clip(SK, "b", frames=30,
                                                                     seed=2)]
    bank, plain = ClipBank(clips), ClipBank(clips)
    one = (19 * SUB_KEYS + 1) * bank.keys.shape[1] * 40        # entry 0's keys exactly
    bank.sub_keys = SubKeys(bank, [0, 1], max_bytes=one)
    assert bank.sub_keys.nbytes == one and bank.sub_keys.start[1] == -1
    ids, t = np.array([0, 1, 0, 1]), np.array([2.125, 3.25, 7.5, 28.875])
    np.testing.assert_array_equal(bank.sample(ids, t), plain.sample(ids, t))
