"""Crowd renderers (DESIGN.md s.2): instanced skinning from the pose texture.

One shader source (``gpu_shaders/``), two backends: :mod:`.moderngl_backend`
(headless EGL, or attached to a current GL context) and Blender's ``gpu`` module,
both fed by :mod:`.assembler` from the declarations in :mod:`.programs`. The data
the backends upload is prepared here without any GL: :mod:`.instances` (per-agent
texture), :mod:`.draw_lists` (culling and LOD per agent, one draw per skeleton and
LOD), :mod:`.proxies` (proxy meshes as vertex arrays), :mod:`.skeleton_data`
(transition shader inputs); :mod:`.camera` frames a crowd and :mod:`.png` writes
images. Importing this package imports neither moderngl nor bpy.
"""

from .camera import Camera, frame_crowd, frame_points, look_at, perspective
from .png import encode_png, write_png

__all__ = ["Camera", "frame_crowd", "frame_points", "look_at", "perspective", "encode_png",
           "write_png"]
