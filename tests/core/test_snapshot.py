"""Exact snapshots (core/shots/snapshot.py): simulate to frame F, snapshot, restore into a
fresh crowd (or the same one, or through a file) and continue. The oracle is the
uninterrupted run: every later frame's local poses (and, on the CPU, skinning rows)
equal it bit for bit, and so do the events and the show's counts."""

import re

import numpy as np
import pytest

from crowd_addon.core import Crowd, CrowdError
from crowd_addon.core.runtime.agents import TRANSITION
from crowd_addon.core.authoring.config_io import save_config
from crowd_addon.core.authoring.show import Action, Cue, Reaction, Show, Sweep, Track
from crowd_addon.core.shots.snapshot import HEADER, load_snapshot

from .test_recording import config as recording_config
from .test_recording import simulate
from .test_show import N, make_config

LAST = 48


def show():
    """Every cue kind the show runs: a held sweep, a held random-offset stand, a unique
    with its return, a parameter cue, trigger and parameter tracks, and a reaction
    reaching the neighbours of the agents whose clap fired. Six slots: a queue forms."""
    return Show((Cue("wave", 3, Action("stream", "wave", 4, hold=6),
                     sweep=Sweep((0, 0, 0), "angle", 1.5)),
                 Cue("stand", 9, Action("stream", "cheer", 3, offset="random", hold=12),
                     agents=np.arange(0, N, 3), seed=4),
                 Cue("hit", 14, Action("unique", "hit", 2, hold=9), agents=np.array([5])),
                 Cue("w", 6, Action("parameter", "mix", name="w", value=0.7)),
                 Cue("answer", 0, Action("stream", "idle", 2, offset=1), timeline=False)),
                tracks=(Track("fsm", "go", 1, (np.arange(60) % 10 == 5).astype(float),
                              "trigger"),
                        Track("mix", "w", 20, np.linspace(0, 1, 15))),
                reactions=(Reaction("near clap", "clap", "answer", radius=2.1),))


def show_crowd(skinning="gpu", substeps=1):
    crowd = Crowd(make_config(show(), slots=6), skinning=skinning, substeps=substeps)
    by_python(crowd)
    return crowd


def by_python(crowd, event="breath", stream="fsm"):
    """A Python callback that requests a transition from inside a step. It keeps no
    state of its own: a snapshot holds the crowd's state, not a callback's."""
    def react(name, frame, ids):
        if frame % 4 == 0:
            crowd.transition_to_streamed(ids[:2], stream, 5)
    crowd.on_event(event, react)


def recording_crowd(skinning="gpu", substeps=1):
    crowd = Crowd(recording_config(), skinning=skinning, substeps=substeps)
    by_python(crowd, "jump", "kid play")
    return crowd


def play(crowd, last, drive=None):
    """Step to ``last``: per frame the agents' poses (every sample), the skinning rows
    on the CPU, what each agent plays, and every event with its agents."""
    heard = []
    handle = crowd.on_event("*", lambda n, f, ids: heard.append((n, f, ids.tolist())))
    out = []
    while crowd.frame < last:
        if drive is not None:
            drive(crowd, crowd.frame + 1)
        crowd.step()
        v = crowd.view
        out.append({"poses": [v.agent_poses(sub=k) for k in range(v.substeps)],
                    "rows": v.agent_rows() if not v.skinning.on_gpu else None,
                    "kind": v.agents.kind.copy(), "ref": v.agents.ref.copy(),
                    "offset": v.agents.offset.copy(), "position": v.agents.position.copy()})
    crowd.events.off(handle)
    return out, heard


def assert_same(a, b):
    assert len(a) == len(b)
    for fa, fb in zip(a, b):
        for k in fa:
            if k == "poses":
                for pa, pb in zip(fa[k], fb[k]):
                    np.testing.assert_array_equal(pa, pb)
            elif fa[k] is not None:
                np.testing.assert_array_equal(fa[k], fb[k], err_msg=k)


CASES = {"show": (show_crowd, None), "recording": (recording_crowd, simulate)}


@pytest.mark.parametrize("skinning", ["gpu", "cpu"])
@pytest.mark.parametrize("case", list(CASES))
def test_a_restored_crowd_continues_exactly(case, skinning):
    """Snapshots at several frames (before the show starts, mid-transition with a queue,
    mid-hold, after the returns) restored into a fresh crowd: the rest of the run equals
    the uninterrupted one, poses, rows, events and show counts alike."""
    make, drive = CASES[case]
    straight = make(skinning)
    snaps = {}

    def drive_and_snap(crowd, frame):
        if frame - 1 in (2, 8, 11, 17, 30):
            snaps[frame - 1] = crowd.snapshot()
        if drive is not None:
            drive(crowd, frame)
    whole, heard = play(straight, LAST, drive_and_snap)
    checked = {"transitioning": 0, "queued": 0}
    for f, snap in snaps.items():
        fresh = make(skinning)
        fresh.restore(snap)
        assert fresh.frame == f
        checked["transitioning"] += int((fresh.agents.kind == TRANSITION).any())
        checked["queued"] += int(len(fresh.slots.queue) > 0)
        rest, rest_heard = play(fresh, LAST, drive)
        assert_same(rest, whole[f + 1 - whole_first(straight, whole):])
        assert rest_heard == [e for e in heard if e[1] > f]
        if fresh.show is not None:
            assert fresh.show.stats == straight.show.stats
            assert fresh.show.reactions == straight.show.reactions
        assert dict(fresh.events.fired) == dict(straight.events.fired)
    # the snapshots really caught blends in flight and a waiting queue
    assert checked["transitioning"] >= 3 and checked["queued"] >= 1, checked


def whole_first(crowd, whole):
    """The frame of ``whole[0]``."""
    return crowd.frame - len(whole) + 1


def test_restoring_into_the_same_crowd_goes_back_and_forward():
    crowd = show_crowd()
    play(crowd, 12)
    at12 = crowd.snapshot()
    later, _ = play(crowd, 30)
    at30 = crowd.snapshot()
    crowd.restore(at12)
    again, _ = play(crowd, 30)
    assert_same(again, later)
    crowd.restore(at12)
    crowd.restore(at30)                       # forward, past frames never simulated
    assert crowd.frame == 30
    a, _ = play(crowd, 40)
    crowd.restore(at30)
    b, _ = play(crowd, 40)
    assert_same(a, b)


def test_sub_frame_samples_continue_exactly():
    straight = show_crowd(substeps=3)
    play(straight, 20)
    snap = straight.snapshot()
    whole, heard = play(straight, 36)
    fresh = show_crowd(substeps=3)
    fresh.restore(snap)
    rest, rest_heard = play(fresh, 36)
    assert_same(rest, whole)
    assert rest_heard == heard


def test_a_snapshot_file_restores_in_another_process(tmp_path):
    """Saved, loaded and restored by a fresh Python process from the configuration file:
    the continuation there equals this process's (the digest is the same there)."""
    import json
    import subprocess
    import sys
    cfg_path = tmp_path / "crowd.json"
    save_config(make_config(show(), slots=6), cfg_path)
    from crowd_addon.core.authoring.config_io import load_config
    crowd = Crowd(load_config(cfg_path))
    play(crowd, 15)
    crowd.snapshot().save(tmp_path / "at15.npz")
    rest, _ = play(crowd, 25)
    script = (
        "import json, sys, numpy as np\n"
        "from crowd_addon.core import Crowd\n"
        "from crowd_addon.core.authoring.config_io import load_config\n"
        "from crowd_addon.core.shots.snapshot import load_snapshot\n"
        "c = Crowd(load_config(sys.argv[1]))\n"
        "c.restore(load_snapshot(sys.argv[2]))\n"
        "out = []\n"
        "while c.frame < 25:\n"
        "    c.step()\n"
        "    out.append(c.agent_poses().tobytes().hex())\n"
        "print(json.dumps(out))\n")
    run = subprocess.run([sys.executable, "-c", script, str(cfg_path),
                          str(tmp_path / "at15.npz")], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    there = json.loads(run.stdout.strip().splitlines()[-1])
    assert there == [f["poses"][0].tobytes().hex() for f in rest]


def test_the_file_round_trip_is_exact(tmp_path):
    crowd = show_crowd()
    play(crowd, 17)
    snap = crowd.snapshot()
    snap.save(tmp_path / "s.npz")
    back = load_snapshot(tmp_path / "s.npz")
    assert (back.frame, back.config_digest, back.substeps) == (17, crowd.config_digest, 1)
    assert back.values == snap.values
    assert set(back.arrays) == set(snap.arrays)
    for k, a in snap.arrays.items():
        assert back.arrays[k].dtype == a.dtype
        np.testing.assert_array_equal(back.arrays[k], a, err_msg=k)
    assert 0 < snap.nbytes <= (tmp_path / "s.npz").stat().st_size


def poses_now(crowd):
    return crowd.agent_poses().copy(), crowd.frame, crowd.slots.active.copy()


def test_a_snapshot_of_another_crowd_is_named_and_changes_nothing():
    crowd = show_crowd()
    play(crowd, 10)
    before = poses_now(crowd)
    other = recording_crowd()
    play(other, 10)
    with pytest.raises(CrowdError, match="another crowd configuration"):
        crowd.restore(other.snapshot())
    sub = show_crowd(substeps=2)
    with pytest.raises(CrowdError, match="keeps 2 samples a frame, this crowd 1"):
        crowd.restore(sub.snapshot())
    after = poses_now(crowd)
    for a, b in zip(before, after):
        np.testing.assert_array_equal(a, b)


def broken_files(tmp_path, good):
    """(file, expected message) pairs: each breaks one rule of the format."""
    import json
    import zipfile
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}
    head = json.loads(arrays[HEADER].tobytes())

    def write(name, arrays):
        p = tmp_path / name
        np.savez(p, **arrays)
        return p

    def with_head(**change):
        h = dict(head, **change)
        return {**arrays, HEADER: np.frombuffer(json.dumps(h).encode(), np.uint8)}

    out = [(write("plain.npz", {"x": np.zeros(3)}), "not a crowd snapshot"),
           (write("v4.npz", with_head(version=4)), "format version 4"),
           (write("v1.npz", with_head(version=1)), "format version 1 .*write it again"),
           (write("fmt.npz", with_head(format="other")), "not a crowd snapshot"),
           (write("frame.npz", with_head(frame="7")), "'frame' must be a whole number"),
           (write("missing.npz", {k: v for k, v in arrays.items()
                                  if k != "agents.kind"}), "missing: \\['agents.kind'\\]"),
           (write("shape.npz", {**arrays, "agents.kind": arrays["agents.kind"][:-1]}),
            "array 'agents.kind' is"),
           (write("json.npz", {**arrays, HEADER: np.frombuffer(b"{nope", np.uint8)}),
            "not valid JSON")]
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    out.append((cut, "not a readable crowd snapshot"))
    text = tmp_path / "text.npz"
    text.write_text("hello")
    out.append((text, "not a readable crowd snapshot"))
    assert zipfile.is_zipfile(good)
    return out


def test_bad_snapshot_files_are_named_and_change_nothing(tmp_path):
    crowd = show_crowd()
    play(crowd, 10)
    crowd.snapshot().save(tmp_path / "good.npz")
    play(crowd, 14)
    before = poses_now(crowd)
    for path, message in broken_files(tmp_path, tmp_path / "good.npz"):
        with pytest.raises(CrowdError, match=message) as err:
            crowd.restore(load_snapshot(path))
        assert str(path) in str(err.value)
    with pytest.raises(CrowdError, match="no such file"):
        load_snapshot(tmp_path / "nothing.npz")
    for a, b in zip(before, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)
    # a header that fits the format but not this crowd: named by the restore
    snap = load_snapshot(tmp_path / "good.npz")
    snap = type(snap)(snap.frame, snap.config_digest, snap.substeps,
                      {**snap.arrays, "slots.start_pose": snap.arrays["slots.start_pose"][:, :3]},
                      snap.values)
    with pytest.raises(CrowdError, match="state array 'slots.start_pose'"):
        crowd.restore(snap)
    for a, b in zip(before, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)


def test_saving_where_it_cannot_leaves_nothing(tmp_path):
    crowd = show_crowd()
    with pytest.raises(CrowdError, match="does not exist"):
        crowd.snapshot().save(tmp_path / "no" / "s.npz")
    with pytest.raises(CrowdError, match="ends in .npz"):
        crowd.snapshot().save(tmp_path / "s.snap")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ scrubbing
def counting(crowd):
    """Count the frames ``crowd`` really simulates."""
    steps = []
    inner = crowd.frame_tasks.step
    crowd.frame_tasks.step = lambda: steps.append(1) or inner()
    return steps


def test_jumps_start_from_the_nearest_snapshot_and_show_the_same_frame():
    """Any frame reached by a jump (backwards, or forwards past frames simulated
    before) equals the straight run's, stepping 1 to ``every`` frames."""
    every = 7
    straight, _ = play(show_crowd(), LAST)
    crowd = show_crowd()
    cache = crowd.keep_snapshots(every=every)
    play(crowd, LAST)
    assert cache.frames == list(range(1, LAST + 1, 7))        # start frame 1: 1 + 7k
    steps = counting(crowd)
    for target in (40, 9, 33, 2, 46, 15, 15, 21, 22, 8):
        steps.clear()
        before = crowd.frame
        crowd.advance_to(target)
        assert crowd.frame == target
        assert 1 <= len(steps) <= every or target == before, (target, len(steps))
        np.testing.assert_array_equal(crowd.agent_poses(), straight[target - 2]["poses"][0])
        np.testing.assert_array_equal(crowd.agents.kind, straight[target - 2]["kind"])


def test_the_memory_cap_thins_the_snapshots_and_says_so():
    crowd = show_crowd()
    one = crowd.snapshot().nbytes
    cache = crowd.keep_snapshots(every=3, max_bytes=int(3.5 * one))
    play(crowd, 40)
    assert cache.nbytes <= 3.5 * one and len(cache) >= 2
    assert cache.requested == 3 and cache.every in (12, 24, 48)    # doubled
    assert all((f - 1) % cache.every == 0 for f in cache.frames)
    assert cache.frames == list(range(1, 41, cache.every))
    crowd.advance_to(20)
    np.testing.assert_array_equal(crowd.agent_poses(), play(show_crowd(), 20)[0][-1]["poses"][0])
    small = show_crowd().keep_snapshots(every=3, max_bytes=one - 1)
    assert not small.fits and len(small) == 0


def test_a_change_from_outside_a_step_forgets_the_later_snapshots():
    crowd = show_crowd()
    cache = crowd.keep_snapshots(every=5)
    play(crowd, 30)
    crowd.advance_to(12)
    assert cache.frames == [1, 6, 11, 16, 21, 26]
    crowd.transition_to_streamed([0, 1], "wave", 3)             # the run changes at 12
    assert cache.frames == [1, 6, 11]
    play(crowd, 30)                                             # kept again, new run
    assert cache.frames == [1, 6, 11, 16, 21, 26]
    changed = crowd.agent_poses().copy()
    assert not np.array_equal(changed, play(show_crowd(), 30)[0][-1]["poses"][0])
    crowd.advance_to(17)
    crowd.advance_to(30)
    np.testing.assert_array_equal(crowd.agent_poses(), changed)
    # requests made by callbacks during steps (by_python's) are part of the run
    assert cache.frames == [1, 6, 11, 16, 21, 26]
    with pytest.raises(CrowdError, match="every must be"):
        crowd.keep_snapshots(every=0)


def test_going_back_before_a_change_replays_without_it_as_a_reset_would():
    """A one-off request at frame 30 (from outside a step) is not made again when the
    crowd goes back before it: every jump afterwards shows what a crowd re-simulated
    from the start shows, the snapshots taken after the change forgotten."""
    plain, _ = play(show_crowd(), 60)
    crowd = show_crowd()
    cache = crowd.keep_snapshots(every=5)
    play(crowd, 30)
    crowd.transition_to_streamed([0, 1, 2], "wave", 3)
    play(crowd, 60)
    assert cache.frames[-1] == 56                          # retaken after the change
    changed = crowd.agent_poses().copy()
    assert not np.array_equal(changed, plain[-1]["poses"][0])
    crowd.advance_to(45)                                   # back, after the change: kept
    crowd.advance_to(60)
    np.testing.assert_array_equal(crowd.agent_poses(), changed)
    crowd.advance_to(20)                                   # back before it: replayed
    assert cache.frames[-1] <= 30
    for target in (58, 40, 25, 59):
        crowd.advance_to(target)
        np.testing.assert_array_equal(crowd.agent_poses(), plain[target - 2]["poses"][0])


def test_the_api_reports_no_events_of_frames_it_replays():
    from crowd_addon import api
    crowd = show_crowd()
    crowd.keep_snapshots(every=5)
    sim = api.wrap(crowd)
    heard = []
    sim.on_event("*", lambda n, f, ids: heard.append(f))
    sim.advance_to(30)
    assert heard and max(heard) <= 30
    heard.clear()
    sim.advance_to(14)                       # from the snapshot at 11: 12, 13 replayed
    assert all(f == 14 for f in heard)
    sim.advance_to(30)
    heard.clear()
    sim.advance_to(28)
    assert all(f == 28 for f in heard)


def test_values_a_shape_check_cannot_see_are_refused_and_rolled_back(tmp_path):
    """Arrays of the right shape with impossible values, or small values of the wrong
    kind inside: the restore is undone and named (the fuzz test tries many more)."""
    crowd = show_crowd()
    play(crowd, 10)
    good = crowd.snapshot()
    play(crowd, 14)
    before = poses_now(crowd)
    cases = [("agents.kind", lambda a: np.full_like(a, 7), "does not exist"),
             ("slots.target_ref", lambda a: np.full_like(a, 10**6), "does not exist"),
             ("streams.log_name", lambda a: a[:-1] if a.size else np.zeros(1, a.dtype),
              "differ in length|was taken|state array"),
             ("slots.start_pose", lambda a: np.full_like(a, np.nan), "not finite")]
    for name, change, message in cases:
        arrays = dict(good.arrays, **{name: change(good.arrays[name])})
        bad = type(good)(good.frame, good.config_digest, good.substeps, arrays, good.values)
        with pytest.raises(CrowdError, match=message):
            crowd.restore(bad)
        for a, b in zip(before, poses_now(crowd)):
            np.testing.assert_array_equal(a, b)
    # a parameter that is not a number: refused by the values' bounds, before anything
    values = dict(good.values, **{"evaluator.params": [{"w": "high"}] * len(
        good.values["evaluator.params"])})
    bad = type(good)(good.frame, good.config_digest, good.substeps, good.arrays, values)
    with pytest.raises(CrowdError, match="value 'evaluator.params' must be finite numbers"):
        crowd.restore(bad)
    for a, b in zip(before, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)
    # one track value too few: found only while the show is put back, then undone
    values = dict(good.values, **{"show.track_last": good.values["show.track_last"][:-1]})
    bad = type(good)(good.frame, good.config_digest, good.substeps, good.arrays, values)
    with pytest.raises(CrowdError, match="cannot be restored.*the crowd is as it was"):
        crowd.restore(bad)
    for a, b in zip(before, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)
    play(crowd, 20)                                       # and it runs on


# ------------------------------------------- damaged and impossible files (issue 31)

def rewritten(tmp_path, good, name, header=None, members=None, **arrays):
    """``good`` written again as ``name`` with its header changed by ``header(head)``,
    arrays replaced, or raw zip members replaced (``members``: {name: bytes})."""
    import json
    import zipfile
    with np.load(good) as z:
        have = {k: z[k] for k in z.files}
    head = json.loads(have[HEADER].tobytes())
    if header is not None:
        header(head)
    have.update(arrays)
    have[HEADER] = np.frombuffer(json.dumps(head).encode(), np.uint8)
    path = tmp_path / name
    np.savez(path, **have)
    if members:
        with zipfile.ZipFile(path) as z:
            raw = {n: z.read(n) for n in z.namelist()}
        raw.update(members)
        with zipfile.ZipFile(path, "w") as z:
            for n, b in raw.items():
                z.writestr(n, b)
    return path


def refused_file(crowd, path, *patterns):
    """Loading and restoring ``path`` is a CrowdError naming the file (and
    ``patterns``), and the crowd is as it was."""
    before = poses_now(crowd)
    with pytest.raises(CrowdError) as err:
        crowd.restore(load_snapshot(path))
    msg = str(err.value)
    assert str(path) in msg, msg
    for p in patterns:
        assert re.search(p, msg), (p, msg)
    for a, b in zip(before, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)
    return msg


@pytest.fixture
def saved(tmp_path):
    """A crowd at frame 14 and a good file of its frame 10."""
    crowd = show_crowd()
    play(crowd, 10)
    crowd.snapshot().save(tmp_path / "good.npz")
    play(crowd, 14)
    return crowd, tmp_path / "good.npz"


def test_a_junk_member_is_named_not_an_attribute_error(saved, tmp_path):
    # regression: a junk snapshot.json.npy member raised AttributeError in load_snapshot
    crowd, good = saved
    junk = rewritten(tmp_path, good, "junk_header.npz",
                     members={f"{HEADER}.npy": b"junk junk junk"})
    refused_file(crowd, junk, re.escape(HEADER), "damaged")
    junk = rewritten(tmp_path, good, "junk_array.npz",
                     members={"agents.kind.npy": b"not an array"})
    refused_file(crowd, junk, "'agents.kind'", "damaged")


@pytest.mark.parametrize("change, patterns", [
    (lambda h: h.update(frame=10**30), ["'frame'", str(2**31 - 1)]),
    (lambda h: h.update(frame=1e30), ["'frame'"]),
    (lambda h: h["values"].update({"slots.cuts": 1e308}), ["'slots.cuts'", "count"]),
    (lambda h: h["values"].update({"slots.queue.issued": 2**63}),
     ["'slots.queue.issued'", "count", str(2**53)]),
    (lambda h: h["values"].update({"slots.served": -1}), ["'slots.served'"]),
    (lambda h: h["values"].update({"crowd.frame": 11}), ["'crowd.frame'", "10"]),
    (lambda h: h["values"].update({"crowd.origin": 10**12}), ["'crowd.origin'"]),
    (lambda h: h["values"].update({"crowd.ms_total": float("inf")}), ["'crowd.ms_total'"]),
    (lambda h: h["values"]["events.fired"].update(clap=0.5), ["'events.fired'"]),
    (lambda h: h["values"]["show.stats"]["wave"].update(agents=2**60),
     ["'show.stats'"]),
    (lambda h: h["values"].update({"evaluator.params": [{"w": float("nan")}] * len(
        h["values"]["evaluator.params"])}), ["'evaluator.params'"]),
    (lambda h: h.update(substeps=10**9), ["'substeps'"]),
    (lambda h: h.update(config_digest="abc"), ["'config_digest'"]),
    (lambda h: h["arrays"]["agents.kind"].update(shape=[-1]), ["'agents.kind'"]),
], ids=["frame 10**30", "frame 1e30", "cuts 1e308", "issued 2**63", "served -1",
        "frame disagrees", "origin", "ms_total inf", "fired 0.5", "stats 2**60", "param nan",
        "substeps", "digest", "shape -1"])
def test_impossible_header_values_are_refused_with_the_file_name(saved, tmp_path, change,
                                                                 patterns):
    """Every header field and count is checked against its bounds (before the fix a
    header frame of 10**30, slots.cuts = 1e308 and queue.issued = 2**63 were accepted)."""
    crowd, good = saved
    refused_file(crowd, rewritten(tmp_path, good, "bad.npz", header=change), *patterns)


def test_a_corrupted_array_of_the_right_shape_is_refused_by_its_digest(saved, tmp_path):
    """Before the fix a damaged array was caught only when its shape broke."""
    crowd, good = saved
    with np.load(good) as z:
        rows = z["streams.history:rows"].copy()         # the history's distinct rows
        kind = z["agents.kind"].copy()
    assert rows.shape[0] > 1 and rows.shape[1] > 4
    changed = rows.copy()
    changed[0, 4] += 0.25
    refused_file(crowd, rewritten(tmp_path, good, "pose.npz",
                                  **{"streams.history:rows": changed}),
                 "'streams.history'", "digest", "damaged")
    kind[3] = 1 - kind[3]
    refused_file(crowd, rewritten(tmp_path, good, "kind.npz", **{"agents.kind": kind}),
                 "'agents.kind'", "digest")
    # the bytes of the file itself, in the middle of the pose history's data
    raw = bytearray(good.read_bytes())
    at = raw.find(rows[1].tobytes()[:64])
    assert at > 0
    raw[at + 5] ^= 0x40
    flipped = tmp_path / "flipped.npz"
    flipped.write_bytes(bytes(raw))
    refused_file(crowd, flipped)


def test_the_header_lists_a_digest_of_every_array(saved):
    import json
    _, good = saved
    with np.load(good) as z:
        head = json.loads(z[HEADER].tobytes())
    assert head["version"] == 3
    assert head["arrays"]["streams.history"]["codec"] == "rows"
    assert all(len(spec["sha256"]) == 64 for spec in head["arrays"].values())


def test_crowd_snapshot_over_too_many_frames_is_refused_before_it_steps(tmp_path, capsys,
                                                                       monkeypatch):
    """crowd snapshot --frames 1-2000000000 --every 1000000000 ran on (issue 31): it is
    refused before the first step, naming the bound and how to split the pass."""
    from crowd_addon.cli import main

    def step(self):
        pytest.fail("the crowd stepped: the pass was not refused before it began")
    monkeypatch.setattr(Crowd, "step", step)
    config = tmp_path / "crowd.json"
    save_config(make_config(show(), slots=6), config)
    out = tmp_path / "snaps"
    assert main(["snapshot", "--config", str(config), "--frames", "1-2000000000",
                 "--every", "1000000000", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    from crowd_addon.core.base.bounds import MAX_RUN_FRAMES
    assert err[-1].startswith("crowd snapshot: error: snapshots: ")
    assert f"{MAX_RUN_FRAMES:,}" in err[-1] and "2000000000" in err[-1]
    assert f"--frames 1-{1 + MAX_RUN_FRAMES}" in err[-1]              # how to split
    assert not list(out.glob("*.npz"))
