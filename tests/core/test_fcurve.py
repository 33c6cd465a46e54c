"""The numpy F-curve evaluator (crowd_addon.core.bake.fcurve) on hand-made curves with
known values. Its agreement with Blender's own ``FCurve.evaluate`` on random curves is
tested in tests/blender/test_fcurve_eval.py (Blender is the oracle there)."""

import numpy as np
import pytest

from crowd_addon.core.bake import fcurve
from crowd_addon.core.base.errors import CrowdError


def pack(curves, handles=False):
    """A CurveSet of ``curves``: ((frames, values, interpolation, linear_extrapolation),
    ...); with ``handles``, Bezier handles at a third of each segment (straight
    segments, so Bezier equals linear)."""
    counts = [len(c[0]) for c in curves]
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    co = np.concatenate([np.stack([f, v], 1) for f, v, _, _ in curves]).astype(np.float32)
    ipo = np.concatenate([np.full(len(f), i) for f, _, i, _ in curves]).astype(np.int32)
    linear = np.array([e for *_, e in curves])
    left = right = None
    if handles:
        left, right = co.copy(), co.copy()
        for (f, v, _, _), a in zip(curves, start[:-1]):
            f, v = np.asarray(f, np.float64), np.asarray(v, np.float64)
            df, dv = np.diff(f) / 3, np.diff(v) / 3
            right[a:a + len(f) - 1] += np.stack([df, dv], 1)
            left[a + 1:a + len(f)] -= np.stack([df, dv], 1)
    return fcurve.CurveSet(co, ipo, left, right, start, linear)


FRAMES, VALUES = [1.0, 5.0, 9.0], [0.0, 2.0, -2.0]


def test_linear_and_constant_segments():
    cs = pack([(FRAMES, VALUES, fcurve.LINEAR, False), (FRAMES, VALUES, fcurve.CONSTANT, False)])
    t = np.array([1, 3, 5, 7, 8.5, 9], np.float32)
    got = fcurve.evaluate(cs, t)
    np.testing.assert_allclose(got[0], [0, 1, 2, 0, -1.5, -2], atol=1e-6)
    np.testing.assert_allclose(got[1], [0, 0, 2, 2, 2, -2], atol=1e-6)
    np.testing.assert_array_equal(fcurve.evaluate_frames(cs, t), got.T)


def test_straight_bezier_segments_are_linear_and_flat_ones_constant():
    cs = pack([(FRAMES, VALUES, fcurve.BEZIER, False), ([0.0, 4.0], [3.0, 3.0],
                                                         fcurve.BEZIER, False)], handles=True)
    t = np.linspace(1, 9, 17, dtype=np.float32)
    np.testing.assert_allclose(fcurve.evaluate(cs, t, [0])[0], np.interp(t, FRAMES, VALUES),
                               atol=1e-5)
    np.testing.assert_array_equal(fcurve.evaluate(cs, t, [1])[0], 3.0)


def test_extrapolation_constant_or_linear():
    cs = pack([(FRAMES, VALUES, fcurve.LINEAR, False), (FRAMES, VALUES, fcurve.LINEAR, True)])
    got = fcurve.evaluate(cs, np.array([-3.0, 13.0], np.float32))
    np.testing.assert_allclose(got[0], [0.0, -2.0])               # held at the end keys
    np.testing.assert_allclose(got[1], [-2.0, -6.0], atol=1e-6)   # slopes 0.5 and -1


def test_times_within_1e4_of_a_key_snap_to_it():
    cs = pack([(FRAMES, VALUES, fcurve.LINEAR, False)])
    got = fcurve.evaluate(cs, np.array([5.00005, 4.99995, 5.01], np.float32))[0]
    assert got[0] == 2.0 and got[1] == 2.0 and got[2] != 2.0


def test_curves_keyed_alike_are_grouped_and_evaluated_together():
    cs = pack([(FRAMES, VALUES, fcurve.LINEAR, False),
               (FRAMES, [1.0, 1.0, 4.0], fcurve.LINEAR, False),
               ([0.0, 2.0], [1.0, 0.0], fcurve.LINEAR, False),
               (FRAMES, VALUES, fcurve.CONSTANT, False)])
    assert sorted(g.tolist() for g in cs.groups(range(4))) == [[0, 1], [2], [3]]
    assert sorted(g.tolist() for g in cs.groups(range(4), frames_only=True)) == [[0, 1, 3],
                                                                                [2]]
    t = np.linspace(-1, 11, 25, dtype=np.float32)
    together = fcurve.evaluate(cs, t, [3, 0, 2, 1])
    alone = np.concatenate([fcurve.evaluate(cs, t, [c]) for c in (3, 0, 2, 1)])
    np.testing.assert_array_equal(together, alone)


def test_check_finite_names_the_curve_and_key():
    cs = pack([(FRAMES, VALUES, fcurve.LINEAR, False), (FRAMES, [0, np.nan, 1],
                                                        fcurve.LINEAR, False)])
    fcurve.check_finite(cs.co[:3], cs.start[:2], str, "key")
    with pytest.raises(CrowdError, match=r"^curve 1: key 1 is not finite \(\[5.0, nan\]\)$"):
        fcurve.check_finite(cs.co, cs.start, lambda c: f"curve {c}", "key")
