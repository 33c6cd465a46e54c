"""The transition request queue (arrays) against a plain ordered-dict model of the
rule: first in first out, one request per agent, a new request goes to the back."""

from collections import OrderedDict

import numpy as np
import pytest

from crowd_addon.core.runtime.request_queue import RequestQueue


def test_fifo_replace_withdraw():
    q = RequestQueue(10)
    q.push(np.array([3, 1, 7]), 1, np.array([5, 6, 7]), np.array([0, 1, 2]), 4)
    assert list(q) == [3, 1, 7] and len(q) == 3
    q.withdraw(np.array([1, 9]))                       # 9 never waited
    q.push(np.array([1]), 2, np.array([8]), np.array([3]), 6)
    assert list(q) == [3, 7, 1] and len(q) == 3
    agents, kind, ref, off, length = q.pop(2)
    assert agents.tolist() == [3, 7] and ref.tolist() == [5, 7] and kind.tolist() == [1, 1]
    assert off.tolist() == [0, 2] and length.tolist() == [4, 4]
    assert q.items() == [(1, (2, 8, 3, 6))]
    q.clear()
    assert not q and list(q) == [] and q.pop(3)[0].size == 0


@pytest.mark.parametrize("seed", range(6))
def test_matches_ordered_dict_model(seed):
    """Random pushes, re-requests, withdrawals and pops, long enough to grow and
    compact the arrays many times."""
    rng = np.random.default_rng(seed)
    n = 50
    q, model = RequestQueue(n), OrderedDict()
    for _ in range(400):
        op = rng.integers(3)
        if op == 0:
            agents = np.unique(rng.integers(0, n, rng.integers(1, 12)))
            q.withdraw(agents)                         # the slots' rule: a new request
            for a in agents.tolist():                  # replaces a waiting one
                model.pop(a, None)
            ref = rng.integers(0, 9, agents.size)
            off = rng.integers(0, 5, agents.size)
            length = int(rng.integers(1, 30))
            q.push(agents, 1, ref, off, length)
            for a, r, o in zip(agents.tolist(), ref.tolist(), off.tolist()):
                model[a] = (1, r, o, length)
        elif op == 1:
            agents = np.unique(rng.integers(0, n, rng.integers(1, 8)))
            q.withdraw(agents)
            for a in agents.tolist():
                model.pop(a, None)
        else:
            k = int(rng.integers(0, 10))
            got = q.pop(k)
            want = [model.popitem(last=False) for _ in range(min(k, len(model)))]
            assert got[0].tolist() == [a for a, _ in want]
            assert got[2].tolist() == [r[1] for _, r in want]
            assert got[3].tolist() == [r[2] for _, r in want]
            assert got[4].tolist() == [r[3] for _, r in want]
        assert len(q) == len(model) and list(q) == list(model)
    assert q.items() == list(model.items())
