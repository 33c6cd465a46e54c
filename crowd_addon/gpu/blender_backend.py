"""The Blender ``gpu`` module backend: :class:`~.renderer.CrowdRenderer`'s primitives
in Blender's GPU API.

It runs wherever Blender draws (OpenGL, Metal, Vulkan): from a ``SpaceView3D`` draw
handler, into the framebuffer bound there, or into its own offscreen image (headless
after ``crowd_addon.blender.headless_gpu.init_headless_gpu``). Programs come from
:func:`.assembler.blender_create_info` through :func:`.blender_gpu.program`.

What Blender's Python API lacks is worked around on the GPU:

* no sub-image texture writes: rows of the pose (or local-pose) and agent textures
  are staged in a small texture made for the write, their row numbers in another
  (R32I), and :data:`~.programs.ROW_UPLOAD` scatters the rows with ``imageStore``
  (4 bytes of row number per row on top of the rows); textures are made from float
  data only, so integer data (draw lists, row numbers) goes through an R32F -> R32I
  copy (:data:`.blender_gpu.UPLOAD_INTS`); the skinning batch goes up as a new
  texture of its whole texel rows;
* no transform feedback: :meth:`BlenderGPURenderer._capture` computes the crowd's
  vertices like its vertex stage and draws each as a point on its own pixel of an
  RGBA32F target (:data:`.blender_gpu.CROWD_CAPTURE`).

Blender frees GPU objects with their Python wrappers; ``release`` drops them. Import
needs only numpy; ``gpu`` is imported when a renderer is made.
"""

from __future__ import annotations

from contextlib import contextmanager, nullcontext

import numpy as np

from ..core.base.errors import CrowdError
from ..core.runtime.pose_storage import TextureRegion
from .blender_gpu import (CROWD_CAPTURE, UPLOAD_INTS, float_texture, program, read_buffer,
                          set_if_used, use_program)
from .frame_plan import DRAW_SAMPLERS, SKIN_SAMPLERS, TextureSpec
from .programs import (CROWD_DRAW, LOOK_TURNS, ROW_UPLOAD, SCENE_DRAW, SKIN_ROWS, UPLOAD_GROUP,
                       for_influences)
from .renderer import CrowdRenderer
from .texture_region import stage_rows

__all__ = ["BlenderGPURenderer"]

_EXACT_INT = 2 ** 24                     # integers up to this are exact in float32


def _vertex_buffer(gpu, buffers):
    """The proxy's attributes (``ProxyBuffers.format``: influences 5..8 too when the
    mesh has them) in a ``GPUVertBuf``."""
    fmt = gpu.types.GPUVertFormat()
    for name, kind, _ in buffers.format:
        if kind == "4u2":
            fmt.attr_add(id=name, comp_type="U16", len=4, fetch_mode="INT")
        elif kind == "4f1":
            fmt.attr_add(id=name, comp_type="U8", len=4, fetch_mode="INT_TO_FLOAT_UNIT")
        elif kind == "u4":
            fmt.attr_add(id=name, comp_type="U32", len=1, fetch_mode="INT")
        else:
            fmt.attr_add(id=name, comp_type="F32", len=int(kind[0]), fetch_mode="FLOAT")
    vbo = gpu.types.GPUVertBuf(fmt, buffers.vertex_count)
    for name, values in buffers.attributes.items():
        vbo.attr_fill(name, values)
    return vbo


class _Mesh:
    """One (skeleton, LOD) proxy: ``copies`` back-to-back copies of its triangles for
    drawing (several agents an instance), one copy's vertices as points for capture."""

    def __init__(self, gpu, buffers, copies):
        self.buffers, self.copies = buffers, copies
        batched = buffers.batched(copies)
        ibo = gpu.types.GPUIndexBuf(type="TRIS", seq=batched.indices.reshape(-1, 3))
        self.triangles = gpu.types.GPUBatch(type="TRIS", buf=_vertex_buffer(gpu, batched),
                                            elem=ibo)
        self.points = gpu.types.GPUBatch(type="POINTS", buf=_vertex_buffer(gpu, buffers))


class _ShadowMap:
    """The shadow map's depth-only framebuffer, its depth texture and side."""

    def __init__(self, framebuffer, texture, size):
        self.framebuffer, self.texture, self.size = framebuffer, texture, size


class BlenderGPURenderer(CrowdRenderer):
    """Draws one crowd with Blender's ``gpu`` module.

    Parameters
    ----------
    view : the crowd's ``FrameView`` (see :class:`~.renderer.CrowdRenderer`).
    size : (width, height) of an offscreen image to render into, or None to draw
        only into the framebuffer bound at ``render`` time (a draw handler's).
    light, culling, shadows : see :class:`~.renderer.CrowdRenderer`.
    """

    def __init__(self, view, size=None, light=(0.4, -0.6, 0.8, 0.35), culling=True,
                 shadows=False, lod=True):
        import gpu
        self.gpu = gpu
        try:
            gpu.types.GPUTexture((1, 1), format="RGBA8")
        except Exception as e:       # noqa: BLE001 - Blender raises plain errors here
            raise CrowdError(f"Blender gpu backend: the GPU cannot draw ({e}); in background "
                             "mode call crowd_addon.blender.headless_gpu.init_headless_gpu() "
                             "first") from None
        self.limit = gpu.capabilities.max_texture_size_get()
        self.size = None if size is None else (int(size[0]), int(size[1]))
        self.framebuffer = None
        if self.size is not None:
            self.color_tex = gpu.types.GPUTexture(self.size, format="RGBA8")
            self.depth_tex = gpu.types.GPUTexture(self.size, format="DEPTH_COMPONENT32F")
            self.framebuffer = gpu.types.GPUFrameBuffer(depth_slot=self.depth_tex,
                                                        color_slots=(self.color_tex,))
        super().__init__(view, self.limit, light, culling, max_int=_EXACT_INT,
                         shadows=shadows, lod=lod)

    # ---------------------------------------------------------------- primitives
    def _create_texture(self, spec):
        if spec.image is not None and spec.format == "RGBA32F":
            return float_texture(self.gpu, spec.image)
        tex = self.gpu.types.GPUTexture(spec.size, format=spec.format)
        if spec.image is not None:
            self._write_ints(tex, TextureRegion(0, 0, *spec.size, spec.image))
        return tex

    def _write_rows(self, texture, block_rows, regions) -> int:
        staged, rows = stage_rows(regions)
        sent = 0
        shader = program(self.gpu, ROW_UPLOAD)
        for at in range(0, rows.size, self.limit):
            part = np.ascontiguousarray(staged[at:at + self.limit], np.float32)
            numbers = np.ascontiguousarray(rows[at:at + self.limit], np.int32)
            staging = float_texture(self.gpu, part)
            index = self.gpu.types.GPUTexture((numbers.size, 1), format="R32I")
            sent += part.nbytes + self._write_ints(
                index, TextureRegion(0, 0, numbers.size, 1, numbers.reshape(1, -1, 1)))
            use_program(self.gpu, shader)
            shader.uniform_int("u_upload", (block_rows, part.shape[1], numbers.size, 0))
            shader.uniform_sampler("staging_tex", staging)
            shader.uniform_sampler("row_index_tex", index)
            shader.image("dest_img", texture)
            self.gpu.compute.dispatch(shader, -(-part.shape[1] // UPLOAD_GROUP), numbers.size,
                                      1)
        return sent

    def _write_ints(self, texture, region) -> int:
        """``region`` (int32 data below 2**24) into the R32I ``texture``."""
        staging = float_texture(self.gpu, region.data[..., :1], fmt="R32F")
        shader = program(self.gpu, UPLOAD_INTS)
        use_program(self.gpu, shader)
        shader.uniform_int("u_offset", (region.x, region.y))
        shader.uniform_sampler("source_tex", staging)
        shader.image("target_img", texture)
        self.gpu.compute.dispatch(shader, -(-region.width // UPLOAD_GROUP), region.height, 1)
        return region.width * region.height * 4

    def _create_mesh(self, buffers, copies):
        return _Mesh(self.gpu, buffers, copies)

    def _set_uniforms(self, shader, spec, uniforms):
        """Push constants of ``spec`` by their declared type; ones the compiler
        dropped are skipped."""
        types = {name: kind for kind, name in spec.push_constants}
        for name, value in uniforms.items():
            setter = shader.uniform_int if types[name].startswith(("INT", "IVEC")) \
                else shader.uniform_float
            set_if_used(setter, name, value)

    def _skin(self, work) -> int:
        shader = program(self.gpu, SKIN_ROWS, {"MAX_BONES": self.plan.layout.bones})
        textures = {**self.textures, "batch": float_texture(self.gpu, work.image)}
        use_program(self.gpu, shader)
        self._set_uniforms(shader, SKIN_ROWS, work.uniforms)
        for _, _, name in SKIN_ROWS.samplers:
            shader.uniform_sampler(name, textures[SKIN_SAMPLERS[name]])
        shader.image("pose_img", self.textures["pose"])
        self.gpu.compute.dispatch(shader, work.groups, 1, 1)
        return work.image.nbytes

    def _turn_looks(self, uniforms, groups):
        shader = program(self.gpu, LOOK_TURNS)
        use_program(self.gpu, shader)
        self._set_uniforms(shader, LOOK_TURNS, uniforms)
        for _, _, name in LOOK_TURNS.samplers:
            set_if_used(shader.uniform_sampler, name, self.textures[DRAW_SAMPLERS[name]])
        shader.image("look_turn_img", self.textures["look_turns"])
        self.gpu.compute.dispatch(shader, groups, 1, 1)

    def _owns_image(self) -> bool:
        return self.framebuffer is not None

    @contextmanager
    def _bind_target(self, target, clear):
        gpu = self.gpu
        target = self.framebuffer if target is None else target
        with nullcontext() if target is None else target.bind():
            state = gpu.state
            depth, mask, blend = state.depth_test_get(), state.depth_mask_get(), \
                state.blend_get()
            if self.framebuffer is not None and self.framebuffer.is_bound:
                state.viewport_set(0, 0, *self.size)
            if clear is not None:
                state.active_framebuffer_get().clear(color=tuple(clear), depth=1.0)
            state.depth_test_set("LESS_EQUAL")
            state.depth_mask_set(True)
            state.blend_set("NONE")
            state.face_culling_set("NONE")
            try:
                yield state.viewport_get()[3]          # LOD: the viewport's height
            finally:
                state.depth_test_set(depth)
                state.depth_mask_set(mask)
                state.blend_set(blend)

    def _bind(self, shader, spec, uniforms, list_texture=None):
        use_program(self.gpu, shader)
        self._set_uniforms(shader, spec, uniforms)
        for _, _, name in spec.samplers:         # ones the compiler dropped are skipped
            set_if_used(shader.uniform_sampler, name, list_texture
                        if name == "agent_list_tex" else self.textures[DRAW_SAMPLERS[name]])

    def _draw(self, mesh, draw):
        n = mesh.buffers.influences
        shader = program(self.gpu, for_influences(CROWD_DRAW, n),
                         {"INFLUENCES": n, **self._fragment_defines()})
        self._bind(shader, CROWD_DRAW, draw.uniforms, self.textures["lists"])
        mesh.triangles.draw_instanced(shader, instance_count=draw.instances)

    def _create_scene(self, geometry):
        fmt = self.gpu.types.GPUVertFormat()
        for name in ("pos", "nor", "col"):
            fmt.attr_add(id=name, comp_type="F32", len=3, fetch_mode="FLOAT")
        vbo = self.gpu.types.GPUVertBuf(fmt, geometry.positions.shape[0])
        for name, values in (("pos", geometry.positions), ("nor", geometry.normals),
                             ("col", geometry.colors)):
            vbo.attr_fill(name, values)
        return self.gpu.types.GPUBatch(type="TRIS", buf=vbo)

    def _draw_scene(self, scene, uniforms):
        shader = program(self.gpu, SCENE_DRAW, self._fragment_defines())
        self._bind(shader, SCENE_DRAW, uniforms)
        scene.draw(shader)

    def _create_shadow_map(self, size):
        tex = self.gpu.types.GPUTexture((size, size), format="DEPTH_COMPONENT32F")
        return _ShadowMap(self.gpu.types.GPUFrameBuffer(depth_slot=tex), tex, size)

    @contextmanager
    def _bind_shadow(self, shadow_map):
        state = self.gpu.state
        viewport = state.viewport_get()
        with shadow_map.framebuffer.bind():
            state.viewport_set(0, 0, shadow_map.size, shadow_map.size)
            shadow_map.framebuffer.clear(depth=1.0)
            try:
                yield
            finally:
                state.viewport_set(*viewport)

    def _matrix_texture(self, texels):
        return float_texture(self.gpu, texels)

    def _capture(self, mesh, capture) -> np.ndarray:
        gpu = self.gpu
        n = capture.agents.size
        size = (mesh.buffers.vertex_count, n)
        if max(size) > self.limit:
            raise CrowdError(f"skinned_positions: {n} agents x {size[0]} vertices exceed "
                             f"the max texture size {self.limit}; ask for fewer agents")
        ids = self._create_texture(TextureSpec("ids", (capture.ids.width, capture.ids.height),
                                               "R32I", capture.ids.data))
        target = gpu.types.GPUTexture(size, format="RGBA32F")
        framebuffer = gpu.types.GPUFrameBuffer(color_slots=(target,))
        influences = mesh.buffers.influences
        shader = program(gpu, for_influences(CROWD_CAPTURE, influences),
                         {"INFLUENCES": influences, "SHADOWS": 0, "ENCODE_SRGB": 0})
        with framebuffer.bind():
            framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.viewport_set(0, 0, *size)
            depth = gpu.state.depth_test_get()
            gpu.state.depth_test_set("NONE")
            gpu.state.program_point_size_set(False)
            gpu.state.point_size_set(1.0)
            self._bind(shader, CROWD_CAPTURE, {**capture.uniforms, "u_capture_size": size},
                       ids)
            mesh.points.draw_instanced(shader, instance_count=n)
            gpu.state.depth_test_set(depth)
            data = framebuffer.read_color(0, 0, size[0], size[1], 4, 0, "FLOAT")
        return read_buffer(data, np.float32).reshape(n, size[0], 4)[..., :3].copy()

    def _read_texture(self, texture) -> np.ndarray:
        return read_buffer(texture.read(), np.float32)

    def read_image(self) -> np.ndarray:
        if self.framebuffer is None:
            raise CrowdError("read_image: this renderer has no offscreen image (give a size)")
        w, h = self.size
        with self.framebuffer.bind():
            data = self.framebuffer.read_color(0, 0, w, h, 4, 0, "UBYTE")
        return read_buffer(data, np.uint8).reshape(h, w, 4)[::-1].copy()

    def finish(self):
        """Waits by reading a pixel back: needs an offscreen image (a renderer made
        without a size does nothing here)."""
        if self.framebuffer is not None:
            with self.framebuffer.bind():          # a read waits for the GPU
                self.framebuffer.read_color(0, 0, 1, 1, 4, 0, "UBYTE")

    @property
    def device(self) -> str:
        return self.gpu.platform.renderer_get()

    def _release(self):
        self.color_tex = self.depth_tex = self.framebuffer = None
        self._shadow_map, self._lit = None, ()

