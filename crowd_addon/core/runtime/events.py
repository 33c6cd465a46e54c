"""Event tags delivered as callbacks into the simulation (paper s.3.3, requirement 3).

:func:`deliver` finds who receives the tags crossed this frame: a stream head's
crossing at frame ``f`` reaches the agents at offset ``frame - f`` (for the next M
frames), a unique's crossing reaches the agents playing it, an agent blending in a
transition slot receives its target's tags. :class:`EventDispatcher` calls back.

``on(name, fn)`` registers ``fn(name, frame, agent_ids)``; ``"*"`` receives every
event. The crowd calls each callback once per (event, frame) with all agent ids
that crossed the tag in that frame (int64 array, ascending). A callback that
raises is logged and recorded in :attr:`EventDispatcher.errors`; the crowd goes on.
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError

__all__ = ["EventDispatcher", "CallbackError", "deliver"]

log = logging.getLogger("crowd_addon.events")

#: Callback errors kept with their tracebacks (the newest); older ones are counted.
KEPT_ERRORS = 20
#: Errors of one callback that are logged; later ones are only counted.
LOGGED_ERRORS = 5


@dataclass(frozen=True)
class CallbackError:
    event: str
    frame: int
    callback: object
    error: BaseException


class EventDispatcher:
    """Callbacks by event name; ``label`` names the owner in logged errors.

    A callback that raises is counted per callback (:attr:`error_counts`); the last
    :data:`KEPT_ERRORS` errors are kept with their tracebacks (:attr:`errors`), older
    ones are dropped and counted (:attr:`errors_dropped`), and each callback's first
    :data:`LOGGED_ERRORS` errors are logged, so one that always raises costs neither
    memory nor a flooded log.
    """

    def __init__(self, label: str = "crowd"):
        self.label = label
        self._handlers = {}
        self._next = 0
        self.errors = deque(maxlen=KEPT_ERRORS)
        self.errors_dropped = 0
        self.error_counts = Counter()   # callback -> errors it raised
        self.fired = Counter()          # event name -> agent-crossings delivered
        self.calls = Counter()          # event name -> frames it fired on

    def state(self) -> dict:
        """What a :mod:`.snapshot` keeps: the counts (callbacks are not state)."""
        return {"fired": dict(self.fired), "calls": dict(self.calls)}

    def set_state(self, state: dict):
        counts = [Counter({str(k): int(v) for k, v in state[key].items()})
                  for key in ("fired", "calls")]
        if any(v < 0 for c in counts for v in c.values()):
            raise ValueError("an event count is negative")
        self.fired, self.calls = counts

    def on(self, name: str, fn) -> int:
        """Register ``fn(name, frame, agent_ids)`` for ``name`` (or ``"*"``); returns a
        handle. A name that is not a non-empty string, or an ``fn`` that cannot be
        called, is a CrowdError (nothing registered)."""
        if not isinstance(name, str) or not name:
            raise CrowdError(f"{self.label}: on_event: the event name must be a tag name "
                             f"(a non-empty string) or '*' for every event, got {name!r}")
        if not callable(fn):
            raise CrowdError(f"{self.label}: on_event: the callback for {name!r} is not "
                             f"callable: {fn!r}")
        self._next += 1
        self._handlers[self._next] = (name, fn)
        return self._next

    def off(self, handle: int) -> None:
        self._handlers.pop(handle, None)

    def clear(self) -> None:
        self._handlers.clear()

    def dispatch(self, frame: int, name: str, agents: np.ndarray) -> None:
        self.fired[name] += int(agents.size)
        self.calls[name] += 1
        for handle, (want, fn) in list(self._handlers.items()):
            if want != name and want != "*":
                continue
            try:
                fn(name, frame, agents)
            except Exception as exc:  # noqa: BLE001 - reported, never fatal
                self._failed(CallbackError(name, frame, fn, exc))

    def _failed(self, err: CallbackError):
        if len(self.errors) == self.errors.maxlen:
            self.errors_dropped += 1
        self.errors.append(err)
        self.error_counts[err.callback] += 1
        count = self.error_counts[err.callback]
        if count <= LOGGED_ERRORS:
            more = ("; its further errors are counted, not logged"
                    if count == LOGGED_ERRORS else "")
            log.error("%s: event callback %r for %r at frame %d raised %s: %s%s",
                      self.label, getattr(err.callback, "__name__", err.callback),
                      err.event, err.frame, type(err.error).__name__, err.error, more)


def deliver(frame, roots, names, streams, uniques, index, dispatcher, tag_names) -> int:
    """Log this frame's crossings and call back for every (tag, frame).

    ``roots`` (k,) int64 animation roots (streams ``0 .. S-1``, then uniques) whose
    clips crossed tags ``names`` (k,) (indices into ``tag_names``) at ``frame``;
    ``streams``/``uniques`` the pools (stream crossings are logged for M frames),
    ``index`` the agents' :class:`~.agents.AgentIndex`; ``dispatcher`` None only logs
    (the history warm-up). Returns the count of (tag, frame) deliveries.
    """
    is_stream = roots < streams.count
    streams.log_events(frame, roots[is_stream], names[is_stream])
    if dispatcher is None:
        return 0
    stream_keys, stream_names = streams.crossings_reaching(frame)
    keys = np.concatenate([stream_keys, uniques.key(roots[~is_stream] - streams.count)])
    key_names = np.concatenate([stream_names, names[~is_stream]])
    if keys.size == 0:
        return 0
    ids, which = index.lookup(keys)
    if ids.size == 0:
        return 0
    ev_names = key_names[which]
    fired = 0
    for n in np.unique(ev_names):
        dispatcher.dispatch(frame, tag_names[n], np.unique(ids[ev_names == n]))
        fired += 1
    return fired
