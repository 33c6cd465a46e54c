"""Where a baked clip samples its action: the key times, the events, and whether its
keys are close enough to be interpolated.

A clip has one key every ``step = scene_fps / (crowd_fps * samples_per_frame)``
Blender frames from the start of the action's frame range (:func:`sample_times`);
pose markers become clip events at fractional clip frames (:func:`marker_events`).
The Blender side reads the frame range and markers (``crowd_addon.blender.action_data``).

Between keys the crowd interpolates (lerp, shortest-arc nlerp). Where the action turns
a bone the long way round between two keys (an Euler curve going from 179 to -179
degrees is a full turn in Blender), or fast enough that the arc is not a straight
blend, the in-between poses differ from Blender's: :func:`interpolation_misses`
measures it halfway between keys against the curves' true values and
:func:`interpolation_note` words it for the bake report, with the samples per frame
that would follow the motion.
"""

from __future__ import annotations

import math

import numpy as np

from . import pose as sqt
from .errors import CrowdError

__all__ = ["sample_times", "marker_events", "interpolation_misses", "interpolation_note",
           "between_key_misses", "between_keys_note", "MISS_TOLERANCE",
           "POSITION_TOLERANCE", "ROTATION_TOLERANCE", "MAX_SAMPLES_PER_FRAME",
           "ADVICE_INTERVALS"]

#: Radians an interpolated rotation may miss the action's halfway between keys.
MISS_TOLERANCE = 0.05
#: How many of the worst key intervals the between-keys advice is checked on.
BETWEEN_ADVICE_INTERVALS = 4
#: Scene units a bone's head may miss the action's position between keys.
POSITION_TOLERANCE = 1e-3
#: Radians a bone's rotation (in armature space) may miss the action's between keys.
ROTATION_TOLERANCE = 1e-3
#: The most keys per crowd frame a bake takes.
MAX_SAMPLES_PER_FRAME = 16
#: How many of the worst key intervals the samples-per-frame advice is checked on.
ADVICE_INTERVALS = 8


def sample_times(name: str, start: float, end: float, step: float, loop: bool):
    """Blender frames of the clip keys of action ``name``: every ``step`` frames from
    ``start``. A range that is not a whole number of steps is stretched (loops, so
    the period is exact) or extended past ``end`` (clamped clips, so no key is lost).

    Returns ``(times, notes)``: (F,) float64 frames, F >= 2 for ``end > start``, and
    a list of str remarks for the bake report.
    """
    span = end - start
    steps = span / step
    notes = []
    if abs(steps - round(steps)) < 1e-6:
        count = int(round(steps))
    elif loop:
        count = max(1, int(round(steps)))
        notes.append(f"action {name!r}: {span:g} frames is not a whole number of crowd "
                     f"frames; the loop is resampled to {count} steps of "
                     f"{span / count:g} frames so that it still closes")
        step = span / count
    else:
        count = math.ceil(steps)
        notes.append(f"action {name!r}: the last key is sampled at frame "
                     f"{start + count * step:g}, after the end of the action ({end:g})")
    return start + np.arange(count + 1) * step, notes


def marker_events(name: str, markers, times: np.ndarray, begin: float, end: float) -> tuple:
    """Clip events ``((marker name, clip frame), ...)`` of pose ``markers``
    (``(name, Blender frame)`` pairs) on a clip keyed at ``times`` (F,) float64.

    A marker outside the clip's keys (by more than 1e-6 of a clip frame) raises a
    :class:`CrowdError` naming it and the action's frames ``begin..end``.
    """
    step = (times[-1] - times[0]) / (len(times) - 1)
    events = []
    for marker, frame in markers:
        f = (frame - times[0]) / step
        if not -1e-6 <= f <= len(times) - 1 + 1e-6:
            raise CrowdError(f"action {name!r}: pose marker {marker!r} at frame {frame} is "
                             f"outside the action's frames {begin:g}..{end:g}")
        events.append((marker, float(min(max(f, 0.0), len(times) - 1))))
    return tuple(events)


def interpolation_misses(keys: np.ndarray, halfway: np.ndarray) -> np.ndarray:
    """Angles ``(F - 1, B)`` in radians between the rotation the crowd interpolates
    halfway between consecutive keys (shortest-arc nlerp of ``keys[i]`` and
    ``keys[i + 1]``) and ``halfway[i]``, the action's own rotation there.

    keys : (F, B, 10) local SQT keys; halfway : (F - 1, B, 10) local SQT at the
    midpoints between them.
    """
    a = np.asarray(keys[:-1, :, sqt.ROT], np.float64)
    b = np.asarray(keys[1:, :, sqt.ROT], np.float64)
    mid = a + np.where((a * b).sum(-1, keepdims=True) < 0, -b, b)
    true = np.asarray(halfway[..., sqt.ROT], np.float64)
    dot = np.abs((mid * true).sum(-1))
    dot /= np.linalg.norm(mid, axis=-1) * np.linalg.norm(true, axis=-1)
    return 2 * np.arccos(np.minimum(dot, 1.0))


def interpolation_note(name: str, times: np.ndarray, keys: np.ndarray, evaluate, bone_names,
                       samples_per_frame: int = 1, tolerance: float = MISS_TOLERANCE):
    """A bake report line when the keys of action ``name`` are too far apart to be
    interpolated (:func:`interpolation_misses` above ``tolerance`` anywhere), else None.

    Parameters
    ----------
    times : (F,) Blender frames of the keys (evenly spaced); keys : (F, B, 10).
    evaluate : ``evaluate(frames)`` -> (n, B, 10) the action's local SQT at Blender
        frames (the F-curves evaluated, e.g. ``pose_channels.local_sqt``).
    bone_names : the B bone names; samples_per_frame : keys per crowd frame of the bake.

    The note names the bone and the key frames where the miss is largest, how many key
    intervals and bones miss, and the fewest samples per frame (up to
    :data:`MAX_SAMPLES_PER_FRAME`) whose keys follow the action over the
    :data:`ADVICE_INTERVALS` worst intervals (evaluated at those keys and halfway
    between them).
    """
    times = np.asarray(times, np.float64)
    misses = interpolation_misses(keys, evaluate(0.5 * (times[:-1] + times[1:])))
    bad = misses > tolerance
    if not bad.any():
        return None
    i, b = np.unravel_index(int(np.argmax(misses)), misses.shape)
    worst = float(misses[i, b])
    per_interval = misses.max(1)
    flagged = np.flatnonzero(per_interval > tolerance)
    check = flagged[np.argsort(-per_interval[flagged], kind="stable")[:ADVICE_INTERVALS]]
    frame = (times[1] - times[0]) * samples_per_frame     # Blender frames per crowd frame
    advice, left = None, worst
    for n in range(samples_per_frame + 1, MAX_SAMPLES_PER_FRAME + 1):
        step = frame / n
        grids = []
        for c in check.tolist():                           # their keys over each interval
            j = np.arange(math.floor((times[c] - times[0]) / step + 1e-9),
                          math.ceil((times[c + 1] - times[0]) / step - 1e-9) + 1)
            grids.append(times[0] + j * step)
        at = np.cumsum([0] + [len(g) for g in grids])
        poses = evaluate(np.concatenate(grids + [0.5 * (g[:-1] + g[1:]) for g in grids]))
        half = at[-1] + at - np.arange(len(at))            # where each grid's midpoints start
        left = max(float(interpolation_misses(poses[at[k]:at[k + 1]],
                                              poses[half[k]:half[k + 1]]).max())
                   for k in range(len(grids)))
        if left <= tolerance:
            advice = n
            break
    around = " (the long way round, e.g. an Euler angle crossing +-180 degrees)" \
        if worst > math.pi / 2 else ""
    intervals, bones = int(bad.any(1).sum()), int(bad.any(0).sum())
    text = (f"action {name!r}: bone {bone_names[b]!r} turns too fast between the keys at "
            f"frames {times[i]:g} and {times[i + 1]:g} to be interpolated: halfway, the "
            f"crowd's rotation is {worst:.2f} rad off the action's{around}; {intervals} key "
            f"interval{'s' if intervals != 1 else ''} of {bones} bone"
            f"{'s' if bones != 1 else ''} {'miss' if intervals != 1 else 'misses'} by more "
            f"than {tolerance:g} rad")
    if advice is not None:
        return text + f"; bake with {advice} samples per frame to follow it"
    return text + (f"; {MAX_SAMPLES_PER_FRAME} samples per frame still miss by {left:.2f} "
                   "rad there")


def between_key_misses(lo: np.ndarray, hi: np.ndarray, halfway: np.ndarray, skeleton,
                       unit_scale: float = 1.0, tolerance=None):
    """How far the pose a crowd plays halfway between two keys is from the action's
    own pose there: ``(position, rotation)``, each ``(n, B)`` float64.

    lo, hi : (n, B, 10) local SQT keys either side; halfway : (n, B, 10) the action's
    local SQT halfway between them (the F-curves evaluated there). The crowd's pose is
    the keys blended as a clip samples them (:func:`crowd_addon.core.pose.blend2` at
    0.5: lerp, shortest-arc nlerp, float32); both poses go through ``skeleton``, and
    ``position`` is the distance between each bone's head in armature space times
    ``unit_scale`` (the armature object's scale: scene units), ``rotation`` the angle
    in radians between the bone's armature-space rotations (scale divided out).

    tolerance : optional ``(position, rotation)``: only the intervals that may exceed
        either are computed exactly; the others (a bound puts them within both) get
        that bound instead, which is then below the tolerance. Without scale keys the
        bound is the errors carried down the hierarchy (a parent turned by ``a`` moves
        a child's head by at most ``a`` times its offset; angles add up), and the
        exact poses are composed as quaternions; scale keys take model matrices.
    """
    lo = np.asarray(lo, np.float32)
    hi = np.asarray(hi, np.float32)
    mid = sqt.blend2(lo, hi, np.float32(0.5))
    true = np.asarray(halfway, np.float64)
    scaled = (np.abs(lo[..., sqt.SCALE] - 1).max(initial=0) > 1e-6
              or np.abs(hi[..., sqt.SCALE] - 1).max(initial=0) > 1e-6
              or np.abs(true[..., sqt.SCALE] - 1).max(initial=0) > 1e-6)
    if scaled:
        return _matrix_misses(mid, true, skeleton, unit_scale)
    parents = skeleton.parents
    n, b = mid.shape[:2]
    position, rotation = _bound(mid, true, parents, unit_scale)
    if tolerance is None:
        position[:], rotation[:] = 0, 0
    if tolerance is not None:
        rows = np.flatnonzero((position > tolerance[0]).any(1)
                              | (rotation > tolerance[1]).any(1))
    else:
        rows = np.arange(n)
    if len(rows):
        p, r = _quaternion_misses(mid[rows], true[rows], parents, unit_scale)
        position[rows], rotation[rows] = p, r
    return position, rotation


def _bound(mid, true, parents, unit_scale):
    """Upper bounds ``(position, rotation)`` (n, B) of the armature-space misses of
    ``mid`` against ``true`` (local SQT, unit scale), from the local misses, in
    float32 bone-major rows (a screen: its margin covers float32's rounding)."""
    a = np.ascontiguousarray(np.asarray(mid, np.float32).transpose(2, 1, 0))   # (10, B, n)
    b = np.ascontiguousarray(np.asarray(true, np.float32).transpose(2, 1, 0))
    qa, qb = a[3:7], b[3:7]
    sign = np.where((qa * qb).sum(0) < 0, np.float32(-1), np.float32(1))
    chord = np.sqrt(((qa - sign * qb) ** 2).sum(0))           # |qa - qb| = 2 sin(angle / 4)
    # angle = 4 asin(chord / 2) <= 2 chord / sqrt(1 - chord^2 / 4)
    local_rot = 2 * chord / np.sqrt(np.maximum(1 - 0.25 * chord * chord, 1e-12))
    diff = (np.asarray(mid[..., sqt.TRANS], np.float64) - true[..., sqt.TRANS]).T
    local_pos = np.sqrt((diff.astype(np.float32) ** 2).sum(0))   # (B, n); roots far out too
    length = np.sqrt((b[7:] ** 2).sum(0))
    rot = local_rot
    pos = local_pos
    for j, p in enumerate(parents.tolist()):
        if p >= 0:                              # parents come first: theirs are final
            pos[j] += pos[p] + np.minimum(rot[p], 2.0) * length[j]
            rot[j] += rot[p]
    margin = np.float32(1e-6) * (1 + pos)           # float32 rounding, relative
    return ((pos + margin) * unit_scale).T.astype(np.float64), (rot + 1e-5).T.astype(np.float64)


def _quaternion_misses(mid, true, parents, unit_scale):
    """Exact armature-space misses of local SQT ``mid`` against ``true`` (unit scale):
    both composed as quaternions and offsets, parents first."""
    n, b = mid.shape[:2]
    both = np.concatenate([np.asarray(mid, np.float64), true]).transpose(2, 1, 0)  # (10, B, 2n)
    w, x, y, z = both[3].copy(), both[4].copy(), both[5].copy(), both[6].copy()
    norm = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    px, py, pz = both[7].copy(), both[8].copy(), both[9].copy()
    for j, p in enumerate(parents.tolist()):
        if p < 0:
            continue
        aw, ax, ay, az = w[p], x[p], y[p], z[p]
        tx, ty, tz = px[j], py[j], pz[j]
        # the offset turned by the parent's rotation: t + 2 w (v x t) + 2 v x (v x t)
        cx, cy, cz = ay * tz - az * ty, az * tx - ax * tz, ax * ty - ay * tx
        ex, ey, ez = ay * cz - az * cy, az * cx - ax * cz, ax * cy - ay * cx
        px[j] = px[p] + tx + 2 * (aw * cx + ex)
        py[j] = py[p] + ty + 2 * (aw * cy + ey)
        pz[j] = pz[p] + tz + 2 * (aw * cz + ez)
        bw, bx, by, bz = w[j].copy(), x[j].copy(), y[j].copy(), z[j].copy()
        w[j] = aw * bw - ax * bx - ay * by - az * bz
        x[j] = aw * bx + ax * bw + ay * bz - az * by
        y[j] = aw * by - ax * bz + ay * bw + az * bx
        z[j] = aw * bz + ax * by - ay * bx + az * bw
    d = np.sqrt((px[:, :n] - px[:, n:]) ** 2 + (py[:, :n] - py[:, n:]) ** 2
                + (pz[:, :n] - pz[:, n:]) ** 2)
    dot = np.abs(w[:, :n] * w[:, n:] + x[:, :n] * x[:, n:] + y[:, :n] * y[:, n:]
                 + z[:, :n] * z[:, n:])
    # the angle from |q_a - q_b| (shortest sign): exact near 0, where arccos is not
    chord = np.sqrt(np.maximum(2 - 2 * np.minimum(dot, 1.0), 0.0))
    angle = 4 * np.arcsin(np.minimum(chord / 2, 1.0))
    return d.T * unit_scale, angle.T


def _matrix_misses(mid, true, skeleton, unit_scale):
    """Exact misses through model matrices (poses with scale)."""
    from .skinning import model_matrices
    got = model_matrices(mid, skeleton)
    want = model_matrices(np.asarray(true, np.float32), skeleton)
    position = np.linalg.norm(got[..., :3, 3] - want[..., :3, 3], axis=-1) * unit_scale
    a, b = got[..., :3, :3], want[..., :3, :3]
    a = a / np.maximum(np.linalg.norm(a, axis=-2, keepdims=True), 1e-30)
    b = b / np.maximum(np.linalg.norm(b, axis=-2, keepdims=True), 1e-30)
    # |Ra - Rb|_F = 2 sqrt(2) sin(angle / 2): exact near 0, where arccos of the trace is not
    chord = np.sqrt(((a - b) ** 2).sum((-2, -1))) / (2 * math.sqrt(2))
    return position, 2 * np.arcsin(np.minimum(chord, 1.0))


def between_keys_note(name: str, times: np.ndarray, keys: np.ndarray, evaluate, skeleton,
                      samples_per_frame: int = 1, unit_scale: float = 1.0,
                      position_tolerance: float = POSITION_TOLERANCE,
                      rotation_tolerance: float = ROTATION_TOLERANCE):
    """A bake report line when the crowd's poses between the keys of action ``name``
    miss the action's (:func:`between_key_misses` halfway between every two keys, above
    ``position_tolerance`` scene units or ``rotation_tolerance`` radians anywhere), else
    None.

    Parameters
    ----------
    times : (F,) Blender frames of the keys (evenly spaced); keys : (F, B, 10).
    evaluate : ``evaluate(frames)`` -> (n, B, 10) the action's local SQT at Blender
        frames (the F-curves evaluated, e.g. ``pose_channels.local_sqt``).
    skeleton : the clip's skeleton; samples_per_frame : keys per crowd frame of the
        bake; unit_scale : scene units per armature unit.

    The note names the largest position miss and the largest rotation miss (each with
    its bone and key frames), the worst key intervals, how many intervals miss, and the
    fewest samples per frame (up to :data:`MAX_SAMPLES_PER_FRAME`) whose keys follow
    the action within the tolerances over the :data:`ADVICE_INTERVALS` worst
    intervals (all candidates evaluated in one call).
    """
    times = np.asarray(times, np.float64)
    keys = np.asarray(keys)
    tol = (position_tolerance, rotation_tolerance)
    pos, rot = between_key_misses(keys[:-1], keys[1:],
                                  evaluate(0.5 * (times[:-1] + times[1:])), skeleton,
                                  unit_scale, tol)
    score = np.maximum(pos / position_tolerance, rot / rotation_tolerance)
    per_interval = score.max(1)
    flagged = np.flatnonzero(per_interval > 1.0)
    if not len(flagged):
        return None
    ip, bp = np.unravel_index(int(np.argmax(pos)), pos.shape)
    ir, br = np.unravel_index(int(np.argmax(rot)), rot.shape)
    order = flagged[np.argsort(-per_interval[flagged], kind="stable")]
    check = order[:BETWEEN_ADVICE_INTERVALS]
    advice, left = _advice(times, check, evaluate, skeleton, samples_per_frame, unit_scale,
                           position_tolerance, rotation_tolerance)
    names = skeleton.bone_names

    def span(i):
        return f"{times[i]:g} and {times[i + 1]:g}"

    around = (" (the long way round, e.g. an Euler angle crossing +-180 degrees)"
              if rot[ir, br] > math.pi / 2 else "")
    worst = ", ".join(f"{0.5 * (times[i] + times[i + 1]):g}" for i in order[:5].tolist())
    n = len(flagged)
    misses = []
    if pos[ip, bp] > position_tolerance:
        misses.append(f"halfway between the keys at frames {span(ip)} bone {names[bp]!r}'s "
                      f"head is {pos[ip, bp]:.3g} scene units off")
    if rot[ir, br] > rotation_tolerance:
        misses.append(f"halfway between the keys at frames {span(ir)} bone {names[br]!r} "
                      f"is turned {rot[ir, br]:.3g} rad off{around}")
    text = (f"action {name!r}: between frames the crowd's pose misses the action's: "
            f"{'; '.join(misses)}; {n} of {len(times) - 1} key "
            f"interval{'s' if len(times) != 2 else ''} miss{'' if n != 1 else 'es'} by "
            f"more than {position_tolerance:g} scene units or {rotation_tolerance:g} rad "
            f"(worst halfway at frames {worst}); motion blur (substeps) and crowds playing "
            f"at other speeds show these poses")
    if advice is not None:
        return (text + f"; bake with {advice} samples per frame (Crowd > Settings > "
                       f"Samples per Frame) to follow it")
    return text + (f"; {MAX_SAMPLES_PER_FRAME} samples per frame still miss by "
                   f"{left[0]:.3g} scene units or {left[1]:.3g} rad there")


def _advice(times, check, evaluate, skeleton, samples_per_frame, unit_scale, ptol, rtol):
    """``(n, (position, rotation) left at the most samples)``: the fewest samples per
    frame above ``samples_per_frame`` whose keys follow the action over key intervals
    ``check`` (None when even :data:`MAX_SAMPLES_PER_FRAME` do not). A miss shrinks as
    keys get closer, so the candidates are bisected: one evaluation per probe."""
    frame = (times[1] - times[0]) * samples_per_frame     # Blender frames per crowd frame

    def misses(n):
        step = frame / n
        lo_t, hi_t = [], []
        for c in check.tolist():                           # their keys over each interval
            j = np.arange(math.floor((times[c] - times[0]) / step + 1e-9),
                          math.ceil((times[c + 1] - times[0]) / step - 1e-9) + 1)
            g = times[0] + j * step
            lo_t.append(g[:-1])
            hi_t.append(g[1:])
        lo_t, hi_t = np.concatenate(lo_t), np.concatenate(hi_t)
        m = len(lo_t)
        poses = evaluate(np.concatenate([lo_t, hi_t, 0.5 * (lo_t + hi_t)]))
        pos, rot = between_key_misses(poses[:m], poses[m:2 * m], poses[2 * m:], skeleton,
                                      unit_scale, (ptol, rtol))
        return float(pos.max()), float(rot.max())

    low, high = samples_per_frame + 1, MAX_SAMPLES_PER_FRAME
    if low > high:
        return None, (0.0, 0.0)
    left = misses(high)
    if left[0] > ptol or left[1] > rtol:
        return None, left
    while low < high:                       # the fewest that pass lies in low..high
        n = (low + high) // 2
        pos, rot = misses(n)
        if pos <= ptol and rot <= rtol:
            high = n
        else:
            low = n + 1
    return high, left
