"""The sample stadium's bowl as a seat generator spec (numpy only, no bpy).

A two-tier bowl round a 105 x 68 m pitch, built with the extension's own seat
generator (:mod:`crowd_addon.core.authoring.seats`, the *Generate Seats* operator): four
straight stands joined by rounded corners; a lower tier of 32 rows (tread 0.8 m,
riser 0.4 m, behind a 1.2 m front wall) and an upper tier of 36 steeper rows that
hangs 3.2 m over the lower tier's back rows, its first row 4 m above the lower
tier's last; aisles every 24 seats; the players' tunnel in the middle of the north
stand and a tunnel in each corner; the away fans in the stand behind the east goal.
At the paper's 65,000 seats the bowl has all its rows; fewer seats fill the lower
tier first (every tier keeps a row) and leave the rest unbuilt.

Units are metres, Z up, the pitch centre at the origin. Seats are agent points
where a fan's root bone (the floor between its feet) goes, each facing the pitch
centre: ``heading`` turns the character's rest forward -Y towards it,
``forward = (sin h, -cos h, 0)``.
"""

from __future__ import annotations

from dataclasses import replace

from crowd_addon.core.authoring.seat_spec import HOME, AWAY, SeatSpec, Tier, Tunnel
from crowd_addon.core.authoring.seats import generate_seats

__all__ = ["SPEC", "HOME", "AWAY", "PAPER_SEATS", "layout_seats"]

PAPER_SEATS = 65000
#: the corners' tunnels point at the corners' middles (33 degrees off the long axis)
SPEC = SeatSpec(
    tiers=(Tier(rows=32, tread=0.8, riser=0.4, lift=1.2),
           Tier(rows=36, tread=0.8, riser=0.45, setback=-3.2, lift=4.0)),
    plan="rect", pitch=(105.0, 68.0), margin=(6.5, 6.0), corner_radius=14.0,
    seat_pitch=0.5, seat_width=0.45, aisle_every=24, aisle_width=1.2,
    tunnels=(Tunnel(90.0, width=6.0, rows=8),) + tuple(Tunnel(a, width=4.0, rows=6)
                                                       for a in (33.0, 147.0, 213.0, 327.0)),
    away_end="east")


def layout_seats(count: int):
    """The bowl sized for exactly ``count`` seats: a
    :class:`crowd_addon.core.authoring.seats.SeatLayout` (a CrowdError names a bad count)."""
    return generate_seats(replace(SPEC, seats=count))
