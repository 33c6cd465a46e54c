"""Clips: validation, sampling (lerp / nlerp, loop / clamp), the clip bank and event tags."""

import numpy as np
import pytest

from crowd_addon.core.base import pose as sqt
from crowd_addon.core.anim.clip import Clip, ClipBank
from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

ROT, TRANS, SCALE = sqt.ROT, sqt.TRANS, sqt.SCALE


def random_keys(frames, bones, seed):
    rng = np.random.default_rng(seed)
    k = np.empty((frames, bones, 10))
    k[..., SCALE] = rng.uniform(0.5, 1.5, (frames, bones, 3))
    q = rng.normal(size=(frames, bones, 4))
    k[..., ROT] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    k[..., TRANS] = rng.normal(size=(frames, bones, 3))
    return k


def sample_ref(keys, u):
    """float64 reference at local time ``u`` in [0, F-1]: lerp S/T, shortest-arc nlerp R."""
    keys = np.asarray(keys, np.float64)
    i0 = min(int(np.floor(u)), len(keys) - 1)
    i1 = min(i0 + 1, len(keys) - 1)
    f = u - i0
    a, b = keys[i0], keys[i1]
    out = a + (b - a) * f
    sign = np.where(np.sum(a[:, ROT] * b[:, ROT], axis=1, keepdims=True) < 0, -1.0, 1.0)
    q = a[:, ROT] * (1 - f) + sign * b[:, ROT] * f
    out[:, ROT] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return out


def assert_pose_close(p, ref, atol):
    p = np.asarray(p, np.float64)
    ref = np.asarray(ref, np.float64)
    np.testing.assert_allclose(p[..., SCALE], ref[..., SCALE], atol=atol)
    np.testing.assert_allclose(p[..., TRANS], ref[..., TRANS], atol=atol)
    d = np.minimum(np.abs(p[..., ROT] - ref[..., ROT]).max(-1),
                   np.abs(p[..., ROT] + ref[..., ROT]).max(-1))
    assert d.max() <= atol, f"rotation distance {d.max()}"


# ----------------------------------------------------------------- validation

@pytest.mark.parametrize("frames", [0, 1])
def test_too_few_keys_rejected(frames):
    with pytest.raises(CrowdError, match=rf"clip 'idle': needs at least 2 keys, got {frames}"):
        Clip("idle", random_keys(max(frames, 1), 3, 0)[:frames])


def test_bad_key_shape_and_names():
    with pytest.raises(CrowdError, match=r"clip 'c': keys must be \(frames, bones, 10\)"):
        Clip("c", np.zeros((4, 3, 9)))
    with pytest.raises(CrowdError, match=r"clip 'c': keys must be"):
        Clip("c", np.zeros((4, 10)))
    with pytest.raises(CrowdError, match=r"clip: empty name"):
        Clip("", random_keys(3, 2, 0))
    with pytest.raises(CrowdError, match=r"clip 'c': 3 bone names for 2 bones"):
        Clip("c", random_keys(3, 2, 0), bone_names=("a", "b", "x"))


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_key_names_frame_and_bone(value):
    keys = random_keys(6, 3, 1)
    keys[4, 1, 8] = value
    with pytest.raises(CrowdError, match=r"clip 'walk': non-finite key at frame 4, bone 'spine'"):
        Clip("walk", keys, bone_names=("root", "spine", "head"))
    with pytest.raises(CrowdError, match=r"non-finite key at frame 4, bone 1\b"):
        Clip("walk", keys)


def test_zero_quaternion_names_frame_and_bone():
    keys = random_keys(6, 3, 2)
    keys[2, 2, ROT] = 0
    with pytest.raises(CrowdError, match=r"clip 'walk': zero rotation quaternion at frame 2, "
                                         r"bone 'head'"):
        Clip("walk", keys, bone_names=("root", "spine", "head"))


def test_bone_name_count_checked_before_naming_bad_key():
    keys = random_keys(4, 3, 3)
    keys[1, 2, 0] = np.nan
    with pytest.raises(CrowdError, match=r"clip 'c'"):
        Clip("c", keys, bone_names=("a",))


@pytest.mark.parametrize("frame", [-0.5, 5.01, 100])
def test_event_outside_range(frame):
    with pytest.raises(CrowdError, match=rf"clip 'walk': event 'step' at frame {frame}.*"
                                         r"outside 0\.\.5"):
        Clip("walk", random_keys(6, 2, 4), events=[("step", frame)])


def test_bad_event_tags_and_fps():
    with pytest.raises(CrowdError, match=r"event tag .* is not \(name, frame\)"):
        Clip("c", random_keys(3, 1, 0), events=[("step",)])
    with pytest.raises(CrowdError, match=r"event tag with an empty name"):
        Clip("c", random_keys(3, 1, 0), events=[("", 1)])
    for fps in (0, -24, np.nan):
        with pytest.raises(CrowdError, match=r"clip 'c': fps must be positive"):
            Clip("c", random_keys(3, 1, 0), fps=fps)


def test_unnormalised_quaternions_are_normalised():
    keys = random_keys(5, 4, 5)
    keys[..., ROT] *= np.random.default_rng(6).uniform(0.1, 10, (5, 4, 1))
    clip = Clip("c", keys)
    assert clip.keys.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(clip.keys[..., ROT], axis=-1), 1, atol=1e-6)
    expect = keys[..., ROT] / np.linalg.norm(keys[..., ROT], axis=-1, keepdims=True)
    np.testing.assert_allclose(clip.keys[..., ROT], expect, atol=1e-6)
    np.testing.assert_allclose(clip.keys[..., TRANS], keys[..., TRANS], atol=1e-6)


def test_properties_and_sorted_events():
    clip = Clip("c", random_keys(7, 3, 7), fps=24, loop=False,
                events=[("b", 5), ("a", 1.5), ("c", 0)])
    assert (clip.frame_count, clip.bone_count, clip.duration) == (7, 3, 6.0)
    assert clip.fps == 24.0 and clip.loop is False
    assert clip.events == (("c", 0.0), ("a", 1.5), ("b", 5.0))


# -------------------------------------------------------------------- sampling

def test_integer_frames_return_keys():
    keys = random_keys(9, 5, 8)
    for loop in (True, False):
        clip = Clip("c", keys, loop=loop)
        out = clip.sample(np.arange(8.0))
        np.testing.assert_allclose(out, clip.keys[:8], rtol=0, atol=2e-7)
    clamped = Clip("c", keys, loop=False)
    np.testing.assert_allclose(clamped.sample(8.0), clamped.keys[8], rtol=0, atol=2e-7)


def test_fractional_frames_interpolate():
    keys = random_keys(9, 5, 9)
    clip = Clip("c", keys, loop=False)
    ts = np.random.default_rng(10).uniform(0, 8, 40)
    out = clip.sample(ts)
    assert out.shape == (40, 5, 10) and out.dtype == np.float32
    for t, p in zip(ts, out):
        assert_pose_close(p, sample_ref(clip.keys, t), atol=2e-6)


def test_hand_made_interpolation_values():
    # bone 0 turns about z by 0.4 rad per key; translation moves (1, 2, 3) per key
    keys = np.zeros((4, 1, 10))
    keys[..., SCALE] = 1
    ang = 0.4 * np.arange(4)
    keys[:, 0, 3] = np.cos(ang / 2)
    keys[:, 0, 6] = np.sin(ang / 2)
    keys[:, 0, TRANS] = np.arange(4)[:, None] * [1, 2, 3]
    keys[2, 0, ROT] *= -1                       # same rotation, far hemisphere
    clip = Clip("c", keys, loop=False)
    p = clip.sample(1.25)[0]
    np.testing.assert_allclose(p[TRANS], [1.25, 2.5, 3.75], atol=1e-6)
    # nlerp between 0.4 and 0.8 rad at 1/4: direction of the chord, not the long way
    q = np.array([np.cos(0.2), 0, 0, np.sin(0.2)]) * 0.75 + \
        np.array([np.cos(0.4), 0, 0, np.sin(0.4)]) * 0.25
    q /= np.linalg.norm(q)
    assert min(np.abs(p[ROT] - q).max(), np.abs(p[ROT] + q).max()) < 1e-6


def test_sample_shapes():
    clip = Clip("c", random_keys(5, 3, 11))
    assert clip.sample(1.5).shape == (3, 10)
    assert clip.sample(np.zeros((2, 3))).shape == (2, 3, 3, 10)


def test_looping_wraps_with_period_f_minus_1():
    keys = random_keys(11, 4, 12)
    clip = Clip("c", keys, loop=True)
    ts = np.random.default_rng(13).uniform(0, 10, 20)
    base = clip.sample(ts)
    for k in (-3, -1, 1, 2, 7):
        assert_pose_close(clip.sample(ts + 10 * k), base, atol=5e-6)
    # t = F - 1 wraps to key 0 (the last key is the same instant as the first)
    np.testing.assert_allclose(clip.sample(10.0), clip.keys[0], atol=2e-7)
    assert_pose_close(clip.sample(10.5), sample_ref(clip.keys, 0.5), atol=2e-6)


def test_clamped_holds_ends():
    clip = Clip("c", random_keys(6, 3, 14), loop=False)
    for t in (5.0, 5.5, 17.0, 1e6):
        np.testing.assert_allclose(clip.sample(t), clip.keys[5], atol=2e-7)
    for t in (-0.1, -3.0):
        np.testing.assert_allclose(clip.sample(t), clip.keys[0], atol=2e-7)


def test_periodic_clip_has_matching_ends():
    sk = humanoid(bones=30)
    clip = periodic_clip(sk, "walk", frames=21)
    np.testing.assert_array_equal(clip.keys[0], clip.keys[-1])
    assert clip.bone_names == sk.bone_names


def test_periodic_clip_bones_limits_motion():
    sk = humanoid(bones=30)
    arms = [n for n in sk.bone_names if "arm" in n or "hand" in n]
    clip = periodic_clip(sk, "wave", bones=arms)
    still = ~np.isin(np.array(sk.bone_names), arms)
    np.testing.assert_allclose(clip.keys[:, still], np.broadcast_to(
        sk.bind_pose[still], clip.keys[:, still].shape), atol=1e-6)


# --------------------------------------------------------------------- bank

def test_bank_pads_different_bone_counts_with_identity():
    c3 = Clip("three", random_keys(5, 3, 15))
    c5 = Clip("five", random_keys(7, 5, 16), loop=False)
    bank = ClipBank([c3, c5], bone_count=6)
    assert bank.bone_count == 6 and bank.keys.shape == (5 + 7 + 1, 6, 10)
    ids = np.array([0, 1, 0, 1, 1])
    ts = np.array([0.0, 2.5, 3.7, 9.0, 6.0])
    out = bank.sample(ids, ts)
    assert out.shape == (5, 6, 10)
    ident = sqt.identity_pose(6)
    for i, (c, t) in enumerate(zip(ids, ts)):
        clip = (c3, c5)[c]
        assert_pose_close(out[i, :clip.bone_count], clip.sample(t), atol=1e-6)
        np.testing.assert_array_equal(out[i, clip.bone_count:], ident[clip.bone_count:])
    assert ClipBank([c3, c5]).bone_count == 5
    assert bank.index("five") == 1
    with pytest.raises(CrowdError, match=r"unknown clip 'six'"):
        bank.index("six")


def test_bank_local_time():
    bank = ClipBank([Clip("l", random_keys(5, 1, 0)), Clip("c", random_keys(5, 1, 0),
                                                            loop=False)])
    ids = np.array([0, 0, 0, 1, 1, 1])
    t = np.array([-1.0, 4.0, 9.5, -1.0, 4.0, 9.5])
    np.testing.assert_allclose(bank.local_time(ids, t), [3, 0, 1.5, 0, 4, 4])


# ------------------------------------------------------------------ crossings

def tag_bank(loop=True, frames=11, tags=(("step", 3.0), ("land", 7.5))):
    return ClipBank([Clip("c", random_keys(frames, 1, 0), loop=loop, events=tags)])


def crossed(bank, t0, t1, clip=0):
    which, tag = bank.crossings(np.array([clip]), np.array([t0]), np.array([t1]))
    return sorted(bank.tag_names[bank.tag_name[k]] for k in tag)


def test_crossings_half_open_interval():
    bank = tag_bank()
    assert crossed(bank, 2.0, 3.0) == ["step"]      # t1 == tau fires
    assert crossed(bank, 3.0, 4.0) == []            # t0 == tau does not
    assert crossed(bank, 2.9, 7.5) == ["land", "step"]
    assert crossed(bank, 7.5, 7.5) == []


def test_crossings_backwards_crosses_nothing():
    bank = tag_bank()
    assert crossed(bank, 4.0, 2.0) == []
    assert crossed(bank, 25.0, 1.0) == []
    assert crossed(ClipBank([Clip("c", random_keys(11, 1, 0), loop=False,
                                  events=[("s", 3)])]), 4.0, 2.0) == []


@pytest.mark.parametrize("step", [1.0, 0.37, 2.5, 9.99])
def test_crossings_once_per_crossing_across_loops(step):
    bank = tag_bank()
    period = 10.0
    t = np.arange(-3.0, 45.0, step)
    counts = {"step": 0, "land": 0}
    for t0, t1 in zip(t[:-1], t[1:]):
        for name in crossed(bank, t0, t1):
            counts[name] += 1
    for name, tau in (("step", 3.0), ("land", 7.5)):
        k = np.arange(-5, 10)
        inst = tau + k * period
        expect = int(np.sum((inst > t[0]) & (inst <= t[-1])))
        assert counts[name] == expect, (name, counts[name], expect)


def test_crossings_big_step_reports_tag_once():
    bank = tag_bank()
    assert crossed(bank, 0.0, 35.0) == ["land", "step"]


def test_crossings_clamped_fires_once():
    bank = tag_bank(loop=False, tags=(("step", 3.0), ("end", 10.0)))
    t = np.arange(-1.0, 40.0, 0.5)
    hits = [n for t0, t1 in zip(t[:-1], t[1:]) for n in crossed(bank, t0, t1)]
    assert hits == ["step", "end"]


def test_crossings_many_inputs_and_clips():
    a = Clip("a", random_keys(5, 1, 0), events=[("x", 1.0)])
    b = Clip("b", random_keys(9, 2, 0), events=[("y", 2.0), ("x", 6.0)])
    nothing = Clip("n", random_keys(3, 1, 0))
    bank = ClipBank([a, nothing, b])
    ids = np.array([0, 2, 1, 2, 0])
    t0 = np.array([0.5, 1.0, 0.0, 5.0, 1.0])
    t1 = np.array([1.5, 3.0, 2.0, 6.0, 4.9])
    which, tag = bank.crossings(ids, t0, t1)
    got = sorted((int(w), bank.tag_names[bank.tag_name[k]]) for w, k in zip(which, tag))
    assert got == [(0, "x"), (1, "y"), (3, "x")]
    np.testing.assert_array_equal(bank.tag_clip[tag], ids[which])


def test_sampling_between_keys_is_the_shortest_arc_blend_of_the_two_keys():
    """Between keys the bank interpolates toward the next key stored on the shortest
    arc: exactly :func:`pose.blend2` of the two keys (which tests the sign itself), for
    keys whose quaternions flip sign from one to the next, in two clips side by side
    (the last key of one is not blended toward the first of the other)."""
    rng = np.random.default_rng(5)
    k1, k2 = random_keys(9, 4, 1), random_keys(6, 4, 2)
    k1[1::2, :, 3:7] *= -1                        # the same rotations, signs flipped
    clips = [Clip("a", k1), Clip("b", k2, loop=False)]
    bank = ClipBank(clips)
    for clip in (0, 1):
        keys = clips[clip].keys                           # float32, as stored
        t = rng.uniform(0, len(keys) - 1, 200)
        t[:3] = (0.0, len(keys) - 1.0, len(keys) - 1.5)
        for t in (t, t[3:]):          # some at keys; all between keys (done in place)
            got = bank.sample(np.full(t.size, clip), t)
            u = bank.local_time(np.full(t.size, clip), t)    # the loop wraps its last key
            i0 = np.floor(u).astype(int)
            i1 = np.minimum(i0 + 1, len(keys) - 1)
            f = (u - i0).astype(np.float32)
            want = keys[i0].copy()
            part = f > 0
            want[part] = sqt.blend2(keys[i0[part]], keys[i1[part]], f[part])
            np.testing.assert_array_equal(got[:, :keys.shape[1]], want)
