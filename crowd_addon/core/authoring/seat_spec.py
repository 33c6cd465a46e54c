"""The seat generator's spec: :class:`SeatSpec` with its :class:`Tier` s and
:class:`Tunnel` s (each field is described in :mod:`.seats`), the limits it is checked
against, and the teams' numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Tier", "Tunnel", "SeatSpec", "HOME", "AWAY", "PLANS", "ENDS", "MAX_SEATS"]

HOME, AWAY = 0, 1
PLANS = ("rect", "oval")
ENDS = ("east", "west", "none")
MAX_SEATS = 5_000_000
MAX_TIERS = 4


@dataclass(frozen=True)
class Tier:
    """One tier of the cross-section (metres; see :mod:`.seats`)."""

    rows: int = 20
    tread: float = 0.8
    riser: float = 0.4
    setback: float = 0.0
    lift: float = 1.2
    slab: float = 0.6


@dataclass(frozen=True)
class Tunnel:
    """A gap through the first tier's front rows: ``angle`` degrees round the pitch
    centre (0 = east, counter-clockwise), ``width`` metres on the front row, ``rows``
    rows deep."""

    angle: float
    width: float = 4.0
    rows: int = 6


@dataclass(frozen=True)
class SeatSpec:
    """What :func:`~.seats.generate_seats` builds (see :mod:`.seats` for each field)."""

    tiers: tuple = (Tier(),)
    plan: str = "rect"
    pitch: tuple = (105.0, 68.0)
    margin: tuple = (6.5, 6.0)
    corner_radius: float = 14.0
    seat_pitch: float = 0.5
    seat_width: float = 0.45
    seat_setback: float = 0.25
    bench: tuple = (0.45, 0.8, 0.45)
    aisle_every: int = 24
    aisle_width: float = 1.2
    tunnels: tuple = ()
    away_end: str = "east"
    seats: int | None = None
