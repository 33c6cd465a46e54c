"""Blender's keyframe F-curve evaluation, vectorised over curves and sample times.

Pure numpy: the Blender side (``crowd_addon.blender.action_data``) reads the arrays
with ``keyframe_points.foreach_get`` and packs them into a :class:`CurveSet`. The
arithmetic follows Blender's ``fcurve.cc`` (``fcurve_eval_keyframes``,
``BKE_fcurve_correct_bezpart``, ``findzero``/``solve_cubic``, ``berekeny``) step
by step, in float32 where Blender uses ``float`` and float64 where it uses
``double``, so results agree with ``FCurve.evaluate`` to the last bit or two.

Supported per curve: constant, linear and Bezier segments, constant or linear
extrapolation, strictly increasing key frames (callers evaluate other curves with
``FCurve.evaluate``).

One known simplification: Blender snaps a time to a key when it is within 1e-4 of
a key *visited by its binary search*; here any key within 1e-4 snaps. The two differ
only for times within 1e-4 of a key that the search skipped, where Blender reads the
neighbouring segment an instant away from that key.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError

__all__ = ["CurveSet", "CONSTANT", "LINEAR", "BEZIER", "evaluate", "evaluate_frames",
           "check_finite"]

CONSTANT, LINEAR, BEZIER = 0, 1, 2      # Keyframe.interpolation enum values
_SNAP = np.float32(1e-4)                # BKE_fcurve_bezt_binarysearch_index_ex threshold
_SMALL = np.float32(-1.0e-10)           # solve_cubic's accepted root range [SMALL, 1.000001]
_ONE = np.float32(1.000001)
_FLT_EPSILON = np.float32(np.finfo(np.float32).eps)
_f32 = np.float32


@dataclass(frozen=True, eq=False)
class CurveSet:
    """The keyframes of ``C`` F-curves packed back to back (one array per field).

    co : (N, 2) float32 (frame, value) per key.
    ipo : (N,) int32 interpolation of the segment starting at each key.
    left, right : (N, 2) float32 handles (zero where not read: curves without Bezier
        keys), or None when no curve has Bezier keys.
    start : (C + 1,) int64; curve ``c`` owns keys ``start[c]:start[c + 1]``.
    linear : (C,) bool, the curve's ``extrapolation == 'LINEAR'``.
    """

    co: np.ndarray
    ipo: np.ndarray
    left: np.ndarray
    right: np.ndarray
    start: np.ndarray
    linear: np.ndarray

    @functools.cached_property
    def counts(self) -> np.ndarray:
        return np.diff(self.start)

    def key_index(self, members: np.ndarray):
        """Index of the keys of curves ``members`` (all with the same key count K) in
        the packed arrays, and K: a slice when they lie back to back, else an
        ``(m, K)`` array."""
        a = int(self.start[members[0]])
        k = int(self.start[members[0] + 1]) - a
        m = len(members)
        if m == 1 or (int(members[-1]) - int(members[0]) == m - 1
                      and (np.diff(members) == 1).all()):
            return slice(a, a + m * k), k
        return self.start[members][:, None] + np.arange(k), k

    @staticmethod
    def _take(field, index, m, k):
        """``field`` at a :meth:`key_index` of ``m`` curves with ``k`` keys: (m, k, ...)."""
        if isinstance(index, slice):
            return field[index].reshape((m, k) + field.shape[1:])
        return field[index]

    def rows(self, field: np.ndarray, members: np.ndarray) -> np.ndarray:
        """``field`` (a per-key array) of curves ``members``, all with the same key
        count K, as ``(m, K, ...)``: a view when they lie back to back, else a gather."""
        index, k = self.key_index(members)
        return self._take(field, index, len(members), k)

    def groups(self, which, frames_only=False) -> list:
        """``which`` (curve indices) split into groups of curves with equal key frames
        (and, unless ``frames_only``, equal interpolations, handle frames and
        extrapolation): one time search and one Bezier root solve serve a group."""
        which = np.asarray(which, np.int64)
        counts = self.counts[which]
        sizes = np.unique(counts)
        out = []
        for k in sizes.tolist():
            rows = which if len(sizes) == 1 else which[counts == k]
            if len(rows) == 1:
                out.append(rows)
                continue
            index, m = self.key_index(rows)[0], len(rows)
            parts = [self._take(self.co, index, m, k)[..., 0]]
            if not frames_only:
                parts += [self._take(self.ipo, index, m, k), self.linear[rows, None]]
                if self.left is not None:
                    parts += [self._take(self.left, index, m, k)[..., 0],
                              self._take(self.right, index, m, k)[..., 0]]
            if all((p == p[:1]).all() for p in parts):      # the usual case: keyed alike
                out.append(rows)
                continue
            found = {}
            for i, r in enumerate(rows):
                found.setdefault(b"".join(p[i].tobytes() for p in parts), []).append(r)
            out.extend(np.array(g, np.int64) for g in found.values())
        return out


def check_finite(values: np.ndarray, start: np.ndarray, curve_label, part: str) -> None:
    """Raise a :class:`CrowdError` at the first key of packed ``values`` that is not
    finite.

    values : (N, 2) float32 packed per key (``co`` or a handle), rows
        ``start[c]:start[c + 1]`` belonging to curve ``c``; start : (C + 1,) int64.
    curve_label : ``curve_label(c)`` -> str naming curve ``c`` in the message
        (e.g. ``"action 'Walk', bone 'leg', location[1]"``).
    part : what a row is, e.g. ``"key"`` or ``"left handle of key"``.
    """
    finite = np.isfinite(values).all(1)
    if finite.all():
        return
    row = int(np.argmax(~finite))
    c = int(np.searchsorted(start, row, side="right") - 1)
    raise CrowdError(f"{curve_label(c)}: {part} {row - start[c]} is not finite "
                     f"({values[row].tolist()})")


def evaluate(curves: CurveSet, times, which=None) -> np.ndarray:
    """Values ``(len(which), n)`` float32 of supported curves at frames ``times`` (n,).

    ``which``: indices of the curves to evaluate (default all). Curves keyed alike
    (:meth:`CurveSet.groups`; the usual case: all channels keyed on the same frames)
    share their time search and Bezier root solving; per curve only values are
    gathered. The result is the transpose of :func:`evaluate_frames`'.
    """
    return evaluate_frames(curves, times, which).T


def evaluate_frames(curves: CurveSet, times, which=None) -> np.ndarray:
    """:func:`evaluate` frame-major: values ``(n, len(which))`` float32.

    Works frame-major throughout: gathering the keys around a sample time is then
    one row per sample, all curves at once."""
    t = np.asarray(times, np.float32)
    which = np.arange(len(curves.linear)) if which is None else np.asarray(which, np.int64)
    groups = curves.groups(which)
    if len(groups) == 1 and np.array_equal(groups[0], which):
        return _evaluate_group(curves, which, t)
    out = np.empty((t.size, which.size), np.float32)
    position = np.empty(len(curves.linear), np.int64)
    position[which] = np.arange(which.size)
    for members in groups:
        out[:, position[members]] = _evaluate_group(curves, members, t)
    return out


def _evaluate_group(cs, members, t):
    """Curves ``members`` of one group (shared frames, interpolation, handle frames,
    extrapolation) at times ``t``: (n, len(members)) float32."""
    first = members[:1]
    x, ipo = cs.rows(cs.co, first)[0, :, 0], cs.rows(cs.ipo, first)[0]
    y = np.array(cs.rows(cs.co, members)[..., 1].T, order="C")             # (K, C)
    lx = rx = ly = ry = None
    if (ipo == BEZIER).any():
        lx, ly = cs.rows(cs.left, first)[0, :, 0], cs.rows(cs.left, members)[..., 1].T
        rx, ry = cs.rows(cs.right, first)[0, :, 0], cs.rows(cs.right, members)[..., 1].T
    n = x.size
    out = None
    if n == t.size and (x == t).all():          # sampled exactly on the keys
        return y
    if n > 1:                   # inside the keys (rows outside are replaced below)
        nxt = np.clip(np.searchsorted(x, t, side="left"), 1, n - 1)  # x[nxt-1] < t <= x[nxt]
        prv = nxt - 1
        snap_next = (x[nxt] - t) <= _SNAP
        snap_prev = ~snap_next & ((t - x[prv]) <= _SNAP)
        # snapped times and constant segments take a key's value: one gather
        out = y[np.where(snap_next, nxt, prv)]
        seg_ipo = np.where(snap_next | snap_prev, CONSTANT, ipo[prv])
        m = np.flatnonzero(seg_ipo == LINEAR)
        if m.size:                              # BLI_easing_linear_ease: c * t / d + b
            p, q = prv[m], nxt[m]
            begin = y[p]
            change = y[q] - begin
            out[m] = change * (t[m] - x[p])[:, None] / (x[q] - x[p])[:, None] + begin
        m = np.flatnonzero(seg_ipo == BEZIER)
        if m.size:
            out[m] = _bezier(x, y, lx, ly, rx, ry, prv[m], t[m])
    if out is None:
        out = np.empty((t.size, len(members)), np.float32)

    # at or before the first key / at or after the last: fcurve_eval_keyframes_extrapolate
    linear = bool(cs.linear[members[0]])
    for before, side, nb in ((True, 0, 1), (False, n - 1, n - 2)):
        mask = np.flatnonzero(t <= x[0] if before else t >= x[-1])
        if mask.size == 0:
            continue
        dx = (x[side] - t[mask])[:, None]                                    # (m, 1)
        ye = y[side]
        if ipo[side] == CONSTANT or not linear:
            out[mask] = ye
        elif ipo[side] == LINEAR:
            fac = x[nb] - x[side] if n > 1 else _f32(0)
            if fac == 0:
                out[mask] = ye
            else:
                slope = (y[nb] - ye) / fac
                out[mask] = ye - slope * dx
        else:
            hx, hy = (lx, ly) if before else (rx, ry)     # the handle facing outwards
            fac = x[side] - hx[side]
            if fac == 0:
                out[mask] = ye
            else:
                slope = (ye - hy[side]) / fac
                out[mask] = ye - slope * dx
    return out


def _bezier(x, y, lx, ly, rx, ry, p, t):
    """Bezier segments from key ``p`` to key ``p + 1`` at times ``t`` (both (m,)), of
    curves with key values ``y``, handle values ``ly``, ``ry`` (K, C) and shared key
    and handle frames ``x``, ``lx``, ``rx`` (K,): (m, C).

    Everything but the root solve and the final polynomial depends on the segment
    only, so it is computed once per segment used ((S, C) arrays, S <= K - 1) and
    gathered per sample; the arithmetic per element is Blender's, unchanged."""
    seg, at = np.unique(p, return_inverse=True)          # segments used; sample -> seg
    nxt = seg + 1
    v1x, v2x, v3x, v4x = x[seg], rx[seg], lx[nxt], x[nxt]
    v1y, v2y, v3y, v4y = y[seg], ry[seg], ly[nxt], y[nxt]                # (S, C)
    flat = ((np.abs(v1y - v4y) < _FLT_EPSILON) & (np.abs(v2y - v3y) < _FLT_EPSILON)
            & (np.abs(v3y - v4y) < _FLT_EPSILON))
    # BKE_fcurve_correct_bezpart: a handle longer than the segment is scaled back
    h1x, h2x = v1x - v2x, v4x - v3x
    span = v4x - v1x
    len1, len2 = np.abs(h1x), np.abs(h2x)
    fix1 = ((len1 + len2) != 0) & (len1 > span)
    fix2 = ((len1 + len2) != 0) & (len2 > span)
    if fix1.any():
        fac1 = np.where(fix1, span / np.where(fix1, len1, 1), 0).astype(np.float32)
        v2x = np.where(fix1, v1x - fac1 * h1x, v2x)
        v2y = np.where(fix1[:, None], v1y - fac1[:, None] * (v1y - v2y), v2y)
    if fix2.any():
        fac2 = np.where(fix2, span / np.where(fix2, len2, 1), 0).astype(np.float32)
        v3x = np.where(fix2, v4x - fac2 * h2x, v3x)
        v3y = np.where(fix2[:, None], v4y - fac2[:, None] * (v4y - v3y), v3y)
    s, found = _findzero(t, v1x[at], v2x[at], v3x[at], v4x[at])
    # berekeny, float32 as in Blender: c0 + s c1 + s^2 c2 + s^3 c3 with the
    # coefficients per segment, gathered per sample into two (m, C) buffers (the
    # sums in Blender's order: a + b is b + a exactly)
    c1 = _f32(3) * (v2y - v1y)
    c2 = _f32(3) * (v1y - _f32(2) * v2y + v3y)
    c3 = v4y - v1y + _f32(3) * (v2y - v3y)
    s = s[:, None]
    s2 = s * s
    val = np.take(c1, at, axis=0)
    val *= s
    term = np.take(v1y, at, axis=0)                                      # c0
    val += term
    np.take(c2, at, axis=0, out=term)
    term *= s2
    val += term
    np.take(c3, at, axis=0, out=term)
    term *= s2 * s
    val += term
    if not found.all():
        val[~found] = 0                                # findzero failed: Blender returns 0
    if flat.any():
        val = np.where(flat[at], np.take(v1y, at, axis=0), val)
    return val


def _findzero(x, q0, q1, q2, q3):
    """First root in [SMALL, 1.000001] of the Bezier x(s) = x: (float32 s, found)."""
    c0 = (q0 - x).astype(np.float64)
    c1 = (_f32(3) * (q1 - q0)).astype(np.float64)
    c2 = (_f32(3) * (q0 - _f32(2) * q1 + q2)).astype(np.float64)
    c3 = (q3 - q0 + _f32(3) * (q1 - q2)).astype(np.float64)
    return _solve_cubic(c0, c1, c2, c3)


def _solve_cubic(c0, c1, c2, c3):
    """Vectorised ``solve_cubic``: candidate roots in Blender's order, first valid wins.

    Each case (cubic with one, two or three real roots, quadratic, linear) is
    computed only for the samples in it."""
    m = c0.shape[0]
    cand = np.full((m, 3), np.nan)
    with np.errstate(all="ignore"):
        cub = c3 != 0
        every = bool(cub.all())
        if every:                               # the usual case: x(s) is a true cubic
            a, b, c = c2 / c3 / 3, c1 / c3, c0 / c3
        else:
            a = np.where(cub, c2 / np.where(cub, c3, 1), 0) / 3
            b = np.where(cub, c1 / np.where(cub, c3, 1), 0)
            c = np.where(cub, c0 / np.where(cub, c3, 1), 0)
        p = b / 3 - a * a
        q = (2 * a * a * a - a * b + c) / 2
        d = q * q + p * p * p
        k = np.flatnonzero(cub & (d > 0))
        if k.size:
            qk, sd = q[k], np.sqrt(d[k])
            cand[k, 0] = np.cbrt(-qk + sd) + np.cbrt(-qk - sd) - a[k]
        k = np.flatnonzero(cub & (d == 0))
        if k.size:
            tt = np.cbrt(-q[k])
            cand[k, 0] = 2 * tt - a[k]
            cand[k, 1] = -tt - a[k]
        k = np.flatnonzero(cub & (d < 0))
        if k.size:
            pk, ak = p[k], a[k]
            phi = np.arccos(-q[k] / np.sqrt(-(pk * pk * pk)))
            tt = np.sqrt(-pk)
            pp = np.cos(phi / 3)
            qq = np.sqrt(3 - 3 * pp * pp)
            cand[k, 0] = 2 * tt * pp - ak
            cand[k, 1] = -tt * (pp + qq) - ak
            cand[k, 2] = -tt * (pp - qq) - ak
        if not every:
            quad = ~cub & (c2 != 0)
            disc = c1 * c1 - 4 * c2 * c0
            k = quad & (disc > 0)
            sq = np.sqrt(np.where(k, disc, 0))
            cand[k, 0] = ((-c1 - sq) / (2 * c2))[k]
            cand[k, 1] = ((-c1 + sq) / (2 * c2))[k]
            k = quad & (disc == 0)
            cand[k, 0] = (-c1 / (2 * c2))[k]
            lin = ~cub & (c2 == 0) & (c1 != 0)
            cand[lin, 0] = (-c0 / c1)[lin]
            cand[~cub & (c2 == 0) & (c1 == 0) & (c0 == 0), 0] = 0.0
        roots = cand.astype(np.float32)
        ok = (roots >= _SMALL) & (roots <= _ONE)
    found = ok.any(1)
    first = np.argmax(ok, 1)
    return np.where(found, roots[np.arange(m), first], _f32(0)), found
