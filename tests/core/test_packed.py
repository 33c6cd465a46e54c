"""Snapshots' packed arrays (core/shots/packed.py): exact, smaller, and refused when
damaged. Before the packing a snapshot held its arrays whole: the paper's
configuration took 62.7 MB a snapshot, nine tenths of it repeated pose rows."""

import json

import numpy as np
import pytest

from crowd_addon.core import CrowdError
from crowd_addon.core.shots import packed as P
from crowd_addon.core.shots.snapshot import HEADER, load_snapshot

from .test_snapshot import play, poses_now, saved, show_crowd  # noqa: F401 (saved: a fixture)


def same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and \
        np.array_equal(a.view(f"u{a.itemsize}"), b.view(f"u{b.itemsize}"))


def poses(rows=200, distinct=7, bones=12, seed=0):
    """(rows, bones, 10) float32 poses: ``distinct`` poses repeated, channels 0..2 and
    7..9 of every bone fixed (a pose's scale and a bone's length)."""
    rng = np.random.default_rng(seed)
    base = rng.standard_normal((distinct, bones, 10)).astype(np.float32)
    base[..., :3] = 1.0
    base[..., 7:] = np.arange(bones * 3, dtype=np.float32).reshape(bones, 3)
    return base[rng.integers(0, distinct, rows)]


def test_repeated_pose_rows_are_kept_once_and_come_back_bit_for_bit():
    a = poses()
    a[3, 2, 4] = np.float32(-0.0)                     # a row of its own, by its sign bit
    a[5, 1, 5] = np.frombuffer(np.uint32(0x7FC0_1234).tobytes(), np.float32)[0]  # NaN payload
    a[6, 0, 6] = np.inf
    p = P.pack(a)
    assert p.codec == "rows"
    assert p.parts["rows"].shape == (10, 12 * 4)      # 7 poses + 3 changed; 4 channels vary
    assert p.nbytes < a.nbytes / 15
    assert same_bits(p.unpack(), a)
    assert same_bits(np.asarray(p), a)


def test_rows_the_hash_sample_cannot_tell_apart_are_still_kept_apart():
    width = 10 * 40                                   # 400 columns; the hash reads 64
    sampled = set(np.unique(np.linspace(0, width - 1, P.HASH_COLUMNS).astype(int)).tolist())
    hidden = next(c for c in range(width) if c not in sampled)
    a = np.zeros((50, 40, 10), np.float32)
    a[1::2].reshape(25, -1)[:, hidden] = 1.0          # odd rows differ off the sample only
    p = P.pack(a)
    assert p.codec == "rows" and p.parts["rows"].shape[0] == 2
    assert same_bits(p.unpack(), a)


def test_integers_take_the_narrowest_type_that_holds_them():
    a = np.array([-3, 0, 1000] * 1000, np.int64)
    p = P.pack(a)
    assert p.codec == "ints" and p.parts["data"].dtype == np.int16
    assert same_bits(p.unpack(), a)
    assert P.pack(np.arange(5, dtype=np.int64)).codec == "raw"            # too small to pay
    assert P.pack(np.zeros(0, np.float32)).codec == "raw"
    b = np.ones(10_000, bool)
    assert P.pack(b).codec == "raw" and same_bits(P.pack(b).unpack(), b)
    f = np.random.default_rng(1).standard_normal((5000, 3))                # nothing repeats
    assert P.pack(f).codec == "raw" and same_bits(P.pack(f).unpack(), f)


def test_a_history_inside_a_padded_pose_storage_packs_and_unpacks_in_place():
    storage = np.zeros((60 * 8, 12, 12), np.float32)   # GPU skinning: 12 floats a bone
    history = storage[:, :, :10].reshape(60, 8, 12, 10)
    history[...] = poses(480).reshape(60, 8, 12, 10)
    p = P.pack(history)
    assert p.codec == "rows" and same_bits(p.unpack(), history)
    kept = history.copy()
    history[...] = 0
    p.unpack_into(history)
    assert np.shares_memory(history, storage) and same_bits(history, kept)
    assert (storage[:, :, 10:] == 0).all()             # the padding left alone
    with pytest.raises(ValueError, match="cannot go into"):
        p.unpack_into(np.zeros((60, 8, 12, 9), np.float32))


def test_a_snapshot_is_packed_and_restores_exactly():
    crowd = show_crowd()
    play(crowd, 10)
    snap = crowd.snapshot()
    whole = sum(a.nbytes for a in snap.arrays.values())
    assert snap.nbytes < whole / 2
    assert snap.packed["streams.history"].codec == "rows"
    play(crowd, 20)
    later = poses_now(crowd)
    crowd.restore(snap)
    play(crowd, 20)
    for a, b in zip(later, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)


def _rewrite(good, path, head_change=None, **arrays):
    with np.load(good) as z:
        members = {k: z[k] for k in z.files}
    head = json.loads(members.pop(HEADER).tobytes())
    if head_change:
        head_change(head, members)
    members.update(arrays)
    np.savez(path, **{HEADER: np.frombuffer(json.dumps(head).encode(), np.uint8)}, **members)
    return path


def test_version_2_files_with_whole_arrays_are_read(tmp_path):
    crowd = show_crowd()
    play(crowd, 10)
    snap = crowd.snapshot()
    snap.save(tmp_path / "v3.npz")
    play(crowd, 16)
    later = poses_now(crowd)

    def whole(head, members):                          # the file version 2 wrote
        head["version"] = 2
        for name, spec in head["arrays"].items():
            for part in spec.pop("parts"):
                members.pop(name if part == "data" else f"{name}:{part}")
            del spec["codec"]
            members[name] = snap.arrays[name]
    old = _rewrite(tmp_path / "v3.npz", tmp_path / "v2.npz", whole)
    back = load_snapshot(old)
    assert all(p.codec == "raw" for p in back.packed.values())
    crowd.restore(back)
    play(crowd, 16)
    for a, b in zip(later, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)


def test_damaged_packed_parts_are_named_and_change_nothing(saved, tmp_path):
    crowd, good = saved
    before = poses_now(crowd)
    with np.load(good) as z:
        index = z["streams.history:index"].copy()
    far = index.copy()
    far[0] = index.max() + 1                            # a row past the distinct rows

    def codec(name):
        def change(head, members):
            head["arrays"]["streams.history"]["codec"] = name
        return change

    def parts_lie(head, members):                       # the header agrees with the lie
        head["arrays"]["streams.history"]["parts"]["index"]["shape"] = [5]
        members["streams.history:index"] = index[:5]
    cases = [(_rewrite(good, tmp_path / "far.npz",
                       **{"streams.history:index": far}), "'streams.history' .*index"),
             (_rewrite(good, tmp_path / "zip.npz", codec("zip")),
              "'streams.history' needs a codec"),
             (_rewrite(good, tmp_path / "ints.npz", codec("ints")),
              "'streams.history' needs a codec .* and its parts"),
             (_rewrite(good, tmp_path / "short.npz", parts_lie),
              "'streams.history' .*index")]
    for path, message in cases:
        with pytest.raises(CrowdError, match=message) as err:
            crowd.restore(load_snapshot(path))
        assert str(path) in str(err.value)
    for a, b in zip(before, poses_now(crowd)):
        np.testing.assert_array_equal(a, b)
