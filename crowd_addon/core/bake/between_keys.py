"""The between-frame accuracy check of a bake: whether a clip's keys are close enough
to be interpolated.

Between keys the crowd interpolates (lerp, shortest-arc nlerp). Where the action turns
a bone the long way round between two keys (an Euler curve going from 179 to -179
degrees is a full turn in Blender), or fast enough that the arc is not a straight
blend, the in-between poses differ from Blender's: :func:`interpolation_misses`
measures it halfway between keys against the curves' true values and
:func:`interpolation_note` words it for the bake report, with the samples per frame
that would follow the motion. :func:`between_key_misses` and :func:`between_keys_note`
do the same for every bone's head and rotation in armature space (what the bake report
warns about). The keys themselves are :mod:`.clip_sampling`'s.
"""

from __future__ import annotations

import math

import numpy as np

from ..base import pose as sqt
from ..base.quaternion import multiply_parts
from .clip_sampling import MAX_SAMPLES_PER_FRAME

__all__ = ["interpolation_misses", "interpolation_note", "between_key_misses",
           "between_keys_note", "MISS_TOLERANCE", "POSITION_TOLERANCE", "ROTATION_TOLERANCE",
           "ADVICE_INTERVALS"]

#: Radians an interpolated rotation may miss the action's halfway between keys.
MISS_TOLERANCE = 0.05
#: How many of the worst key intervals the between-keys advice is checked on.
BETWEEN_ADVICE_INTERVALS = 4
#: Scene units a bone's head may miss the action's position between keys.
POSITION_TOLERANCE = 1e-3
#: Radians a bone's rotation (in armature space) may miss the action's between keys.
ROTATION_TOLERANCE = 1e-3
#: How many of the worst key intervals the samples-per-frame advice is checked on.
ADVICE_INTERVALS = 8


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
    the keys blended as a clip samples them (:func:`crowd_addon.core.base.pose.blend2` at
    0.5: lerp, shortest-arc nlerp, float32); both poses go through ``skeleton``, and
    ``position`` is the distance between each bone's head in armature space times
    ``unit_scale`` (the armature object's scale: scene units), ``rotation`` the angle
    in radians between the bone's armature-space rotations (scale divided out).

    Without scale keys the misses themselves are carried down the hierarchy, one
    depth level of bones at a time over all intervals (:func:`_difference_misses`),
    so float32 keeps them to about 1e-7 rad and 1e-7 of a bone's offset whatever the
    armature's size; scale keys take model matrices. Component-major arrays
    (``pose_channels.local_sqt(..., component_major=True)``) turn into the pass's
    layout fastest. ``tolerance`` is accepted for callers of the earlier screened version and
    changes nothing: every interval is computed exactly.
    """
    return _component_misses(_bones_by_intervals(lo), _bones_by_intervals(hi),
                             _bones_by_intervals(halfway), skeleton, unit_scale)


def _bones_by_intervals(poses):
    """``(10, B, n)`` float32 components of ``(n, B, 10)`` poses, each bone's row over
    the intervals contiguous (the layout the hierarchy pass gathers from)."""
    return np.ascontiguousarray(np.asarray(poses, np.float32).transpose(2, 1, 0))


def _component_misses(lo, hi, true, skeleton, unit_scale):
    """:func:`between_key_misses` of ``(10, B, n)`` float32 components."""
    scaled = any(float(np.abs(x[c] - 1).max(initial=0)) > 1e-6
                 for x in (lo, hi, true) for c in (0, 1, 2))
    if scaled:
        mid = sqt.blend2(lo.transpose(2, 1, 0), hi.transpose(2, 1, 0), np.float32(0.5))
        return _matrix_misses(mid, true.transpose(2, 1, 0), skeleton, unit_scale)
    # the crowd's pose halfway, as blend2 makes it: lerp, shortest-arc nlerp
    half = np.float32(0.5)
    sign = np.where(lo[3] * hi[3] + lo[4] * hi[4] + lo[5] * hi[5] + lo[6] * hi[6] < 0,
                    np.float32(-1), np.float32(1))
    q = [lo[c] + (sign * hi[c] - lo[c]) * half for c in (3, 4, 5, 6)]
    norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    norm[norm == 0] = 1
    q = [c / norm for c in q]
    t = [lo[c] + (hi[c] - lo[c]) * half for c in (7, 8, 9)]
    qb = true[3:7] / np.sqrt((true[3:7] ** 2).sum(0))     # the action's, unit
    return _difference_misses(q, t, qb, true[7:10], skeleton, unit_scale)


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _difference_misses(qa, ta, qb, tb, skeleton, unit_scale):
    """Exact armature-space misses ``(position, rotation)`` (n, B) float64 of the local
    rotations ``qa`` and offsets ``ta`` (components, each (B, n) float32) against
    ``qb``, ``tb`` (unit quaternions), carried down the hierarchy as differences;
    the components are (B, n) here, the results (n, B).

    With ``Q``/``P`` a bone's armature-space rotation and head, ``a`` the crowd's pose
    and ``b`` the action's: ``F = Qb^-1 Qa`` (the rotation miss, seen from the bone)
    and ``D = Qb^-1 (Pa - Pb)`` (the head miss, likewise) follow from the parent's as

        G = D_p + (t_a - t_b) + (F_p - 1) t_a     (the head miss in the parent's frame)
        D = q_b^-1 G,   F = q_b^-1 F_p q_a

    with ``q``, ``t`` the bone's local rotation and offset. ``|G|`` is the position
    miss and ``F``'s angle the rotation miss; ``(F - 1) t = 2 w (v x t) + 2 v x (v x t)``
    is formed from ``F``'s small vector part, so the misses keep their own relative
    precision in float32 instead of being differences of whole positions. All the
    intervals go through one depth level of bones at a time.
    """
    bones, n = qa[0].shape
    f = np.empty((4, bones, n), np.float32)          # F per bone
    d = np.empty((3, bones, n), np.float32)          # D per bone
    position = np.empty((bones, n), np.float32)
    roots = np.flatnonzero(skeleton.parents < 0)
    for js, ps in [(roots, None)] + list(skeleton.levels):
        a = [c[js] for c in qa]
        t = [c[js] for c in ta]
        g = [t[i] - tb[i][js] for i in range(3)]
        if ps is not None:
            fp = f[:, ps]
            v = fp[1:]
            c = _cross(v, t)
            e = _cross(v, c)
            for i in range(3):
                g[i] += d[i][ps] + 2 * (fp[0] * c[i] + e[i])
            a = multiply_parts(fp, a)
        bw, bx, by, bz = (c[js] for c in qb)
        f[:, js] = multiply_parts((bw, -bx, -by, -bz), a)
        position[js] = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
        # D = q_b^-1 G: G turned by the conjugate, G - 2 w (v x G) + 2 v x (v x G)
        v = (bx, by, bz)
        c = _cross(v, g)
        e = _cross(v, c)
        for i in range(3):
            d[i][js] = g[i] - 2 * (bw * c[i] - e[i])
    vector = np.sqrt(f[1] * f[1] + f[2] * f[2] + f[3] * f[3])
    rotation = 2 * np.arctan2(vector, np.abs(f[0]))
    return position.T.astype(np.float64) * unit_scale, rotation.T.astype(np.float64)


def _matrix_misses(mid, true, skeleton, unit_scale):
    """Exact misses through model matrices (poses with scale)."""
    from ..base.skinning import model_matrices
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
                      rotation_tolerance: float = ROTATION_TOLERANCE, halfway=None):
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
    halfway : optional (F - 1, B, 10) ``evaluate`` of the midpoints between the keys,
        when the caller has it (evaluated together with the keys).

    The note names the largest position miss and the largest rotation miss (each with
    its bone and key frames), the worst key intervals, how many intervals miss, and the
    fewest samples per frame (up to :data:`MAX_SAMPLES_PER_FRAME`) whose keys follow
    the action within the tolerances over the :data:`BETWEEN_ADVICE_INTERVALS` worst
    intervals (estimated from the 1/n^2 law of interpolation and verified there: one
    evaluation, two where the law does not hold).
    """
    times = np.asarray(times, np.float64)
    keys = np.asarray(keys)
    both = _bones_by_intervals(keys)                  # (10, B, F): lo and hi are views
    if halfway is None:
        halfway = evaluate(0.5 * (times[:-1] + times[1:]))
    pos, rot = _component_misses(both[..., :-1], both[..., 1:],
                                 _bones_by_intervals(halfway), skeleton, unit_scale)
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
                           position_tolerance, rotation_tolerance,
                           float(per_interval[check].max()))
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


def _advice(times, check, evaluate, skeleton, samples_per_frame, unit_scale, ptol, rtol,
            worst):
    """``(n, (position, rotation) left at the most samples)``: the fewest samples per
    frame above ``samples_per_frame`` whose keys follow the action over key intervals
    ``check`` (None when even :data:`MAX_SAMPLES_PER_FRAME` do not, and then their
    misses with that many; else ``left`` is None); ``worst``: their
    largest miss over its tolerance at the bake's samples.

    An interpolation's miss shrinks as the square of the key spacing, so ``n`` is
    first estimated as ``samples_per_frame * sqrt(worst)`` and that estimate and the
    one below are evaluated together (one call of ``evaluate``); only where the law
    does not hold (a bone turning the long way round follows with 2 whatever its
    miss, a step never does) are the other candidates evaluated, all in one more call.
    """
    frame = (times[1] - times[0]) * samples_per_frame     # Blender frames per crowd frame
    low, high = samples_per_frame + 1, MAX_SAMPLES_PER_FRAME
    if low > high:
        return None, (0.0, 0.0)

    def misses(candidates):
        """{n: (position, rotation) largest misses with n samples per frame}."""
        grids, count = [], []
        for n in candidates:
            step = frame / n
            m = 0
            for c in check.tolist():                       # their keys over each interval
                j = np.arange(math.floor((times[c] - times[0]) / step + 1e-9),
                              math.ceil((times[c + 1] - times[0]) / step - 1e-9) + 1)
                grids.append(times[0] + j * step)
                m += len(j) - 1
            count.append(m)
        # each grid's keys once, then the halfway points of all of them
        keys = np.concatenate(grids)
        ends = np.cumsum([len(g) for g in grids])
        lo = np.delete(np.arange(len(keys)), ends - 1)            # keys with one after
        poses = _bones_by_intervals(evaluate(np.concatenate([keys, 0.5 * (keys[lo]
                                                                          + keys[lo + 1])])))
        pos, rot = _component_misses(poses[..., lo], poses[..., lo + 1],
                                     poses[..., len(keys):], skeleton, unit_scale)
        at = np.cumsum([0] + count)
        return {n: (float(pos[at[k]:at[k + 1]].max()), float(rot[at[k]:at[k + 1]].max()))
                for k, n in enumerate(candidates)}

    def passes(miss):
        return miss[0] <= ptol and miss[1] <= rtol

    guess = min(high, max(low, math.ceil(samples_per_frame * math.sqrt(worst) - 1e-9)))
    found = misses(sorted({max(low, guess - 1), guess}))
    if passes(found[guess]) and (guess == low or not passes(found[guess - 1])):
        return guess, None
    rest = [n for n in range(low, high + 1) if n not in found
            and (n < guess if passes(found[guess]) else n > guess)]
    if rest:
        found.update(misses(rest))
    fewest = [n for n in sorted(found) if passes(found[n])]
    return (fewest[0], None) if fewest else (None, found[high])
