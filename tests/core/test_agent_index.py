"""AgentIndex (who plays a key, for event delivery) against a brute-force search,
through rebuilds and the overlay of agents changed since the last rebuild, with
repeated query keys."""

import numpy as np
import pytest

from crowd_addon.core.runtime.agents import AgentIndex


def brute(keys_of_agents, queries):
    pairs = [(int(a), int(i)) for i, q in enumerate(queries)
             for a in np.flatnonzero(keys_of_agents == q)]
    return sorted(pairs)


@pytest.mark.parametrize("seed", range(4))
def test_lookup_matches_brute_force_through_changes(seed):
    rng = np.random.default_rng(seed)
    n = 3000
    keys = rng.integers(0, 200, n)
    index = AgentIndex(keys)
    for step in range(60):
        who = rng.choice(n, rng.integers(1, 80), replace=False)
        keys[who] = rng.integers(0, 220, who.size)
        index.set(who, keys[who])
        queries = rng.integers(0, 230, rng.integers(0, 40))
        queries = np.concatenate([queries, queries[:5]])       # repeated keys
        ids, which = index.lookup(queries)
        assert sorted(zip(ids.tolist(), which.tolist())) == brute(keys, queries), step
    assert index.overlay.size < n            # rebuilt on the way, not grown without end
