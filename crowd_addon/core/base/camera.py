"""Cameras for crowd rendering: look-at view, perspective projection, framing.

Matrices are float64 ``(4, 4)`` acting on column vectors (``clip = P @ V @ p``),
OpenGL clip space (z in -w..w), world Z up (Blender's axes, docs/architecture.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import CrowdError

__all__ = ["Camera", "look_at", "perspective", "frame_crowd", "frame_points",
           "frame_positions"]


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World -> camera matrix; the camera looks down its -Z at ``target``."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    f = target - eye
    if np.linalg.norm(f) < 1e-12:
        raise CrowdError("camera: eye and target are the same point")
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:                 # looking along up: any side will do
        s = np.cross(f, (0.0, 1.0, 0.0) if abs(f[1]) < 0.9 else (1.0, 0.0, 0.0))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y, aspect, near, far) -> np.ndarray:
    """OpenGL perspective projection; ``fov_y`` in radians."""
    if not (0 < fov_y < np.pi and aspect > 0 and 0 < near < far):
        raise CrowdError(f"camera: bad perspective fov_y={fov_y}, aspect={aspect}, "
                         f"near={near}, far={far}")
    t = 1.0 / np.tan(fov_y / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = t / aspect, t
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


@dataclass(frozen=True)
class Camera:
    """A perspective camera. ``fov_y`` in radians, distances in metres; compares equal
    to another with the same values (points are stored as float tuples)."""

    eye: tuple
    target: tuple
    fov_y: float = np.radians(40.0)
    aspect: float = 16 / 9
    near: float = 0.1
    far: float = 1000.0
    up: tuple = (0.0, 0.0, 1.0)

    def __post_init__(self):
        for name in ("eye", "target", "up"):
            v = np.asarray(getattr(self, name), np.float64).reshape(-1)
            if v.shape != (3,) or not np.isfinite(v).all():
                raise CrowdError(f"camera: {name} must be 3 finite numbers, got "
                                 f"{getattr(self, name)!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        for name in ("fov_y", "aspect", "near", "far"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def view(self) -> np.ndarray:
        return look_at(self.eye, self.target, self.up)

    @property
    def projection(self) -> np.ndarray:
        return perspective(self.fov_y, self.aspect, self.near, self.far)

    @property
    def view_projection(self) -> np.ndarray:
        return self.projection @ self.view


def frame_points(lo, hi, aspect=16 / 9, fov_y=np.radians(40.0), azimuth=np.radians(-60.0),
                 elevation=np.radians(30.0), margin=1.05) -> Camera:
    """A camera that sees the whole box ``lo .. hi`` (metres), looking at its centre
    from ``azimuth`` (about +Z, from +X) and ``elevation`` above the horizon."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 0.1) * margin
    half = min(fov_y, 2 * np.arctan(np.tan(fov_y / 2) * aspect)) / 2
    dist = radius / np.sin(half)
    d = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                  np.sin(elevation)])
    eye = centre + dist * d
    return Camera(eye, centre, fov_y, aspect, max(dist - radius, dist * 1e-3), dist + radius)


def frame_crowd(crowd, **kwargs) -> Camera:
    """:func:`frame_points` around every agent's bind-pose proxy (or a 2 m box per agent
    when the crowd has no proxies); read through ``crowd.view``."""
    view = crowd.view
    pos = np.asarray(view.agents.position, np.float64)
    meshes = [body.levels[0] for body in view.bodies if body.levels]
    if meshes:
        ext = np.concatenate([m.extent for m in meshes]).astype(np.float64) * float(
            view.agents.scale.max(initial=1.0))
        reach = np.abs(ext).max(0)
        reach[:2] = np.linalg.norm(np.abs(ext[:, :2]).max(0))   # any heading about +Z
    else:
        reach = np.array([1.0, 1.0, 2.0])
    lo = pos.min(0) - np.r_[reach[:2], 0.0]
    hi = pos.max(0) + reach
    return frame_points(lo, hi, **kwargs)


def frame_positions(positions, aspect=16 / 9) -> Camera:
    """:func:`frame_points` around agents standing at ``positions`` (n, 3) (a 2 m tall
    box each; none: the origin): the view a measurement uses without a camera."""
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    if not pos.size:
        pos = np.zeros((1, 3))
    return frame_points(pos.min(0) - 1.0, pos.max(0) + np.array([1.0, 1.0, 2.0]),
                        aspect=aspect)
