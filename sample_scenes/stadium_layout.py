"""Stadium bowl and seat layout as plain arrays (numpy only, no bpy).

The bowl follows a rounded rectangle around the pitch (a football stadium's
plan): straight stands along the touchlines and behind the goals, joined by
quarter-circle corners, so every row is one closed loop and a Mexican wave can
travel all the way round. Row ``r`` is a step of the bowl: its tread (floor) is
at height ``front_wall + r * riser`` and starts ``r * tread`` metres behind the
bowl's inner edge. Units are metres, Z up, the pitch centre at the origin.

Seats are agent points: where a fan's root bone (the floor between its feet)
goes. Each seat faces the pitch centre. The fan character's rest forward is -Y
(Blender's front view), so ``heading`` is the rotation about +Z that turns -Y
towards the centre: ``forward = (sin h, -cos h, 0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowd_addon.core.errors import CrowdError

__all__ = ["Bowl", "SeatLayout", "layout_seats", "in_away_end", "bowl_ring", "stand_profile",
           "bench_profile", "sweep"]

HOME, AWAY = 0, 1


@dataclass(frozen=True)
class Bowl:
    """Dimensions of the bowl (metres).

    half_straight : half lengths (a, b) of the straight parts of the inner edge
        along X and Y; the inner edge is the rounded rectangle with corner radius
        ``corner_radius`` around the corner centres ``(+-a, +-b)``.
    """

    half_straight: tuple = (45.0, 26.0)
    corner_radius: float = 14.0
    pitch_half: tuple = (52.5, 34.0)
    front_wall: float = 1.2
    tread: float = 0.8
    riser: float = 0.4
    seat_pitch: float = 0.5
    seat_setback: float = 0.25
    bench_depth: tuple = (0.45, 0.8)
    bench_height: float = 0.45
    min_rows: int = 12

    def row_radius(self, rows):
        """Corner radius of the seat line of each row in ``rows`` (array-like of int)."""
        rows = np.asarray(rows, np.float64)
        return self.corner_radius + rows * self.tread + self.seat_setback

    def perimeter(self, radius):
        """Length of the rounded rectangle loop with corner radius ``radius``."""
        a, b = self.half_straight
        return 4.0 * a + 4.0 * b + 2.0 * np.pi * np.asarray(radius, np.float64)

    def floor_height(self, rows):
        """Tread height of each row (metres above the pitch)."""
        return self.front_wall + np.asarray(rows, np.float64) * self.riser


@dataclass(frozen=True)
class SeatLayout:
    """The seats: N agent points.

    position : (N, 3) float32, metres. heading : (N,) float32, radians about +Z.
    section : (N,) int32, 0 = home, 1 = away: the straight stand behind the
    east goal (x > a, |y| <= b), about 10-15 % of the seats.
    row : (N,) int32 row from the front. index : (N,) int32 seat number within
    its row, counter-clockwise. rows : rows used by seats.
    """

    position: np.ndarray
    heading: np.ndarray
    section: np.ndarray
    row: np.ndarray
    index: np.ndarray
    rows: int


def in_away_end(bowl: Bowl, xy):
    """Whether points (N, 2) lie in the away stand: behind the east goal, x > a, |y| <= b."""
    xy = np.asarray(xy)
    a, b = bowl.half_straight
    return (xy[:, 0] > a) & (np.abs(xy[:, 1]) <= b)


def _allocate(total, weights):
    """Split ``total`` into integer parts proportional to ``weights`` (largest remainder)."""
    share = total * weights / weights.sum()
    count = np.floor(share).astype(np.int64)
    order = np.argsort(-(share - count), kind="stable")
    count[order[:total - count.sum()]] += 1
    return count


def loop_points(bowl: Bowl, s, radius):
    """Points and outward normals at arc lengths ``s`` along the loop of corner ``radius``.

    s : (K,) arc lengths (wrapped into [0, perimeter)); radius : scalar or (K,).
    The loop starts at (a + radius, b) and runs counter-clockwise: corner arc,
    straight, corner arc, ... Returns (points (K, 2), normals (K, 2)) float64.
    """
    a, b = bowl.half_straight
    s = np.asarray(s, np.float64).reshape(-1)
    radius = np.broadcast_to(np.asarray(radius, np.float64), s.shape)
    arc = 0.5 * np.pi * radius
    seg_len = np.column_stack([arc, np.full_like(s, 2 * a), arc, np.full_like(s, 2 * b),
                               arc, np.full_like(s, 2 * a), arc, np.full_like(s, 2 * b)])
    ends = np.cumsum(seg_len, axis=1)
    s = np.mod(s, ends[:, -1])
    seg = np.minimum((s[:, None] >= ends).sum(1), 7)
    u = s - np.take_along_axis(ends - seg_len, seg[:, None], 1)[:, 0]
    corner = seg // 2
    centres = np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
    runs = np.array([[-1.0, 0.0], [0.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    on_arc = (seg % 2) == 0
    theta = corner * 0.5 * np.pi + np.where(on_arc, u / radius, 0.5 * np.pi)
    normal = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    slide = np.where(on_arc, 0.0, u)[..., None] * runs[corner]
    return centres[corner] + radius[..., None] * normal + slide, normal


def layout_seats(bowl: Bowl, count: int) -> SeatLayout:
    """Lay out ``count`` seats over as few rows as hold them at ``bowl.seat_pitch``.

    Seats are shared between the rows in proportion to their length and spaced
    evenly along each row, odd rows staggered by half a seat.
    """
    count = int(count)
    if count < 1:
        raise CrowdError(f"seats: need at least 1 seat, got {count}")
    rows, capacity = 0, 0
    while capacity < count:
        capacity += int(bowl.perimeter(bowl.row_radius(rows)) // bowl.seat_pitch)
        rows += 1
    row_ids = np.arange(rows)
    radius = bowl.row_radius(row_ids)
    length = bowl.perimeter(radius)
    per_row = _allocate(count, length)
    row = np.repeat(row_ids, per_row)
    index = np.arange(count) - np.repeat(np.cumsum(per_row) - per_row, per_row)
    spacing = (length / per_row)[row]
    s = (index + 0.5 + 0.5 * (row % 2)) * spacing
    xy, _ = loop_points(bowl, s, radius[row])
    z = bowl.floor_height(row)
    position = np.column_stack([xy, z]).astype(np.float32)
    heading = np.arctan2(-xy[:, 0], xy[:, 1]).astype(np.float32)
    section = np.where(in_away_end(bowl, xy), AWAY, HOME).astype(np.int32)
    return SeatLayout(position, heading, section, row.astype(np.int32),
                      index.astype(np.int32), rows)


def bowl_ring(bowl: Bowl, arc_segments=8):
    """The inner edge sampled for meshing: (K, 2) points and (K, 2) outward normals.

    Each corner contributes ``arc_segments + 1`` points; the straights are the
    edges between consecutive corners. Offsetting a point by ``d`` along its
    normal gives the loop at distance ``d`` behind the inner edge.
    """
    a, b = bowl.half_straight
    centres = np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
    t = np.linspace(0.0, 0.5 * np.pi, arc_segments + 1)
    theta = (np.arange(4)[:, None] * 0.5 * np.pi + t[None, :]).reshape(-1)
    normal = np.column_stack([np.cos(theta), np.sin(theta)])
    return np.repeat(centres, arc_segments + 1, axis=0) + bowl.corner_radius * normal, normal


def stand_profile(bowl: Bowl, rows: int):
    """Cross-section of the terraces as (P, 2) (distance behind inner edge, height).

    Front wall, then tread and riser per row, then a back wall down to the ground.
    """
    r = np.arange(rows)
    z = bowl.floor_height(r)
    front = r * bowl.tread
    steps = np.column_stack([front, z, front + bowl.tread, z]).reshape(-1, 2)
    depth = rows * bowl.tread
    top = bowl.floor_height(rows) + 0.6
    return np.vstack([[[0.0, 0.0]], steps, [[depth, top], [depth + 0.4, top],
                                            [depth + 0.4, 0.0]]])


def bench_profile(bowl: Bowl, row: int):
    """Closed (4, 2) cross-section of the bench along row ``row``."""
    d0, d1 = row * bowl.tread + np.asarray(bowl.bench_depth)
    z0 = float(bowl.floor_height(row))
    z1 = z0 + bowl.bench_height
    return np.array([[d0, z0], [d0, z1], [d1, z1], [d1, z0]])


def sweep(ring_xy, ring_normal, profile, closed_profile=False):
    """Sweep a (distance, height) profile along a closed ring.

    Returns (vertices (P*K, 3) float64, quads (F, 4) int64) with normals facing
    up / towards the pitch for a profile that runs outwards and upwards.
    """
    k = len(ring_xy)
    d, z = profile[:, 0], profile[:, 1]
    xy = ring_xy[None, :, :] + d[:, None, None] * ring_normal[None, :, :]
    verts = np.concatenate([xy, np.broadcast_to(z[:, None, None], xy.shape[:2] + (1,))],
                           axis=-1).reshape(-1, 3)
    p = len(profile)
    pi = np.arange(p if closed_profile else p - 1)
    ki = np.arange(k)
    p0, k0 = np.meshgrid(pi, ki, indexing="ij")
    p1, k1 = (p0 + 1) % p, (k0 + 1) % k
    quads = np.stack([p0 * k + k0, p1 * k + k0, p1 * k + k1, p0 * k + k1], axis=-1)
    return verts, quads.reshape(-1, 4)
