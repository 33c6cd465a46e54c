"""The bounds every run of a crowd is checked against before it starts.

A frame number is a whole number of magnitude at most :data:`MAX_FRAME` (as in
configuration files and snapshots), and one run steps at most :data:`MAX_RUN_FRAMES`
frames: one :meth:`Crowd.advance_to <.crowd.Crowd.advance_to>` call, one snapshot pass
(``crowd snapshot``, :func:`.snapshot_store.write_snapshots`), one recording
(:func:`.recorder.record`). A longer run is refused before its first step, with the
bound and how to split it: into runs of at most that many frames, each going on from
where the last one stopped (a crowd stepped on, or the last one's snapshot).
"""

from __future__ import annotations

import math
from numbers import Integral, Real

from .errors import CrowdError

__all__ = ["MAX_FRAME", "MAX_RUN_FRAMES", "whole_frame", "check_run", "finite"]

#: The largest frame number in magnitude.
MAX_FRAME = 2**31 - 1
#: The most frames one run may step: about 9 hours of a shot at 30 fps; at the paper's
#: scale (65k agents, about 2 ms a frame) half an hour of stepping.
MAX_RUN_FRAMES = 1_000_000


def whole_frame(value, what: str) -> int:
    """``value`` as an int frame number (a whole number, an integral float included, of
    magnitude at most :data:`MAX_FRAME`); CrowdError naming ``what`` otherwise."""
    ok = not isinstance(value, bool) and (
        isinstance(value, Integral)
        or (isinstance(value, Real) and float(value).is_integer()))
    if not ok:
        raise CrowdError(f"{what}: a frame must be a whole number, got {value!r}")
    frame = int(value)
    if abs(frame) > MAX_FRAME:
        raise CrowdError(f"{what}: frame {frame} is past the largest frame number "
                         f"(magnitude at most {MAX_FRAME})")
    return frame


def check_run(what: str, start: int, end: int, split: str) -> None:
    """Refuse a run that would step from frame ``start`` to frame ``end`` when that is
    more than :data:`MAX_RUN_FRAMES` frames. ``split`` says how to split it."""
    steps = end - start
    if steps > MAX_RUN_FRAMES:
        raise CrowdError(f"{what}: reaching frame {end} steps {steps:,} frames from frame "
                         f"{start}, where the run starts; a single run steps at most "
                         f"{MAX_RUN_FRAMES:,} frames (MAX_RUN_FRAMES, "
                         f"crowd_addon.core.base.bounds): split it: {split}")


def finite(value, what) -> float:
    """``value`` as a finite float, or a CrowdError naming ``what``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CrowdError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise CrowdError(f"{what} must be finite, got {value!r}")
    return v
