"""Crowd renderers: instanced skinning from the pose texture.

One shader source (``gpu_shaders/``, declared in :mod:`.programs`, assembled by
:mod:`.assembler`), one frame sequence, two backends. A renderer reads a crowd only
through its ``FrameView`` (``crowd.view``). :mod:`.frame_plan` works out, without
any GPU API, what each frame needs -- textures, upload regions, the agent rows that
changed (:mod:`.instances`), draw lists and LODs (:mod:`.draw_lists`), proxy meshes
(:mod:`.proxies`), the skinning batch (:mod:`.skeleton_data`), uniforms, statistics;
:class:`.renderer.CrowdRenderer` runs it over a backend's primitives
(:mod:`.moderngl_backend`, :mod:`.blender_backend`); :func:`.backends.make_renderer`
picks the backend. :mod:`.camera` frames a crowd and :mod:`.png` writes images.
Importing this package imports neither moderngl nor bpy.
"""

from ..core.base.camera import Camera, frame_crowd, frame_points, look_at, perspective
from .png import encode_png, write_png

__all__ = ["Camera", "frame_crowd", "frame_points", "look_at", "perspective", "encode_png",
           "write_png"]
