"""The transition request queue (paper s.4.3): requests that wait for a free slot,
first in first out, kept in per-agent arrays so thousands queue, leave and are served
in a few numpy calls (:mod:`.transitions` serves them).
"""

from __future__ import annotations

import numpy as np

__all__ = ["RequestQueue"]


class RequestQueue:
    """Waiting transition requests, first in first out, at most one per agent (a new
    request of a waiting agent replaces its old one and goes to the back).

    Kept in arrays so that queueing, withdrawing and serving thousands of agents is a
    few numpy calls: each agent's request lives in per-agent arrays with its ticket
    (the arrival number), and a growing list of (ticket, agent) in arrival order is
    read from its head; entries whose ticket is no longer the agent's are withdrawn
    requests and are skipped.
    """

    def __init__(self, agents: int):
        self._ticket = np.full(agents, -1, np.int64)      # -1: not waiting
        self._kind = np.zeros(agents, np.int8)
        self._ref = np.zeros(agents, np.int64)
        self._offset = np.zeros(agents, np.int64)
        self._length = np.zeros(agents, np.int64)
        self._line = np.zeros((2, 64), np.int64)          # (ticket, agent) by arrival
        self._head = self._tail = 0
        self._count = 0
        self._issued = 0                                  # tickets handed out so far

    def __len__(self) -> int:
        return self._count

    def __bool__(self) -> bool:
        return self._count > 0

    def __iter__(self):
        return iter(self.agents().tolist())

    def _live(self):
        """Positions (in the line) of the live entries, in arrival order."""
        tickets, agents = self._line[:, self._head:self._tail]
        return np.flatnonzero(self._ticket[agents] == tickets)

    def state(self) -> dict:
        """What a :mod:`.snapshot` keeps: the per-agent request arrays, the line from its
        head, the live count and the tickets issued."""
        return {"ticket": self._ticket, "kind": self._kind, "ref": self._ref,
                "offset": self._offset, "length": self._length,
                "line": self._line[:, self._head:self._tail], "count": self._count,
                "issued": self._issued}

    def set_state(self, state: dict):
        """Back to a :meth:`state` (the same requests, in the same order)."""
        for k in ("ticket", "kind", "ref", "offset", "length"):
            getattr(self, "_" + k)[...] = state[k]
        m = state["line"].shape[1]
        self._line = np.zeros((2, max(64, 2 * m)), np.int64)
        self._line[:, :m] = state["line"]
        self._head, self._tail = 0, m
        self._count, self._issued = int(state["count"]), int(state["issued"])

    def agents(self) -> np.ndarray:
        """(k,) int64 waiting agents, first in first."""
        return self._line[1, self._head:self._tail][self._live()].copy()

    def items(self) -> list:
        """``[(agent, (kind, ref, offset, length))]`` in queue order (for inspection)."""
        a = self.agents()
        return [(int(i), (int(k), int(r), int(o), int(n))) for i, k, r, o, n in zip(
            a, self._kind[a], self._ref[a], self._offset[a], self._length[a])]

    def clear(self):
        self._ticket[:] = -1
        self._head = self._tail = self._count = 0

    def withdraw(self, agents: np.ndarray):
        """Forget the waiting requests of ``agents`` (unique ids); others are ignored."""
        if self._count:
            waiting = agents[self._ticket[agents] >= 0]
            self._ticket[waiting] = -1
            self._count -= int(waiting.size)
            if self._count == 0:
                self._head = self._tail = 0

    def push(self, agents, kind, ref, offset, length):
        """Queue ``agents`` (unique ids, none of them waiting) in this order."""
        k = int(agents.size)
        if self._tail + k > self._line.shape[1]:     # full: keep the live entries only
            live = self._line[:, self._head:self._tail][:, self._live()]
            m = live.shape[1]
            line = np.zeros((2, max(64, 2 * (m + k))), np.int64)
            line[:, :m] = live
            self._line, self._head, self._tail = line, 0, m
        tickets = self._issued + np.arange(k, dtype=np.int64)
        self._issued += k
        self._line[0, self._tail:self._tail + k] = tickets
        self._line[1, self._tail:self._tail + k] = agents
        self._tail += k
        self._ticket[agents] = tickets
        self._kind[agents] = kind
        self._ref[agents] = ref
        self._offset[agents] = offset
        self._length[agents] = length
        self._count += k

    def check_refs(self, refs_ok, agents: int) -> None:
        """Raise ValueError unless every waiting request targets what exists
        (``refs_ok(kind, ref, offset)``) and names one of ``agents`` agents."""
        wait = np.flatnonzero(self._ticket >= 0)
        line = self._line[:, self._head:self._tail]
        if not (refs_ok(self._kind[wait], self._ref[wait], self._offset[wait])
                and (self._length[wait] >= 1).all() and wait.size == len(self)
                and ((line[1] >= 0) & (line[1] < agents)).all()):
            raise ValueError("the transition queue holds a request that cannot be")

    def pop(self, n: int) -> tuple:
        """The ``n`` oldest requests as arrays ``(agents, kind, ref, offset, length)``,
        removed from the queue."""
        live = self._live()[:n]
        agents = self._line[1, self._head + live]
        self._head = self._head + int(live[-1]) + 1 if live.size else self._head
        self._ticket[agents] = -1
        self._count -= int(agents.size)
        if self._count == 0:
            self._head = self._tail = 0
        return (agents, self._kind[agents].copy(), self._ref[agents].copy(),
                self._offset[agents].copy(), self._length[agents].copy())
