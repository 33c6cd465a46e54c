"""A scene's camera object as the headless renderer's camera.

:func:`find_camera` picks a camera object of a scene by name (or the scene camera);
:func:`camera_from_object` converts it to a :class:`crowd_addon.core.base.camera.Camera` for
images of a given aspect, as Blender frames that camera for a render of that aspect:
the lens and sensor (with its fit: *Auto* fits the sensor width to the larger side),
the object's world matrix without its scale (the camera looks down its local -Z, +Y
up) and its clip distances. Orthographic and panoramic cameras and lens shift have
no counterpart in that camera and are refused.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.base.errors import CrowdError
from ..core.base.camera import Camera

__all__ = ["find_camera", "camera_from_object", "scene_size", "metric_view"]


def find_camera(scene, name: str | None = None):
    """The camera object ``name`` of ``scene``, or the scene camera when ``name`` is
    None (None when the scene has none). A name that is no object of the scene, or an
    object that is not a camera, is a CrowdError naming it."""
    if name is None:
        return scene.camera
    obj = scene.objects.get(name)
    if obj is None:
        cameras = sorted(o.name for o in scene.objects if o.type == "CAMERA")
        raise CrowdError(f"camera {name!r}: scene {scene.name!r} has no object of that "
                         f"name (its cameras: {cameras})")
    if obj.type != "CAMERA":
        raise CrowdError(f"camera {name!r}: the object is a {obj.type.lower()}, not a "
                         "camera")
    return obj


def camera_from_object(obj, aspect: float) -> Camera:
    """The :class:`Camera` that sees what Blender's camera object ``obj`` sees in an
    image of width / height ``aspect`` (square pixels)."""
    what = f"camera {obj.name!r}"
    cam = obj.data
    if cam.type != "PERSP":
        kind = {"ORTHO": "an orthographic", "PANO": "a panoramic"}.get(cam.type, cam.type)
        raise CrowdError(f"{what}: {kind} camera; only perspective cameras can render "
                         "the crowd")
    if cam.shift_x or cam.shift_y:
        raise CrowdError(f"{what}: lens shift ({cam.shift_x:g}, {cam.shift_y:g}) is not "
                         "supported; set it to 0")
    if not 0 < cam.clip_start < cam.clip_end:
        raise CrowdError(f"{what}: clip start {cam.clip_start:g} must be below clip end "
                         f"{cam.clip_end:g}")
    if not aspect > 0:
        raise CrowdError(f"{what}: image aspect must be > 0, got {aspect}")
    fit = cam.sensor_fit
    if fit == "AUTO":
        fit, sensor = ("HORIZONTAL" if aspect >= 1 else "VERTICAL"), cam.sensor_width
    else:
        sensor = cam.sensor_width if fit == "HORIZONTAL" else cam.sensor_height
    half = sensor / (2.0 * cam.lens)                # tan of half the fitted angle
    fov_y = 2.0 * math.atan(half / aspect if fit == "HORIZONTAL" else half)
    m = np.array(obj.matrix_world, np.float64)
    axes = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)      # without the scale
    eye = m[:3, 3]
    try:
        camera = Camera(eye, eye - axes[:, 2], fov_y, aspect, cam.clip_start,
                        cam.clip_end, up=axes[:, 1])
        camera.projection                           # checks the angle and clip distances
        return camera
    except CrowdError as e:
        raise CrowdError(f"{what}: {str(e).removeprefix('camera: ')}") from None


def scene_size(scene, size=(None, None)) -> tuple:
    """``size`` with a None width or height taken from ``scene``'s render resolution
    (``resolution_x/y`` times ``resolution_percentage``)."""
    r = scene.render
    pct = r.resolution_percentage / 100.0
    return tuple(int(v) if v is not None else max(1, int(round(full * pct)))
                 for v, full in zip(size, (r.resolution_x, r.resolution_y)))


def metric_view(scene, settings):
    """The camera and settings the repetition metric of ``scene``'s crowd is measured
    with: its scene camera at its render size, as a render frames it. Without a scene
    camera, or with one the renderer cannot draw (orthographic, lens shift), the
    camera is None (the export frames the agents) and the size stays the settings'.
    ``settings`` None: None, None (not measured)."""
    import dataclasses
    if settings is None:
        return None, None
    obj = scene.camera
    if obj is None:
        return None, settings
    w, h = scene_size(scene)
    try:
        return camera_from_object(obj, w / h), dataclasses.replace(settings, width=w,
                                                                   height=h)
    except CrowdError:
        return None, settings
