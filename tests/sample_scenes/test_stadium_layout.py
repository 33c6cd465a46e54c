"""The sample stadium's bowl (sample_scenes/stadium_layout.py): the seat generator's
spec the builder uses, at the demo's and the paper's seat counts (numpy only). The
generator itself is tested in tests/core/test_seats.py."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from crowd_addon.core.base.errors import CrowdError

_PATH = Path(__file__).resolve().parents[2] / "sample_scenes" / "stadium_layout.py"


def _load():
    """The module by path, under the name build_stadium.py imports it by (one copy)."""
    if "stadium_layout" not in sys.modules:
        spec = importlib.util.spec_from_file_location("stadium_layout", _PATH)
        module = importlib.util.module_from_spec(spec)
        sys.modules["stadium_layout"] = module
        spec.loader.exec_module(module)
    return sys.modules["stadium_layout"]


layout = _load()


def test_the_paper_scale_is_the_whole_two_tier_bowl():
    """65,000 seats: both tiers with all their rows, the upper tier above and behind the
    lower one's front, the away end behind the east goal."""
    seats = layout.layout_seats(layout.PAPER_SEATS)
    assert len(seats) == 65000 and seats.rows == tuple(t.rows for t in layout.SPEC.tiers)
    assert seats.capacity - 65000 < 1000          # the bowl is built for that many
    lower, upper = seats.position[seats.tier == 0], seats.position[seats.tier == 1]
    assert upper[:, 2].min() > lower[:, 2].max() + 3.0
    away = seats.team == layout.AWAY
    assert np.all(seats.position[away, 0] > 0.5 * layout.SPEC.pitch[0])
    assert 0.05 < away.mean() < 0.2
    assert set(np.unique(seats.tier[away])) == {0, 1}


def test_the_demo_default_fills_the_lower_tier_first():
    seats = layout.layout_seats(2000)
    assert len(seats) == 2000 and seats.rows[1] == 1 and seats.rows[0] >= 2
    assert (seats.tier == 0).sum() > (seats.tier == 1).sum()
    assert {0, 1} <= set(np.unique(seats.team))


def test_the_players_tunnel_and_the_corner_tunnels_are_open():
    seats = layout.layout_seats(layout.PAPER_SEATS)
    front = (seats.tier == 0) & (seats.row < 6)
    angle = np.degrees(np.arctan2(seats.position[:, 1], seats.position[:, 0])) % 360
    for tunnel in layout.SPEC.tunnels:
        near = np.abs((angle - tunnel.angle + 180) % 360 - 180) < 0.5
        assert not np.any(front & near), tunnel.angle
        assert np.any(~front & near & (seats.tier == 0)), tunnel.angle   # rows behind


@pytest.mark.parametrize("count", [0, -5])
def test_bad_seat_count_is_named(count):
    with pytest.raises(CrowdError, match="seats"):
        layout.layout_seats(count)
