"""How a crowd plays a clip: bound to each skeleton by bone name, at the clip's own rate.

Bone names: a clip with ``bone_names`` is matched to the skeleton that plays it by name;
the same bones in another order are remapped per (clip, skeleton), while a missing or
foreign bone is a configuration error naming the clip, the skeleton and the bones. A
clip without names keeps matching by index.

Rate: a clip keyed at ``clip.fps`` shows clip frame ``clip.fps / crowd fps * (start +
speed * t)`` at crowd time ``t``: speed 1 plays it at its own rate whatever its fps, and
event tags fire when that clip time crosses them.
"""

import numpy as np
import pytest

from crowd_addon.core import (Clip, ClipPlayer, Crowd, CrowdConfig, CrowdError, Layer,
                              Skeleton, StateMachine, StateTransition, validate_config)
from crowd_addon.core.planning import budget
from crowd_addon.core.base import pose as sqt
from crowd_addon.core.authoring.synthetic import humanoid, periodic_clip

SK = humanoid("fan", bones=24)
B = SK.bone_count


def reordered(skeleton, name, order):
    """``skeleton`` with its bones listed in ``order`` (parents still first)."""
    names = [skeleton.bone_names[i] for i in order]
    parents = [None if skeleton.parents[i] < 0 else skeleton.bone_names[skeleton.parents[i]]
               for i in order]
    return Skeleton.from_parent_names(name, names, parents,
                                      skeleton.bind_pose[np.asarray(order)])


def permuted(clip, name, order):
    """``clip`` with its key columns (and names) in ``order``: the same motion."""
    return Clip(name, clip.keys[:, order], fps=clip.fps, loop=clip.loop, events=clip.events,
                bone_names=[clip.bone_names[i] for i in order])


def by_name(pose, skeleton):
    return dict(zip(skeleton.bone_names, pose[:skeleton.bone_count]))


ORDER = np.random.default_rng(4).permutation(B)


def crowd_of(clips, streams, fps=30.0, skeletons=(SK,), m=4, agents=None):
    cfg = CrowdConfig(max_offset=m, transition_slots=2, fps=fps)
    for sk in skeletons:
        cfg.add_skeleton(sk)
    for c in clips:
        cfg.add_clip(c)
    for name, skel, root in streams:
        cfg.add_stream(name, skel, root)
    cfg.add_agents(len(streams) if agents is None else agents,
                   streams=np.arange(len(streams)) if agents is None else None,
                   offsets=np.zeros(len(streams) if agents is None else agents, np.int32))
    return cfg


# -------------------------------------------------------------------- bone names

def test_permuted_clip_plays_the_same_poses_and_events():
    """The same motion stored in another bone order plays bit for bit like the original
    (clip players, an additive layer's reference and event tags alike), and a second
    skeleton with yet another order plays the same clip right too."""
    walk = periodic_clip(SK, "walk", frames=17, seed=1, events=[("step", 5.0)])
    wave = periodic_clip(SK, "wave", frames=9, seed=2, amplitude=1.0)
    shuffled = permuted(walk, "walk_shuffled", ORDER)
    wave_shuffled = permuted(wave, "wave_shuffled", ORDER[::-1])
    other = reordered(SK, "other", np.r_[0, 1, np.arange(B - 1, 1, -1)])
    assert other.bone_names != SK.bone_names
    cfg = crowd_of([walk, wave, shuffled, wave_shuffled], [
        ("plain", "fan", Layer(ClipPlayer("walk", speed=0.75), ClipPlayer("wave"),
                               "additive", reference=("wave", 2.5))),
        ("shuffled", "fan", Layer(ClipPlayer("walk_shuffled", speed=0.75),
                                  ClipPlayer("wave_shuffled"), "additive",
                                  reference=("wave_shuffled", 2.5))),
        ("other", "other", Layer(ClipPlayer("walk_shuffled", speed=0.75),
                                 ClipPlayer("wave"), "additive", reference=("wave", 2.5))),
    ], skeletons=(SK, other))
    crowd = Crowd(cfg)
    fired = []
    crowd.on_event("step", lambda n, f, ids: fired.append((f, ids.tolist())))
    moved = 0.0
    for _ in range(30):
        crowd.step()
        plain, shuffled_pose = crowd.pose("plain"), crowd.pose("shuffled")
        assert plain.tobytes() == shuffled_pose.tobytes(), f"frame {crowd.frame}"
        theirs = by_name(crowd.pose("other"), other)
        ours = by_name(plain, SK)
        for n in SK.bone_names:
            np.testing.assert_allclose(theirs[n], ours[n], atol=1e-6, err_msg=n)
        moved = max(moved, float(np.abs(plain - crowd.pose("plain", 1)).max()))
    assert moved > 1e-2
    # "step" at clip frame 5, speed 0.75: every 16 / 0.75 frames, for all three streams
    assert fired and all(ids == [0, 1, 2] for _, ids in fired)
    # one bank entry per distinct (clip, bone order): the four clips, walk_shuffled for
    # "fan" and for "other", wave_shuffled for "fan", wave for "other"
    assert crowd.bank.frames.size == 4 + 4


@pytest.mark.parametrize("case, message", [
    ("foreign", r"clip 'walk' \(24 bones\) does not match skeleton 'fan' \(24 bones\): it "
                r"names bones the skeleton lacks \['ghost'\] and lacks bones the skeleton has "
                r"\['head'\]"),
    ("fewer", r"clip 'walk' \(21 bones\) does not match skeleton 'fan' \(24 bones\): it "
              r"lacks bones the skeleton has \['finger3_1\.L', 'finger3_2\.L', 'finger4_0\.L'\]"),
    ("more", r"clip 'walk' \(31 bones\) does not match skeleton 'fan' \(24 bones\): it "
             r"names bones the skeleton lacks \['tail0', 'tail1', 'tail2', 'tail3', 'tail4'\] "
             r"\(and 2 more\)"),
])
def test_clip_with_other_bones_is_named_at_configuration(case, message):
    walk = periodic_clip(SK, "walk", frames=9, seed=1)
    names = list(SK.bone_names)
    keys = walk.keys
    if case == "foreign":
        names[names.index("head")] = "ghost"
    elif case == "fewer":
        names, keys = names[:-3], keys[:, :-3]
    else:
        names += [f"tail{i}" for i in range(7)]
        keys = np.concatenate([keys, np.repeat(keys[:, :7], 1, axis=1)], axis=1)
    bad = Clip("walk", keys, bone_names=names)
    for root in (ClipPlayer("walk"),
                 Layer(ClipPlayer("idle"), ClipPlayer("idle"), "additive",
                       reference=("walk", 1))):
        cfg = crowd_of([bad, periodic_clip(SK, "idle", frames=9)], [("s", "fan", root)])
        with pytest.raises(CrowdError, match=r"stream 's': " + message):
            validate_config(cfg)
        with pytest.raises(CrowdError, match=message):
            Crowd(cfg)


def test_clip_without_bone_names_still_matches_by_index():
    walk = periodic_clip(SK, "walk", frames=9, seed=1)
    anonymous = Clip("anon", walk.keys, fps=walk.fps)
    crowd = Crowd(crowd_of([walk, anonymous], [("a", "fan", ClipPlayer("walk")),
                                               ("b", "fan", ClipPlayer("anon"))]))
    for _ in range(5):
        crowd.step()
        assert crowd.pose("a").tobytes() == crowd.pose("b").tobytes()
    short = Clip("short", walk.keys[:, :-1])
    with pytest.raises(CrowdError, match=r"clip 'short' has 23 bones but skeleton 'fan' has 24"):
        Crowd(crowd_of([short], [("a", "fan", ClipPlayer("short"))]))


def test_clip_bone_names_must_be_unique():
    walk = periodic_clip(SK, "walk", frames=9, seed=1)
    names = list(SK.bone_names)
    names[3] = names[2]
    with pytest.raises(CrowdError, match=r"clip 'w': duplicate bone name 'spine0' "
                                         r"\(columns 2 and 3\)"):
        Clip("w", walk.keys, bone_names=names)


# -------------------------------------------------------------------------- rate

def dense_and_sparse(fps_dense, fps_sparse, frames=41, **kw):
    """The same looping motion keyed at two rates (the dense keys include the sparse)."""
    dense = periodic_clip(SK, "dense", frames=frames, seed=7, fps=fps_dense, **kw)
    step = int(round(fps_dense / fps_sparse))
    sparse = Clip("sparse", dense.keys[::step], fps=fps_sparse, loop=dense.loop,
                  events=[(n, f / step) for n, f in dense.events], bone_names=dense.bone_names)
    return dense, sparse


def test_clip_plays_at_its_own_rate():
    """A 48 fps clip and the same motion at 24 fps show the same pose at every frame of
    a 24 fps crowd (the dense clip advances two keys a frame), loop with the same period
    and fire their tags at the same frames."""
    dense, sparse = dense_and_sparse(48.0, 24.0, events=[("clap", 10.0)])
    assert sparse.frame_count == 21 and sparse.events == (("clap", 5.0),)
    cfg = crowd_of([dense, sparse], [("dense", "fan", ClipPlayer("dense")),
                                     ("sparse", "fan", ClipPlayer("sparse"))], fps=24.0)
    crowd = Crowd(cfg)
    fired = []
    crowd.on_event("clap", lambda n, f, ids: fired.append((f, ids.tolist())))
    for _ in range(45):
        crowd.step()
        assert crowd.pose("dense").tobytes() == crowd.pose("sparse").tobytes(), crowd.frame
        np.testing.assert_array_equal(crowd.pose("dense")[:B], sparse.keys[crowd.frame % 20])
    # period 20 crowd frames, tag at crowd frame 5 of each loop, both streams together
    assert fired == [(5, [0, 1]), (25, [0, 1]), (45, [0, 1])]


def test_speed_start_and_reference_are_crowd_frames():
    """``start + speed * t`` and an additive reference frame count crowd frames; the clip
    frame is that times clip fps / crowd fps."""
    dense = periodic_clip(SK, "dense", frames=41, seed=7, fps=60.0)
    wave = periodic_clip(SK, "wave", frames=13, seed=3, fps=60.0, amplitude=1.0)
    rate = 60.0 / 24.0
    cfg = crowd_of([dense, wave], [
        ("clip", "fan", ClipPlayer("dense", speed=0.7, start=3.5)),
        ("layer", "fan", Layer(ClipPlayer("dense"), ClipPlayer("wave"), "additive",
                               reference=("wave", 4.8))),                 # the last key
        ("fsm", "fan", StateMachine({"a": ClipPlayer("wave"), "b": ClipPlayer("dense")},
                                    [StateTransition("a", "b", 0, trigger="go")])),
    ], fps=24.0)
    crowd = Crowd(cfg)
    for _ in range(9):
        crowd.step()
    t = float(crowd.frame)
    np.testing.assert_allclose(crowd.pose("clip")[:B], dense.sample(rate * (3.5 + 0.7 * t)),
                               atol=1e-6)
    ref = wave.keys[-1]
    delta = sqt.additive_delta(wave.sample(rate * t)[None], ref[None])
    want = sqt.apply_additive(dense.sample(rate * t)[None], delta, np.float32(1))[0]
    np.testing.assert_allclose(crowd.pose("layer")[:B], want, atol=1e-6)
    crowd.set_trigger("fsm", "go")
    crowd.step()
    crowd.step()                                  # entered one frame ago
    np.testing.assert_allclose(crowd.pose("fsm")[:B], dense.sample(rate * 1.0), atol=1e-6)
    # the reference frame may not pass the clip's length in crowd frames (12 / 2.5)
    bad = crowd_of([dense, wave], [("layer", "fan", Layer(
        ClipPlayer("dense"), ClipPlayer("wave"), "additive", reference=("wave", 5.0)))],
        fps=24.0)
    with pytest.raises(CrowdError, match=r"reference frame 5\.0 outside clip 'wave' "
                                         r"\(0\.\.4\.8 frames at 24 fps\)"):
        Crowd(bad)


def test_clip_length_in_crowd_frames():
    dense = periodic_clip(SK, "dense", frames=41, fps=48.0)
    assert dense.duration == 40.0 and dense.seconds == pytest.approx(40 / 48)
    assert dense.frames_at(24.0) == 20.0 and dense.frames_at(48.0) == 40.0


def test_budget_counts_clip_lengths_in_crowd_frames():
    """A 41-key clip at 48 fps lasts 20 frames of a 24 fps crowd: M may not exceed 20."""
    dense = periodic_clip(SK, "dense", frames=41, fps=48.0)
    p = budget.plan(1000, 520e6, 24, [dense, 300], fps=24.0, offset_seconds=2.0)
    assert p.max_offset == 20 and "shortest clip (20 frames)" in p.notes[0]
    with pytest.raises(CrowdError, match=r"max_offset 21 exceeds the shortest clip \(20 "):
        budget.plan(1000, 520e6, 24, [dense], fps=24.0, max_offset=21)
