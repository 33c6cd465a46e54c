"""A crowd's whole state, from its parts and back: what a snapshot is taken of,
checked against and restored into (the file and its value: :mod:`.snapshot`).

Each part keeps its own state (``state()`` / ``set_state()``: the pools, agents, slots
with their queue, the tree evaluator, events, looks and the show) and checks what it
can; :func:`restore` sets them all, checks what they refer to across parts, and rolls
the crowd back to where it was when a value is wrong, so a failed restore changes
nothing.
"""

from __future__ import annotations

import json

import numpy as np

from ..base.errors import CrowdError
from ..base.state import copy_state
from ..runtime.agents import STREAM, TRANSITION, UNIQUE
from .snapshot import Snapshot, flatten_state, value_kind, check_values

__all__ = ["take", "check", "restore", "set_state", "crowd_state"]


def crowd_state(crowd) -> dict:
    """Every part's state (views), what a snapshot copies."""
    return {"crowd": {"frame": int(crowd.frame), "origin": int(crowd._origin),
                      "steps": crowd._steps, "ms_total": crowd._ms_total,
                      "sub_streams": crowd.subs.streams, "sub_uniques": crowd.subs.uniques},
            "streams": crowd.streams.state(), "uniques": crowd.uniques.state(),
            "agents": crowd.agents.state(), "slots": crowd.slots.state(),
            "evaluator": crowd.evaluator.state(), "events": crowd.events.state(),
            "looks": crowd.looks.state(),
            **({"show": crowd.show.state()} if crowd.show is not None else {})}


def set_state(crowd, state: dict) -> None:
    """Set every part from ``state`` (:func:`crowd_state`'s layout); ValueError when
    a value refers to what does not exist (the crowd may then be part set: see
    :func:`restore`). The streams go last, after every check, and set themselves
    whole or not at all: a failed restore never touches the history ring, the
    largest part, so :func:`restore` keeps no copy of it to roll back to."""
    _set_parts(crowd, state)
    _check_refs(crowd)
    crowd.streams.set_state(state["streams"])
    crowd._events_fired = 0
    crowd.skinning.restored()


def _set_parts(crowd, state: dict) -> None:
    """Every part of ``state`` but the streams."""
    c = state["crowd"]
    crowd.frame, crowd._origin = int(c["frame"]), int(c["origin"])
    crowd._steps, crowd._ms_total = int(c["steps"]), float(c["ms_total"])
    crowd.subs.streams[...] = c["sub_streams"]
    crowd.subs.uniques[...] = c["sub_uniques"]
    crowd.uniques.set_state(state["uniques"])
    crowd.slots.set_state(state["slots"])
    crowd.agents.set_state(state["agents"])        # after the slots: it regroups by target
    crowd.evaluator.set_state(state["evaluator"])
    crowd.events.set_state(state["events"])
    crowd.looks.set_state(state["looks"], len(crowd.look.targets))
    if crowd.show is not None:
        crowd.show.set_state(state["show"])


def _check_refs(crowd) -> None:
    """Raise ValueError unless what the agents, slots and queue play exists (restored
    values the shape checks cannot see)."""
    a = crowd.agents
    s, u, m = crowd.streams.count, crowd.uniques.count, crowd.streams.max_offset

    def refs_ok(kind, ref, off):
        return bool(np.all(np.where(kind == STREAM, (ref >= 0) & (ref < s) & (off >= 0)
                                    & (off < m), (kind == UNIQUE) & (ref >= 0) & (ref < u))))
    tr = a.kind == TRANSITION
    if not (np.isin(a.kind, (STREAM, UNIQUE, TRANSITION)).all()
            and refs_ok(a.kind[~tr], a.ref[~tr], a.offset[~tr])):
        raise ValueError("an agent plays a stream, unique or slot that does not exist")
    crowd.slots.check_refs(refs_ok)


def take(crowd) -> Snapshot:
    """A :class:`Snapshot` of ``crowd`` now (copies)."""
    arrays, values = flatten_state(crowd_state(crowd))
    return Snapshot(int(crowd.frame), crowd.config_digest, int(crowd.substeps), arrays,
                    json.loads(json.dumps(values)))      # packing copies the arrays


def check(crowd, snap: Snapshot, what: str = "snapshot") -> None:
    """Raise CrowdError (naming what differs) unless ``snap`` fits ``crowd``: same
    configuration digest and samples per frame, and the same state arrays (names,
    dtypes, shapes) and values (names, kinds). Changes nothing."""
    if snap.config_digest != crowd.config_digest:
        raise CrowdError(f"{what} of frame {snap.frame} was taken of another crowd "
                         f"configuration (digest {snap.config_digest[:12]}, this crowd's "
                         f"{crowd.config_digest[:12]})")
    if snap.substeps != crowd.substeps:
        raise CrowdError(f"{what} of frame {snap.frame} keeps {snap.substeps} samples a "
                         f"frame, this crowd {crowd.substeps}")
    from ..base.bounds import MAX_FRAME
    if isinstance(snap.frame, bool) or not isinstance(snap.frame, int) or \
            abs(snap.frame) > MAX_FRAME:
        raise CrowdError(f"{what}: its frame {snap.frame!r} is not a frame number (a whole "
                         f"number of magnitude at most {MAX_FRAME})")
    check_values(snap.values, snap.frame, what)
    arrays, values = flatten_state(crowd_state(crowd))
    for name in sorted(set(arrays) | set(snap.packed)):
        a, b = arrays.get(name), snap.packed.get(name)
        if a is None or b is None:
            raise CrowdError(f"{what}: state array {name!r} is "
                             f"{'missing' if b is None else 'unknown to this crowd'}")
        # the queue's line and the show's due lists vary in length
        if a.dtype != b.dtype or (a.shape != b.shape and not _varies(name)) \
                or a.ndim != b.ndim:
            raise CrowdError(f"{what}: state array {name!r} is {b.dtype} {b.shape}, "
                             f"this crowd's is {a.dtype} {a.shape}")
    for name, b in snap.packed.items():
        if b.dtype.kind == "f" and not name.endswith(_NAN_ALLOWED) and \
                not all(np.isfinite(v).all() for v in b.element_values()):
            raise CrowdError(f"{what}: state array {name!r} holds values that are not "
                             "finite")
    for name in sorted(set(values) | set(snap.values)):
        if name not in values or name not in snap.values:
            raise CrowdError(f"{what}: state value {name!r} is "
                             f"{'missing' if name not in snap.values else 'unknown'}")
        if value_kind(snap.values[name]) != value_kind(values[name]):
            raise CrowdError(f"{what}: state value {name!r} is a "
                             f"{value_kind(snap.values[name])}, expected a {value_kind(values[name])}")


#: float state arrays where NaN means something (a clip player's "no last time", a
#: state machine's "not entered yet")
_NAN_ALLOWED = (".prev", ".entered")


def _varies(name) -> bool:
    return name.endswith(("queue.line", ".ids", ".counts", ".frame", ".duration",
                          ".reaction", "log_stream", "log_name", "log_frame",
                          "releases.cue", "releases.stream"))


def restore(crowd, snap: Snapshot) -> None:
    """Set ``crowd`` to ``snap``'s frame and state (``Crowd.restore``): checked first
    (:func:`check`), and rolled back when a value the checks cannot see is wrong."""
    check(crowd, snap)
    # a value the checks cannot see: roll back (the streams are set last, whole or not
    # at all, so they need no copy)
    before = copy_state({k: v for k, v in crowd_state(crowd).items() if k != "streams"})
    with crowd.scrub.inside():
        try:
            set_state(crowd, snap.state())
        except Exception as e:  # noqa: BLE001 - any fault of the snapshot's values
            _set_parts(crowd, before)
            crowd.skinning.restored()
            raise CrowdError(f"snapshot of frame {snap.frame} cannot be restored: "
                             f"{type(e).__name__}: {e}; the crowd is as it was") from e
