"""The Blender ``gpu`` module backend: the moderngl renderer's behaviour, any GPU API.

Same shader sources (``gpu_shaders/``, assembled by :func:`.assembler.blender_create_info`),
same data (:mod:`.instances`, :mod:`.draw_lists`, :mod:`.proxies`), same
:class:`~.moderngl_backend.FrameStats`. It runs wherever Blender draws (OpenGL,
Metal, Vulkan): from a ``SpaceView3D`` draw handler, into the framebuffer bound
there, or into its own offscreen image (headless after :func:`init_headless_gpu`).

What Blender's Python API lacks is worked around on the GPU:

* no sub-image texture writes: each frame the dirty rows of the pose (or local-pose)
  and agent textures are staged in a small texture made for the frame, their row
  numbers in another (R32I), and :data:`~.programs.ROW_UPLOAD` scatters
  the rows with ``imageStore`` (4 bytes of row number per row on top of the rows);
  textures are made from float data only, so integer data (draw lists, row
  numbers) goes through an R32F -> R32I copy (:data:`.blender_gpu.UPLOAD_INTS`);
* no transform feedback: :meth:`BlenderGPURenderer.skinned_positions` computes the
  crowd's vertices like its vertex stage and draws each as a point on its own pixel
  of an RGBA32F target (:data:`.blender_gpu.CROWD_CAPTURE`).

Blender frees GPU objects with their Python wrappers; :meth:`~BlenderGPURenderer.release`
drops them. Import needs only numpy; ``gpu`` is imported when a renderer is made
(:mod:`.blender_gpu` has the plumbing: headless start, programs, textures).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import CrowdError
from .blender_gpu import (CROWD_CAPTURE, UPLOAD_INTS, float_texture, init_headless_gpu,
                          program, read_buffer, set_if_used, use_program)
from .draw_lists import DrawLists, capture_mesh, proxy_bounds
from .instances import InstanceData
from .moderngl_backend import FrameStats
from .programs import (CROWD_DRAW, ROW_UPLOAD, SKIN_ROWS, SKIN_GROUP,
                       UPLOAD_GROUP)
from .proxies import agent_skeletons, copies_per_instance, crowd_proxies
from .skeleton_data import batch_image, fill_batch, skeleton_image
from .texture_region import TextureRegion, stage_rows

__all__ = ["BlenderGPURenderer", "init_headless_gpu"]   # the latter from .blender_gpu

_EXACT_INT = 2 ** 24                     # integers up to this are exact in float32


def _vertex_buffer(gpu, buffers):
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type="F32", len=3, fetch_mode="FLOAT")
    fmt.attr_add(id="nor", comp_type="F32", len=3, fetch_mode="FLOAT")
    fmt.attr_add(id="bone_idx", comp_type="U16", len=4, fetch_mode="INT")
    fmt.attr_add(id="bone_w", comp_type="F32", len=4, fetch_mode="FLOAT")
    vbo = gpu.types.GPUVertBuf(fmt, buffers.vertex_count)
    for name, values in buffers.attributes.items():
        vbo.attr_fill(name, values)
    return vbo


class _Mesh:
    """One (skeleton, LOD) proxy: ``copies`` back-to-back copies of its triangles for
    drawing (several agents an instance, like the moderngl backend), one copy's
    vertices as points for capture."""

    def __init__(self, gpu, buffers):
        self.buffers = buffers
        self.copies = copies_per_instance(buffers.vertex_count)
        batched = buffers.batched(self.copies)
        ibo = gpu.types.GPUIndexBuf(type="TRIS", seq=batched.indices.reshape(-1, 3))
        self.triangles = gpu.types.GPUBatch(type="TRIS", buf=_vertex_buffer(gpu, batched),
                                            elem=ibo)
        self.points = gpu.types.GPUBatch(type="POINTS", buf=_vertex_buffer(gpu, buffers))


class BlenderGPURenderer:
    """Draws one core ``Crowd`` with Blender's ``gpu`` module.

    Parameters
    ----------
    crowd : the ``Crowd``; call :meth:`sync` after each ``crowd.step()`` (this
        renderer consumes the crowd's upload regions).
    size : (width, height) of an offscreen image to render into, or None to draw
        only into the framebuffer bound at :meth:`render` time (a draw handler's).
    light : (x, y, z, ambient): direction towards the light and ambient level.
    culling : leave out agents outside the camera's view.
    """

    def __init__(self, crowd, size=None, light=(0.4, -0.6, 0.8, 0.35), culling=True):
        import gpu
        self.gpu = gpu
        self.crowd, self.culling = crowd, bool(culling)
        self.light = tuple(float(v) for v in light)
        self.stats = FrameStats()
        self.limit = gpu.capabilities.max_texture_size_get()
        st = crowd.storage
        if max(st.width, st.height) > self.limit:
            raise CrowdError(f"pose texture {st.width} x {st.height} texels exceeds this GPU's "
                             f"max texture size {self.limit}; set CrowdConfig.max_texture_size "
                             f"= {self.limit}")
        if crowd.N >= _EXACT_INT:
            raise CrowdError(f"Blender gpu backend: {crowd.N} agents, at most {_EXACT_INT - 1}")
        self.layout = (st.height, st.row_texels, crowd.M, crowd.S)
        # the whole texture the CPU keeps goes up now; with GPU skinning the pose
        # texture is filled by the compute shader at the end of __init__
        self.local_tex = None
        if crowd.gpu_skinning:
            self.local_tex = float_texture(gpu, st.texture_image())
            self.pose_tex = gpu.types.GPUTexture((st.width, st.height), format="RGBA32F")
        else:
            self.pose_tex = float_texture(gpu, st.texture_image())
        crowd.take_upload_regions()
        self.instances = InstanceData(crowd, self.limit)
        self.agent_tex = float_texture(gpu, self.instances.texture_image())
        self._agents_on_gpu = self.instances.records.copy()
        self.proxies = crowd_proxies(crowd)
        self.lists = DrawLists(agent_skeletons(crowd), [len(p) for p in self.proxies],
                               [proxy_bounds(p[0].extent) if p else (0.0, 0.0)
                                for p in self.proxies],
                               crowd.config.lod_distances, min(4096, self.limit))
        self.list_tex = gpu.types.GPUTexture((self.lists.width, self.lists.height),
                                             format="R32I")
        self._list_key = None
        self._upload_rows = program(gpu, ROW_UPLOAD)
        self._upload_ints = program(gpu, UPLOAD_INTS)
        self.meshes = {(k, lod): _Mesh(gpu, buf) for k, levels in enumerate(self.proxies)
                       for lod, buf in enumerate(levels)}
        self._build_skinning()
        self.size = None if size is None else (int(size[0]), int(size[1]))
        self.framebuffer = None
        if self.size is not None:
            self.color_tex = gpu.types.GPUTexture(self.size, format="RGBA8")
            self.depth_tex = gpu.types.GPUTexture(self.size, format="DEPTH_COMPONENT32F")
            self.framebuffer = gpu.types.GPUFrameBuffer(depth_slot=self.depth_tex,
                                                        color_slots=(self.color_tex,))

    # -------------------------------------------------------------------- setup
    def _build_skinning(self):
        self.skin_program = None
        if not self.crowd.gpu_skinning:
            return
        self.skeleton_tex = float_texture(self.gpu, skeleton_image(self.crowd.skeletons,
                                                                    self.crowd.B))
        self.batch_image = batch_image(self.crowd.storage.row_count)
        self.skin_program = program(self.gpu, SKIN_ROWS, {"MAX_BONES": self.crowd.B})
        self._run_skinning()

    # ------------------------------------------------------------------- upload
    def _write_rows(self, texture, block_rows, staged, rows) -> int:
        """Write ``staged`` rows ``(n, row_texels, 4)`` as logical ``rows`` ``(n,)`` of a
        block-laid RGBA32F ``texture`` ``block_rows`` high; returns the bytes sent (the
        rows and a 4-byte row number each)."""
        sent = 0
        shader = self._upload_rows
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

    def _write_instances(self) -> int:
        """The agent rows that changed since the last frame, exactly: the regions
        :meth:`InstanceData.update` returns may span unchanged rows (fewer, larger
        writes suit moderngl), so they are compared with what the GPU holds."""
        regions = self.instances.update(self.crowd)
        if not regions:
            return 0
        rows = np.concatenate([np.arange(*r.rows) for r in regions])
        records = self.instances.records[rows]
        changed = (records != self._agents_on_gpu[rows]).any((1, 2))
        rows, records = rows[changed], records[changed]
        self._agents_on_gpu[rows] = records
        return self._write_rows(self.agent_tex, self.instances.block_rows, records, rows)

    def _write_ints(self, texture, region) -> int:
        """Write ``region`` (int32 data below 2**24) into the R32I ``texture``."""
        staging = float_texture(self.gpu, region.data[..., :1], fmt="R32F")
        shader = self._upload_ints
        use_program(self.gpu, shader)
        shader.uniform_int("u_offset", (region.x, region.y))
        shader.uniform_sampler("source_tex", staging)
        shader.image("target_img", texture)
        self.gpu.compute.dispatch(shader, -(-region.width // UPLOAD_GROUP), region.height, 1)
        return region.width * region.height * 4

    def _set_pose_uniforms(self, shader):
        st = self.crowd.storage
        shader.uniform_int("u_pose_layout", self.layout)
        shader.uniform_int("u_pose_regions", (st.unique_base, st.slot_base,
                                              self.crowd.frame % self.crowd.M, 0))

    # -------------------------------------------------------------------- frame
    def sync(self) -> FrameStats:
        """Bring the GPU up to the crowd's current frame: dirty pose (or local-pose)
        rows, changed instance texels, with GPU skinning the skinning-rows shader."""
        crowd, s = self.crowd, FrameStats()
        target = self.local_tex if crowd.gpu_skinning else self.pose_tex
        written = self._write_rows(target, crowd.storage.height,
                                   *stage_rows(crowd.take_upload_regions()))
        if crowd.gpu_skinning:
            s.local_bytes = written
        else:
            s.pose_bytes = written
        s.instance_bytes = self._write_instances()
        if self.instances.moved:
            self._list_key = None
        if self.skin_program is not None:
            s.batch_bytes, s.skinned_rows = self._run_skinning()
        self.stats = s
        return s

    def _run_skinning(self):
        n, texel_rows = fill_batch(self.batch_image, self.crowd.gpu_skinning_batch())
        if n == 0:
            return 0, 0
        batch_tex = float_texture(self.gpu, self.batch_image[:texel_rows])
        shader = self.skin_program
        use_program(self.gpu, shader)
        shader.uniform_int("u_pose_layout", self.layout)
        shader.uniform_int("u_batch_count", n)
        shader.uniform_sampler("local_tex", self.local_tex)
        shader.uniform_sampler("skeleton_tex", self.skeleton_tex)
        shader.uniform_sampler("batch_tex", batch_tex)
        shader.image("pose_img", self.pose_tex)
        self.gpu.compute.dispatch(shader, -(-n // SKIN_GROUP), 1, 1)
        return self.batch_image[:texel_rows].nbytes, n

    def _regroup(self, camera, pixels_high):
        """Rebuild the draw lists when the camera, the viewport height or the agents
        moved."""
        vp = np.asarray(camera.view_projection, np.float64)
        key = (vp.tobytes(), int(pixels_high))
        if key == self._list_key:
            return
        for region in self.lists.rebuild(self.crowd.agent_position, vp, pixels_high,
                                         self.culling):
            self.stats.list_bytes += self._write_ints(self.list_tex, region)
        self._list_key = key

    def _bind_crowd(self, shader, view_projection, list_tex, draw):
        """Uniforms and textures of one draw; ``draw`` = (list base, agents, vertices a
        copy, copies an instance)."""
        use_program(self.gpu, shader)
        self._set_pose_uniforms(shader)
        set_if_used(shader.uniform_float, "u_view_proj",
                 np.asarray(view_projection, np.float32).T.ravel())
        shader.uniform_int("u_draw", tuple(int(v) for v in draw))
        shader.uniform_sampler("pose_tex", self.pose_tex)
        shader.uniform_sampler("agent_tex", self.agent_tex)
        shader.uniform_sampler("agent_list_tex", list_tex)

    def render(self, camera, target=None, clear=(0.62, 0.66, 0.72, 1.0)) -> FrameStats:
        """Draw the crowd as seen by ``camera`` (its ``view_projection`` (4, 4), OpenGL
        clip space) into ``target``: a ``GPUFrameBuffer`` or ``GPUOffScreen``; None =
        this renderer's offscreen image when it has one (read with :meth:`read_image`),
        else the framebuffer bound now. LODs follow the target's viewport height.
        ``clear``: RGBA to clear colour and depth to first, None to draw over what is
        there."""
        gpu = self.gpu
        if target is None:
            target = self.framebuffer
        s = self.stats
        s.draws = s.instances = s.vertices = 0
        if target is None:
            self._draw(camera, gpu.state.active_framebuffer_get(), clear)
        else:
            with target.bind():
                self._draw(camera, gpu.state.active_framebuffer_get(), clear)
        return s

    def _draw(self, camera, framebuffer, clear):
        gpu, s = self.gpu, self.stats
        depth, mask, blend = (gpu.state.depth_test_get(), gpu.state.depth_mask_get(),
                              gpu.state.blend_get())
        if self.framebuffer is not None and self.framebuffer.is_bound:
            gpu.state.viewport_set(0, 0, *self.size)
        self._regroup(camera, gpu.state.viewport_get()[3])   # LOD: the viewport's height
        view_projection = camera.view_projection
        if clear is not None:
            framebuffer.clear(color=tuple(clear), depth=1.0)
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(True)
        gpu.state.blend_set("NONE")
        gpu.state.face_culling_set("NONE")
        try:
            for g in self.lists.groups:
                mesh = self.meshes[g.skeleton, g.lod]
                shader = program(gpu, CROWD_DRAW, {"INFLUENCES": mesh.buffers.influences})
                self._bind_crowd(shader, view_projection, self.list_tex,
                                 (g.base, g.count, mesh.buffers.vertex_count, mesh.copies))
                shader.uniform_float("u_light", self.light)
                mesh.triangles.draw_instanced(shader,
                                              instance_count=-(-g.count // mesh.copies))
                s.draws += 1
                s.instances += g.count
                s.vertices += g.count * mesh.buffers.vertex_count
        finally:
            gpu.state.depth_test_set(depth)
            gpu.state.depth_mask_set(mask)
            gpu.state.blend_set(blend)

    # ---------------------------------------------------------------- read-back
    def read_image(self) -> np.ndarray:
        """The offscreen image ``(H, W, 4)`` uint8 RGBA, first row at the top."""
        if self.framebuffer is None:
            raise CrowdError("read_image: this renderer has no offscreen image (give a size)")
        w, h = self.size
        with self.framebuffer.bind():
            data = self.framebuffer.read_color(0, 0, w, h, 4, 0, "UBYTE")
        return read_buffer(data, np.uint8).reshape(h, w, 4)[::-1].copy()

    def read_pose_texture(self) -> np.ndarray:
        """The pose texture ``(height, width, 4)`` float32 as the GPU holds it."""
        st = self.crowd.storage
        return read_buffer(self.pose_tex.read(), np.float32).reshape(st.height, st.width, 4)

    def skinned_positions(self, agents, lod: int = 0) -> np.ndarray:
        """World positions ``(n, V, 3)`` float32 of ``agents`` (all of one skeleton)
        skinned by the crowd's vertex stage with LOD ``lod``, read back from an
        RGBA32F target with one pixel per (vertex, agent)."""
        gpu = self.gpu
        agents, mesh = capture_mesh(self.crowd, self.lists, self.meshes, agents, lod)
        size = (mesh.buffers.vertex_count, agents.size)
        if max(size) > self.limit:
            raise CrowdError(f"skinned_positions: {size[1]} agents x {size[0]} vertices exceed "
                             f"the max texture size {self.limit}; ask for fewer agents")
        ids = gpu.types.GPUTexture((agents.size, 1), format="R32I")
        self._write_ints(ids, TextureRegion(0, 0, agents.size, 1,
                                            agents.astype(np.int32).reshape(1, -1, 1)))
        target = gpu.types.GPUTexture(size, format="RGBA32F")
        framebuffer = gpu.types.GPUFrameBuffer(color_slots=(target,))
        shader = program(gpu, CROWD_CAPTURE, {"INFLUENCES": mesh.buffers.influences})
        with framebuffer.bind():
            framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.viewport_set(0, 0, *size)
            depth = gpu.state.depth_test_get()
            gpu.state.depth_test_set("NONE")
            gpu.state.program_point_size_set(False)
            gpu.state.point_size_set(1.0)
            self._bind_crowd(shader, np.eye(4), ids, (0, agents.size, size[0], 1))
            shader.uniform_int("u_capture_size", size)
            mesh.points.draw_instanced(shader, instance_count=agents.size)
            gpu.state.depth_test_set(depth)
            data = framebuffer.read_color(0, 0, size[0], size[1], 4, 0, "FLOAT")
        return read_buffer(data, np.float32).reshape(agents.size, size[0], 4)[..., :3].copy()

    def release(self):
        """Drop this renderer's GPU objects (Blender frees them with their wrappers)."""
        for name in ("pose_tex", "local_tex", "agent_tex", "list_tex", "skeleton_tex",
                     "color_tex", "depth_tex", "framebuffer"):
            if hasattr(self, name):
                setattr(self, name, None)
        self.meshes = {}

