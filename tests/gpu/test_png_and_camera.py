"""The PNG writer (decoded by ffmpeg, an independent decoder) and camera framing."""

import subprocess

import numpy as np
import pytest

from crowd_addon.core import CrowdError
from crowd_addon.core.base.camera import Camera, frame_crowd, look_at, perspective
from crowd_addon.gpu.png import write_png


@pytest.mark.parametrize("channels", [3, 4])
def test_png_decodes_to_the_same_pixels(tmp_path, channels):
    ffmpeg = pytest.importorskip("imageio_ffmpeg", reason="imageio-ffmpeg not installed")
    rng = np.random.default_rng(channels)
    image = rng.integers(0, 256, (13, 21, channels), dtype=np.uint8)
    path = write_png(tmp_path / "x.png", image)
    fmt = "rgba" if channels == 4 else "rgb24"
    raw = subprocess.run([ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-f",
                          "rawvideo", "-pix_fmt", fmt, "-"], capture_output=True, check=True)
    np.testing.assert_array_equal(np.frombuffer(raw.stdout, np.uint8).reshape(image.shape),
                                  image)


def test_png_rejects_bad_images_and_paths(tmp_path):
    with pytest.raises(CrowdError, match="uint8"):
        write_png(tmp_path / "a.png", np.zeros((4, 4, 3), np.float32))
    with pytest.raises(CrowdError, match="cannot write"):
        write_png(tmp_path / "missing" / "a.png", np.zeros((4, 4, 3), np.uint8))
    assert list(tmp_path.iterdir()) == []


def project(m, points):
    p = np.c_[points, np.ones(len(points))] @ m.T
    return p[:, :3] / p[:, 3:]


def test_look_at_and_perspective_map_the_view_volume():
    cam = Camera((3.0, -4.0, 2.0), (0.0, 1.0, 1.0), fov_y=0.8, aspect=1.5, near=0.5, far=50.0)
    np.testing.assert_allclose(project(cam.view_projection, [cam.target])[0, :2], 0, atol=1e-12)
    view = look_at(cam.eye, cam.target)
    fwd = np.subtract(cam.target, cam.eye) / np.linalg.norm(np.subtract(cam.target, cam.eye))
    ndc = project(perspective(0.8, 1.5, 0.5, 50.0),
                  [(view[:3, :3] @ (np.array(cam.eye) + d * fwd - cam.eye)) for d in (0.5, 50.0)])
    np.testing.assert_allclose(ndc[:, 2], [-1, 1], atol=1e-9)


def test_frame_crowd_keeps_every_agent_in_view(h):
    crowd = h.Crowd(h.make_config(agents=30, spacing=3.0))
    cam = frame_crowd(crowd, aspect=2.0)
    ext = crowd.config.meshes["fan"][0].extent
    corners = np.array(np.meshgrid(*ext.T)).reshape(3, -1).T
    pts = (crowd.agents.position[:, None] + corners[None]).reshape(-1, 3)
    ndc = project(cam.view_projection, pts)
    assert (np.abs(ndc) <= 1).all()
    assert np.abs(ndc[:, :2]).max() > 0.5            # and it is framed, not tiny


def test_png_files_get_the_usual_permissions(tmp_path):
    """Regression: PNGs were left with mkstemp's 0600, unlike every other output."""
    import os

    from crowd_addon.gpu.png import write_png
    mask = os.umask(0o022)
    try:
        p = write_png(tmp_path / "a.png", np.zeros((2, 3, 4), np.uint8))
        assert os.stat(p).st_mode & 0o777 == 0o644
        os.chmod(p, 0o664)                       # an existing file keeps its mode
        write_png(p, np.ones((2, 3, 4), np.uint8))
        assert os.stat(p).st_mode & 0o777 == 0o664
    finally:
        os.umask(mask)
