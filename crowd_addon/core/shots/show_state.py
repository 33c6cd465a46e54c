"""What a snapshot keeps of the show's runner: :class:`ShowState`, the part of
:class:`~.show_runner.ShowRunner` that turns its homes, holds, pending returns,
releases and reactions, the tracks' last values and the counts into arrays
(:meth:`ShowState.state`) and back (:meth:`ShowState.set_state`, checked).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ..runtime.agents import STREAM, UNIQUE

__all__ = ["ShowState", "STAT_KEYS"]

#: what ShowRunner.stats counts per cue
STAT_KEYS = ("agents", "skipped", "queued", "cut", "switched", "streams")


def _grouped(arrays) -> dict:
    """A list of int64 id arrays as ``{"ids": concatenated, "counts": sizes}``."""
    return {"ids": np.concatenate([np.zeros(0, np.int64), *arrays]).astype(np.int64),
            "counts": np.array([a.size for a in arrays], np.int64)}


def _ungrouped(d) -> list:
    """The arrays of :func:`_grouped`, back."""
    return np.split(d["ids"], np.cumsum(d["counts"])[:-1]) if d["counts"].size else []


class ShowState:
    """The runner's state as a :mod:`.snapshot` keeps it (a base of
    :class:`~.show_runner.ShowRunner`, whose attributes it reads and sets)."""

    def state(self) -> dict:
        """What a :mod:`.snapshot` keeps: homes, holds, the returns and reactions still
        due (in the order they will be issued), the tracks' last values and the counts."""
        returns = [(f, ids, d) for f, groups in self._returns.items() for ids, d in groups]
        reacted = [(r, ids) for r, groups in self._reacted.items() for ids in groups]
        releases = [(f, *entry) for f, groups in self._releases.items() for entry in groups]
        return {"home_kind": self.home_kind, "home_ref": self.home_ref,
                "home_offset": self.home_offset, "held_until": self.held_until,
                "returns": {"frame": np.array([f for f, _, _ in returns], np.int64),
                            "duration": np.array([d for _, _, d in returns], np.float64),
                            **_grouped([ids for _, ids, _ in returns])},
                "reacted": {"reaction": np.array([r for r, _ in reacted], np.int64),
                            **_grouped([ids for _, ids in reacted])},
                "releases": {"frame": np.array([e[0] for e in releases], np.int64),
                             "cue": np.array([e[1] for e in releases], np.int64),
                             "stream": np.array([e[2] for e in releases], np.int64),
                             **_grouped([e[3] for e in releases])},
                "track_last": list(self._track_last), "stats": self.stats,
                "reactions": self.reactions}

    def set_state(self, state: dict):
        for k in ("home_kind", "home_ref", "home_offset", "held_until"):
            getattr(self, k)[...] = state[k]
        self._returns, self._reacted = defaultdict(list), defaultdict(list)
        self._releases = defaultdict(list)
        rel = state["releases"]
        if not (rel["frame"].size == rel["cue"].size == rel["stream"].size
                == rel["counts"].size and int(rel["counts"].sum()) == rel["ids"].size
                and (rel["counts"] >= 0).all()
                and ((rel["ids"] >= 0) & (rel["ids"] < self._n)).all()
                and ((rel["stream"] >= 0) & (rel["stream"] < self.crowd.streams.count)).all()
                and all(0 <= k < len(self.show.cues) and self.show.cues[k].action.release
                        for k in rel["cue"].tolist())):
            raise ValueError("the show's pending releases name what does not exist")
        for f, k, st, ids in zip(rel["frame"].tolist(), rel["cue"].tolist(),
                                 rel["stream"].tolist(), _ungrouped(rel)):
            self._releases[f].append((k, st, ids))
        r = state["returns"]
        for f, d, ids in zip(r["frame"].tolist(), r["duration"].tolist(), _ungrouped(r)):
            self._returns[f].append((ids, d))
        r = state["reacted"]
        for k, ids in zip(r["reaction"].tolist(), _ungrouped(r)):
            self._reacted[k].append(ids)
        last = [None if v is None else float(v) for v in state["track_last"]]
        if len(last) != len(self.show.tracks):
            raise ValueError("the show's track values do not fit its tracks")
        self._track_last = last
        self.stats = {str(c): {**dict.fromkeys(STAT_KEYS, 0),
                               **{str(k): int(v) for k, v in d.items()}}
                      for c, d in state["stats"].items()}
        self.reactions = {str(k): int(v) for k, v in state["reactions"].items()}
        c = self.crowd
        ids = [r["ids"] for r in (state["returns"], state["reacted"])]
        if not (np.isin(self.home_kind, (STREAM, UNIQUE)).all()
                and all(((i >= 0) & (i < self._n)).all() for i in ids)
                and all(int(r["counts"].sum()) == r["ids"].size and (r["counts"] >= 0).all()
                        for r in (state["returns"], state["reacted"]))
                and state["returns"]["frame"].size == state["returns"]["duration"].size
                == state["returns"]["counts"].size
                and state["reacted"]["reaction"].size == state["reacted"]["counts"].size
                and ((state["reacted"]["reaction"] >= 0)
                     & (state["reacted"]["reaction"] < len(self.show.reactions))).all()
                and np.where(self.home_kind == STREAM,
                             (self.home_ref >= 0) & (self.home_ref < c.streams.count)
                             & (self.home_offset >= 0)
                             & (self.home_offset < c.streams.max_offset),
                             (self.home_ref >= 0) & (self.home_ref < c.uniques.count)).all()):
            raise ValueError("the show's homes, returns or reactions name what does not "
                             "exist")
        self._grid_cursor = 0               # the neighbour grids are rebuilt when needed
