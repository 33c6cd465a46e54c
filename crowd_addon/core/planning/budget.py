"""GPU memory budget: the paper's clip-count model and a stream/offset planner.

Paduraru, section 5. All sizes are in **bytes**; clip lengths and offsets in frames of
the crowd (a clip keyed at another rate plays at its own rate: its length in crowd
frames is ``Clip.frames_at(fps)``, not its key count).

The paper's model (functions named after its symbols)::

    PoseSize      = NBones x SizePerBone                       pose_size
    ClipSize_OLD  = MotionLength x PoseSize                    clip_size_old
    NumClips_OLD  = floor(MemBudget / ClipSize_OLD)            num_clips_old
    ClipSize_NEW  = M x PoseSize                               clip_size_new
    NumClips_NEW  = floor(MotionLength / M x NumClips_OLD)     num_clips_new

``num_clips_new`` is the paper's formula exactly: it scales NumClips_OLD, it does not
divide the budget by ClipSize_NEW. That second figure,
``floor(MemBudget / ClipSize_NEW)``, is :func:`num_clips_new_direct`; it differs from the
paper's by at most ``MotionLength / M`` clips (the floor taken before the scaling).
The paper requires ``M <= MotionLength`` ("the maximum offset cannot exceed the number
of frames in the animation"); it also calls ``MotionLength / M`` "always in (0, 1]",
which holds for the inverse ratio ``M / MotionLength``; the factor itself is >= 1.

What reproduces and what does not, with the paper's inputs (82 bones, PoseSize 0.8 KB
i.e. 10 bytes per bone, MotionLength 300, MemBudget 520 MB, M = 60):

- ClipSize_OLD = 82 x 10 B x 300 = 246,000 B, the paper's "246KB".  Reproduces.
- NumClips_NEW = floor(300 / 60 x 216) = 1,080, the paper's figure.  Reproduces
  *given* the paper's NumClips_OLD of 216.
- NumClips_OLD does **not** reproduce: floor(520e6 / 246,000) = 2,113 (decimal MB) and
  floor(520 x 2**20 / 246,000) = 2,216 (MiB), not 216. Feeding those into the paper's
  formula gives 10,565 and 11,080 clips. The printed 216 and 1,080 equal 2,216 and
  11,080 with their first digit missing, which suggests a typesetting slip, but the
  paper does not say so; this module computes what the formulas give and never
  substitutes the printed 216. ``PAPER_NUM_CLIPS_OLD`` keeps the printed value only so
  the NEW-from-OLD step can be checked against the paper.

The planner (:func:`plan`) works in the GPU layout of docs/architecture.md: a pose row is
``bones x 3`` RGBA32F texels (48 bytes per bone); the pose history holds ``M x S`` rows
(S streams, M offsets), followed by one row per unique-pool agent and per transition slot.
Its heuristic is documented on :func:`plan` and in ``docs/performance_budget.md``.

Pure stdlib; never imports bpy.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from fractions import Fraction

from ..base.errors import CrowdError

__all__ = [
    "GPU_BYTES_PER_BONE",
    "PAPER_BONES",
    "PAPER_BYTES_PER_BONE",
    "PAPER_MOTION_LENGTH",
    "PAPER_BUDGET_MB",
    "PAPER_MAX_OFFSET",
    "PAPER_NUM_CLIPS_OLD",
    "PAPER_NUM_CLIPS_NEW",
    "MemoryModel",
    "BudgetPlan",
    "pose_size",
    "clip_size_old",
    "clip_size_new",
    "num_clips_old",
    "num_clips_new",
    "num_clips_new_direct",
    "memory_model",
    "plan",
]

#: Bytes per bone in the GPU pose texture: three RGBA32F texels (docs/architecture.md.
GPU_BYTES_PER_BONE = 3 * 4 * 4

# The paper's stated inputs (section 5) and the two clip counts it prints.
PAPER_BONES = 82
PAPER_BYTES_PER_BONE = 10  # "0.8KB" per pose / 82 bones, compressed SQT
PAPER_MOTION_LENGTH = 300  # 10 s at 30 fps
PAPER_BUDGET_MB = 520
PAPER_MAX_OFFSET = 60
PAPER_NUM_CLIPS_OLD = 216  # as printed; does not follow from the inputs above
PAPER_NUM_CLIPS_NEW = 1080  # as printed; = floor(300 / 60 x 216)


# --------------------------------------------------------------------------- checks

def _number(value, name: str, *, positive: bool = True) -> float:
    """Return ``value`` as a finite float, > 0 (or >= 0 when not ``positive``)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise CrowdError(f"budget: {name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise CrowdError(f"budget: {name} must be finite, got {value!r}")
    if positive and v <= 0:
        raise CrowdError(f"budget: {name} must be > 0, got {value!r}")
    if not positive and v < 0:
        raise CrowdError(f"budget: {name} must be >= 0, got {value!r}")
    return v


def _count(value, name: str, *, minimum: int = 1) -> int:
    """Return ``value`` as an int >= ``minimum`` (integral floats are accepted)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise CrowdError(f"budget: {name} must be an integer, got {value!r}")
    if isinstance(value, numbers.Integral):
        v = int(value)
    else:
        f = float(value)
        if not (math.isfinite(f) and f.is_integer()):
            raise CrowdError(f"budget: {name} must be an integer, got {value!r}")
        v = int(f)
    if v < minimum:
        raise CrowdError(f"budget: {name} must be >= {minimum}, got {value!r}")
    return v


def _offset_fits(max_offset: int, frames: float, what: str) -> None:
    if max_offset > frames:
        raise CrowdError(f"budget: max_offset {max_offset} exceeds {what} ({frames:g} "
                         "frames); the maximum offset cannot exceed the number of frames "
                         "in the animation")


def _floor_div(a: float, b: float) -> int:
    """floor(a / b) computed exactly (no float rounding at integer boundaries)."""
    return math.floor(Fraction(a) / Fraction(b))


# ------------------------------------------------------------------- paper's model

def pose_size(bones, bytes_per_bone) -> float:
    """PoseSize = NBones x SizePerBone, in bytes.

    Parameters
    ----------
    bones : int >= 1, NBones.
    bytes_per_bone : float > 0, SizePerBone in bytes (10 in the paper, 48 on our GPU).
    """
    return _count(bones, "bones") * _number(bytes_per_bone, "bytes_per_bone")


def clip_size_old(bones, bytes_per_bone, motion_length) -> float:
    """ClipSize_OLD = MotionLength x PoseSize, in bytes (a whole clip resident).

    ``clip_size_old(82, 10, 300) == 246_000``, the paper's 246 KB.

    Parameters
    ----------
    bones : int >= 1.
    bytes_per_bone : float > 0, bytes.
    motion_length : float > 0, average keys (frames) per clip.
    """
    return _number(motion_length, "motion_length") * pose_size(bones, bytes_per_bone)


def clip_size_new(bones, bytes_per_bone, max_offset) -> float:
    """ClipSize_NEW = M x PoseSize, in bytes (the pose history of one stream).

    Parameters
    ----------
    bones : int >= 1.
    bytes_per_bone : float > 0, bytes.
    max_offset : int >= 1, M in frames.
    """
    return _count(max_offset, "max_offset") * pose_size(bones, bytes_per_bone)


def num_clips_old(budget_bytes, clip_size_old_bytes) -> int:
    """NumClips_OLD = floor(MemBudget / ClipSize_OLD).

    Parameters
    ----------
    budget_bytes : float > 0, MemBudget in bytes.
    clip_size_old_bytes : float > 0, ClipSize_OLD in bytes.
    """
    return _floor_div(_number(budget_bytes, "budget_bytes"),
                      _number(clip_size_old_bytes, "clip_size_old"))


def num_clips_new(num_clips_old, motion_length, max_offset) -> int:
    """NumClips_NEW = floor(MotionLength / M x NumClips_OLD), the paper's formula.

    ``num_clips_new(num_clips_old=216, motion_length=300, max_offset=60) == 1080``.

    Parameters
    ----------
    num_clips_old : int >= 0.
    motion_length : float > 0, average keys (frames) per clip.
    max_offset : int >= 1, M in frames, at most ``motion_length``.

    Raises
    ------
    CrowdError
        If ``max_offset > motion_length``.
    """
    old = _count(num_clips_old, "num_clips_old", minimum=0)
    length = _number(motion_length, "motion_length")
    m = _count(max_offset, "max_offset")
    _offset_fits(m, length, "motion_length")
    return math.floor(Fraction(length) * old / m)


def num_clips_new_direct(budget_bytes, clip_size_new_bytes) -> int:
    """floor(MemBudget / ClipSize_NEW): the budget divided directly, not the paper's step.

    Parameters
    ----------
    budget_bytes : float > 0, bytes.
    clip_size_new_bytes : float > 0, ClipSize_NEW in bytes.
    """
    return _floor_div(_number(budget_bytes, "budget_bytes"),
                      _number(clip_size_new_bytes, "clip_size_new"))


@dataclass(frozen=True)
class MemoryModel:
    """Every figure of the paper's model for one set of inputs (bytes, frames)."""

    budget_bytes: float
    pose_bytes: float
    motion_length: float
    max_offset: int
    clip_size_old: float
    clip_size_new: float
    num_clips_old: int
    num_clips_new: int  # the paper's formula, scaled from num_clips_old
    num_clips_new_direct: int  # floor(budget / clip_size_new)


def memory_model(budget_bytes, motion_length, max_offset, *, pose_bytes=None,
                 bones=None, bytes_per_bone=None) -> MemoryModel:
    """Evaluate the paper's model.

    Parameters
    ----------
    budget_bytes : float > 0, MemBudget in bytes.
    motion_length : float > 0, MotionLength, average frames per clip.
    max_offset : int, 1 <= M <= motion_length.
    pose_bytes : float > 0, PoseSize in bytes; or give ``bones`` and ``bytes_per_bone``
        (``pose_bytes`` wins when both are given).
    """
    if pose_bytes is not None:
        pose = _number(pose_bytes, "pose_bytes")
    elif bones is not None and bytes_per_bone is not None:
        pose = pose_size(bones, bytes_per_bone)
    else:
        raise CrowdError("budget: give pose_bytes, or bones and bytes_per_bone")
    budget = _number(budget_bytes, "budget_bytes")
    length = _number(motion_length, "motion_length")
    m = _count(max_offset, "max_offset")
    _offset_fits(m, length, "motion_length")
    size_old = length * pose
    size_new = m * pose
    old = _floor_div(budget, size_old)
    return MemoryModel(
        budget_bytes=budget, pose_bytes=pose, motion_length=length, max_offset=m,
        clip_size_old=size_old, clip_size_new=size_new,
        num_clips_old=old, num_clips_new=num_clips_new(old, length, m),
        num_clips_new_direct=_floor_div(budget, size_new))


# ------------------------------------------------------------------------ planner

@dataclass(frozen=True)
class BudgetPlan:
    """A proposed stream count and max offset, with the figures that justify it.

    Bytes are GPU pose-texture bytes; rows are pose rows of ``row_bytes`` each.
    """

    streams: int  # S
    max_offset: int  # M, frames
    agents: int
    streamed_agents: int  # agents - unique_agents
    unique_agents: int
    transition_slots: int
    row_bytes: int  # bones x bytes_per_bone
    history_rows: int  # M x S
    total_rows: int  # M x S + unique + transition slots
    bytes_used: int  # total_rows x row_bytes
    budget_bytes: float
    max_streams: int  # streams that fit the budget at this M
    key_capacity: int  # (stream, offset) keys the budget could hold at all
    agents_per_stream: float
    agents_per_key: float  # streamed agents per (stream, offset) pair
    target_agents_per_key: float
    meets_target: bool
    offset_seconds: float  # M / fps
    stream_upload_bytes: int  # per frame: S x row_bytes (the new history slice)
    peak_upload_bytes: int  # per frame with every unique row and transition slot dirty
    notes: tuple = ()


def _is_clip(value) -> bool:
    """A clip object (``Clip``: ``frames_at(fps)`` gives its length at a crowd rate)."""
    return callable(getattr(value, "frames_at", None))


def _clip_frames(clip_frames, fps: float) -> tuple[float, float]:
    """(shortest, mean) of a clip length or a sequence of them, in crowd frames (clip
    objects are converted at ``fps``)."""
    if (isinstance(clip_frames, numbers.Real) and not isinstance(clip_frames, bool)) \
            or _is_clip(clip_frames):
        values = [clip_frames]
    else:
        try:
            values = list(clip_frames)
        except TypeError:
            raise CrowdError("budget: clip_frames must be a number or a sequence of "
                             f"numbers, got {clip_frames!r}") from None
        if not values:
            raise CrowdError("budget: clip_frames is empty")
    lengths = [_number(v.frames_at(fps) if _is_clip(v) else v, f"clip_frames[{i}]")
               for i, v in enumerate(values)]
    shortest = min(lengths)
    if shortest < 1:
        raise CrowdError(f"budget: clip_frames must be >= 1 frame, shortest is {shortest:g}")
    return shortest, sum(lengths) / len(lengths)


def plan(agents, budget_bytes, bones, clip_frames, *, bytes_per_bone=GPU_BYTES_PER_BONE,
         fps=30.0, max_agents_per_key=4.0, offset_seconds=2.0, max_offset=None,
         streams=None, unique_agents=0, transition_slots=800) -> BudgetPlan:
    """Propose a stream count S and max offset M that fit a GPU pose budget.

    Heuristic (each step can be pinned by passing ``max_offset`` or ``streams``):

    1. Fixed rows: one per unique-pool agent and per transition slot. They must fit.
    2. M = round(``offset_seconds`` x fps) (2 s: the paper's 60 frames at 30 fps),
       capped by the shortest clip, since an offset cannot exceed a clip's frames.
    3. S = the fewest streams that keep streamed agents per (stream, offset) key at or
       below ``max_agents_per_key`` (4: the paper's 65,000 / (256 x 60) = 4.2), i.e.
       ``ceil(streamed / (target x M))``, but no more than the budget holds. Streams
       are the per-frame cost (one CPU evaluation and one uploaded row each), so the
       planner does not spend budget on streams the diversity target does not need;
       ``max_streams`` reports the headroom.
    4. If not even one stream of M poses fits, M shrinks to what one stream can hold.

    The memory used by the history is ``M x S x row_bytes``; for a given budget the
    number of keys ``M x S`` is bounded by ``key_capacity`` whatever the split, so
    when ``meets_target`` is false no choice of S and M would meet the target.

    Parameters
    ----------
    agents : int >= 1, all agents of the crowd.
    budget_bytes : float > 0, GPU bytes for the pose texture.
    bones : int >= 1, max bones of any skeleton (a row fits every skeleton).
    clip_frames : float or sequence of float, clip lengths in crowd frames (>= 1 each),
        i.e. at ``fps``: a clip of F keys at its own ``clip_fps`` lasts
        ``(F - 1) * fps / clip_fps`` crowd frames (a clip plays at its own rate). Clip
        objects may be given instead of numbers: ``Clip.frames_at(fps)``.
    bytes_per_bone : float > 0, bytes per bone and row (48: three RGBA32F texels).
    fps : float > 0, crowd frames per second.
    max_agents_per_key : float > 0, diversity target.
    offset_seconds : float > 0, preferred M in seconds before the clip cap.
    max_offset : int, optional, fixes M (1 <= M <= shortest clip).
    streams : int >= 1, optional, fixes S.
    unique_agents : int, 0 <= unique_agents <= agents, agents in the unique pool.
    transition_slots : int >= 0, NT (800 in the paper).

    Returns
    -------
    BudgetPlan

    Raises
    ------
    CrowdError
        On a non-positive or non-finite input (the field is named), a max offset
        longer than the shortest clip, or a budget that cannot hold the fixed rows
        plus one stream (or the given ``streams``) at the given or smallest M.
    """
    n_agents = _count(agents, "agents")
    budget = _number(budget_bytes, "budget_bytes")
    n_bones = _count(bones, "bones")
    per_bone = _number(bytes_per_bone, "bytes_per_bone")
    rate = _number(fps, "fps")
    target = _number(max_agents_per_key, "max_agents_per_key")
    seconds = _number(offset_seconds, "offset_seconds")
    n_unique = _count(unique_agents, "unique_agents", minimum=0)
    n_slots = _count(transition_slots, "transition_slots", minimum=0)
    shortest, _ = _clip_frames(clip_frames, rate)
    if n_unique > n_agents:
        raise CrowdError(f"budget: unique_agents ({n_unique}) exceeds agents ({n_agents})")
    fixed_m = None
    if max_offset is not None:
        fixed_m = _count(max_offset, "max_offset")
        _offset_fits(fixed_m, shortest, "the shortest clip")
    fixed_s = None if streams is None else _count(streams, "streams")

    row = math.ceil(n_bones * per_bone)
    streamed = n_agents - n_unique
    fixed_rows = n_unique + n_slots
    free_rows = math.floor(budget // row) - fixed_rows
    if free_rows < 0:
        raise CrowdError(
            f"budget: {fixed_rows} unique and transition rows need {fixed_rows * row:,} B, "
            f"more than the budget of {budget:,.0f} B")
    notes = []
    m_cap = math.floor(shortest)
    if fixed_m is not None:
        m = fixed_m
    else:
        m = max(1, min(round(seconds * rate), m_cap))
        if m == m_cap and round(seconds * rate) > m_cap:
            notes.append(f"M capped at the shortest clip ({m_cap} frames)")
    want_s = fixed_s if fixed_s is not None else (1 if streamed else 0)
    if want_s * m > free_rows:
        if fixed_m is None and free_rows >= want_s:
            m = free_rows // want_s
            notes.append(f"M reduced to {m} so that {want_s} stream(s) fit the budget")
        else:
            raise CrowdError(
                f"budget: {want_s} stream(s) x M={m} need {want_s * m * row:,} B of pose "
                f"history but only {free_rows * row:,} B are left after "
                f"{fixed_rows} unique and transition rows")
    max_s = free_rows // m
    if fixed_s is not None:
        s = fixed_s
    else:
        needed = min(math.ceil(streamed / (target * m)), streamed)
        s = min(needed, max_s)
        if s < needed:
            notes.append(f"budget holds {free_rows:,} (stream, offset) keys, so at least "
                         f"{streamed / free_rows:.2f} agents per key whatever S and M; "
                         f"target {target:g}")
    per_key = streamed / (s * m) if s else 0.0
    meets = per_key <= target
    history = m * s
    total = history + fixed_rows
    return BudgetPlan(
        streams=s, max_offset=m, agents=n_agents, streamed_agents=streamed,
        unique_agents=n_unique, transition_slots=n_slots, row_bytes=row,
        history_rows=history, total_rows=total, bytes_used=total * row,
        budget_bytes=budget, max_streams=max_s, key_capacity=free_rows,
        agents_per_stream=streamed / s if s else 0.0, agents_per_key=per_key,
        target_agents_per_key=target, meets_target=meets, offset_seconds=m / rate,
        stream_upload_bytes=s * row, peak_upload_bytes=(s + fixed_rows) * row,
        notes=tuple(notes))
