"""The moderngl backend: a crowd drawn by instanced skinning from the pose texture.

Headless on EGL (:meth:`ModernGLRenderer.standalone`, Mesa llvmpipe needs no GPU)
or inside an already-current GL context such as Blender's OpenGL viewport
(:meth:`ModernGLRenderer.attach`). Each frame, after ``Crowd.step``:

* :meth:`~ModernGLRenderer.sync` writes exactly the texture rectangles core marked
  dirty (``Crowd.take_upload_regions``: pose texture rows, or with GPU skinning
  local-pose rows) and the instance texels of agents whose reference or placement
  changed; with GPU skinning it then runs the skinning-rows compute shader for
  ``Crowd.gpu_skinning_batch`` (new history slice, uniques, transition slots);
  :attr:`~ModernGLRenderer.stats` counts the bytes;
* :meth:`~ModernGLRenderer.render` draws one instanced call per (skeleton, LOD),
  regrouping agents by camera distance only when the camera or the agents moved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import CrowdError
from .assembler import gl_sources
from .camera import Camera
from .draw_lists import DrawLists, capture_mesh, proxy_bounds
from .instances import InstanceData
from .programs import CROWD_DRAW, SKIN_ROWS, SKIN_GROUP
from .proxies import INTERLEAVED_FORMAT, agent_skeletons, copies_per_instance, crowd_proxies
from .skeleton_data import batch_image, fill_batch, skeleton_image

__all__ = ["ModernGLRenderer", "FrameStats"]

GL_VERSION = 430
_POSE_UNIT, _AGENT_UNIT, _LIST_UNIT = 0, 1, 2          # CROWD_DRAW sampler slots
_LOCAL_UNIT, _SKELETON_UNIT, _BATCH_UNIT = 0, 1, 2     # SKIN_ROWS sampler slots


@dataclass
class FrameStats:
    """What the last :meth:`ModernGLRenderer.sync` / :meth:`~ModernGLRenderer.render` did.

    ``pose_bytes``/``local_bytes``: pose / local-pose texture bytes written;
    ``instance_bytes``, ``list_bytes``, ``batch_bytes``: instance texture, draw list
    and skinning batch bytes; ``skinned_rows``: pose rows the compute shader wrote;
    ``draws``, ``instances``, ``vertices``: instanced calls, agents and skinned
    vertices of the last render.
    """

    pose_bytes: int = 0
    local_bytes: int = 0
    instance_bytes: int = 0
    list_bytes: int = 0
    batch_bytes: int = 0
    skinned_rows: int = 0
    draws: int = 0
    instances: int = 0
    vertices: int = 0

    @property
    def upload_bytes(self) -> int:
        return (self.pose_bytes + self.local_bytes + self.instance_bytes + self.list_bytes
                + self.batch_bytes)


@dataclass(frozen=True)
class _Mesh:
    """GL objects of one (skeleton, LOD) proxy: its programs and vertex arrays for
    drawing (indexed triangles, ``copies`` agents an instance) and for
    transform-feedback capture (the first copy's vertices, one agent an instance)."""

    buffers: object
    copies: int
    draw_program: object
    capture_program: object
    draw: object
    capture: object
    vbo: object
    ibo: object


def _write(texture, region) -> int:
    texture.write(np.ascontiguousarray(region.data),
                  viewport=(region.x, region.y, region.width, region.height))
    return region.nbytes


class ModernGLRenderer:
    """Draws one core ``Crowd`` with moderngl.

    Parameters
    ----------
    crowd : the ``Crowd`` (its pose storage is mirrored; call :meth:`sync` after
        each ``crowd.step()``; this renderer consumes the crowd's upload regions).
    ctx : a moderngl context with OpenGL 4.3 (compute shaders and ``binding``
        layouts).
    size : (width, height) of the offscreen image in pixels.
    light : (x, y, z, ambient): direction towards the light and ambient level.
    culling : leave out agents outside the camera's view.
    owns_context : release ``ctx`` with the renderer.
    """

    def __init__(self, crowd, ctx, size=(640, 360), light=(0.4, -0.6, 0.8, 0.35),
                 culling=True, owns_context=False):
        import moderngl
        self._mgl = moderngl
        self._owns_context = bool(owns_context)
        self.culling = bool(culling)
        if ctx.version_code < GL_VERSION:
            raise CrowdError(f"moderngl renderer: needs OpenGL 4.3, the context has "
                             f"{ctx.version_code / 100:.1f}")
        self.ctx, self.crowd = ctx, crowd
        self.size = (int(size[0]), int(size[1]))
        self.light = tuple(float(v) for v in light)
        self.stats = FrameStats()
        st = crowd.storage
        limit = ctx.info["GL_MAX_TEXTURE_SIZE"]
        if max(st.width, st.height) > limit:
            raise CrowdError(f"pose texture {st.width} x {st.height} texels exceeds this GPU's "
                             f"max texture size {limit}; set CrowdConfig.max_texture_size = "
                             f"{limit}")
        self.layout = (st.height, st.row_texels, crowd.M, crowd.S)
        # the whole texture the CPU keeps goes up now; with GPU skinning the pose
        # texture is filled by the compute shader at the end of __init__
        self.local_tex = None
        if crowd.gpu_skinning:
            self.local_tex = self._texture((st.width, st.height), st.texture_image())
            self.pose_tex = self._texture((st.width, st.height), None)
        else:
            self.pose_tex = self._texture((st.width, st.height), st.texture_image())
        crowd.take_upload_regions()
        self.instances = InstanceData(crowd, limit)
        self.agent_tex = self._texture((self.instances.width, self.instances.height),
                                       self.instances.texture_image())
        self.proxies = crowd_proxies(crowd)
        self.lists = DrawLists(agent_skeletons(crowd), [len(p) for p in self.proxies],
                               [proxy_bounds(p[0].extent) if p else (0.0, 0.0)
                                for p in self.proxies],
                               crowd.config.lod_distances, min(4096, limit))
        self.list_tex = ctx.texture((self.lists.width, self.lists.height), 1, dtype="i4")
        self.list_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._list_camera = None
        self._build_meshes()
        self._build_skinning()
        self._attachments = (ctx.renderbuffer(self.size, 4), ctx.depth_renderbuffer(self.size))
        self.fbo = ctx.framebuffer(color_attachments=[self._attachments[0]],
                                   depth_attachment=self._attachments[1])
        if self.skin_program is not None:
            self._run_skinning()

    # ------------------------------------------------------------------ contexts
    @classmethod
    def standalone(cls, crowd, size=(640, 360), backend="egl", **kwargs):
        """A renderer with its own headless context (EGL: works without a GPU on Mesa)."""
        import moderngl
        try:
            ctx = moderngl.create_standalone_context(backend=backend, require=GL_VERSION)
        except Exception as e:                        # moderngl raises plain Exception
            raise CrowdError(f"moderngl renderer: cannot create a headless {backend} "
                             f"OpenGL {GL_VERSION / 100:.1f} context ({e})") from None
        return cls(crowd, ctx, size, owns_context=True, **kwargs)

    @classmethod
    def attach(cls, crowd, size=(640, 360), **kwargs):
        """A renderer in the GL context current on this thread (EGL or GLX, e.g.
        Blender's OpenGL viewport draw handler); draw into that context's framebuffer
        with ``render(camera, target=renderer.ctx.detect_framebuffer())``."""
        import moderngl
        from _moderngl import DefaultLoader         # ships with moderngl >= 5.10
        try:
            ctx = moderngl.create_context(require=GL_VERSION, context=DefaultLoader())
        except Exception as e:
            raise CrowdError(f"moderngl renderer: no current OpenGL {GL_VERSION / 100:.1f} "
                             f"context to attach to ({e})") from None
        return cls(crowd, ctx, size, **kwargs)

    # -------------------------------------------------------------------- setup
    def _texture(self, size, image, components=4, dtype="f4"):
        tex = self.ctx.texture(size, components, dtype=dtype)
        tex.filter = (self._mgl.NEAREST, self._mgl.NEAREST)
        if image is not None:
            tex.write(np.ascontiguousarray(image))
        return tex

    def _programs(self, influences):
        """(draw, capture) programs for meshes with ``influences`` bones a vertex."""
        if influences not in self.programs:
            src = gl_sources(CROWD_DRAW, {"INFLUENCES": influences})
            draw = self.ctx.program(vertex_shader=src["vertex_shader"],
                                    fragment_shader=src["fragment_shader"])
            capture = self.ctx.program(vertex_shader=src["vertex_shader"],
                                       varyings=["v_world"])
            self.programs[influences] = (draw, capture)
        return self.programs[influences]

    def _build_meshes(self):
        self.programs, self.meshes = {}, {}
        for k, levels in enumerate(self.proxies):
            for lod, buf in enumerate(levels):
                draw, capture = self._programs(buf.influences)
                copies = copies_per_instance(buf.vertex_count)
                batch = buf.batched(copies)
                vbo = self.ctx.buffer(batch.interleaved().tobytes())
                ibo = self.ctx.buffer(batch.indices.tobytes())
                self.meshes[k, lod] = _Mesh(
                    buf, copies, draw, capture,
                    self.ctx.vertex_array(draw, [_layout(vbo, draw)], ibo,
                                          index_element_size=4),
                    self.ctx.vertex_array(capture, [_layout(vbo, capture)]), vbo, ibo)

    def _build_skinning(self):
        self.skin_program = None
        if not self.crowd.gpu_skinning:
            return
        skeletons = skeleton_image(self.crowd.skeletons, self.crowd.B)
        self.skeleton_tex = self._texture(skeletons.shape[1::-1], skeletons)
        self.batch_image = batch_image(self.crowd.storage.row_count)
        self.batch_tex = self._texture(self.batch_image.shape[1::-1], self.batch_image)
        src = gl_sources(SKIN_ROWS, {"MAX_BONES": self.crowd.B})
        self.skin_program = self.ctx.compute_shader(src["compute_shader"])

    def _set(self, program, name, value):
        if name in program:                         # the GLSL compiler may drop unused ones
            program[name].value = value

    def _pose_uniforms(self, program):
        st = self.crowd.storage
        self._set(program, "u_pose_layout", self.layout)
        self._set(program, "u_pose_regions", (st.unique_base, st.slot_base,
                                              self.crowd.frame % self.crowd.M, 0))

    # -------------------------------------------------------------------- frame
    def sync(self) -> FrameStats:
        """Bring the GPU up to the crowd's current frame (see the module docstring)."""
        crowd, s = self.crowd, FrameStats()
        target = self.local_tex if crowd.gpu_skinning else self.pose_tex
        written = sum(_write(target, r) for r in crowd.take_upload_regions())
        if crowd.gpu_skinning:
            s.local_bytes = written
        else:
            s.pose_bytes = written
        s.instance_bytes = sum(_write(self.agent_tex, r)
                               for r in self.instances.update(crowd))
        if self.instances.moved:
            self._list_camera = None
        if self.skin_program is not None:
            s.batch_bytes, s.skinned_rows = self._run_skinning()
        self.stats = s
        return s

    def _run_skinning(self):
        n, texel_rows = fill_batch(self.batch_image, self.crowd.gpu_skinning_batch())
        if n == 0:
            return 0, 0
        width = self.batch_image.shape[1]
        full, rest = divmod(n, width)           # whole texel rows, then the last part
        if full:
            self.batch_tex.write(np.ascontiguousarray(self.batch_image[:full]),
                                 viewport=(0, 0, width, full))
        if rest:
            self.batch_tex.write(np.ascontiguousarray(self.batch_image[full, :rest]),
                                 viewport=(0, full, rest, 1))
        prog = self.skin_program
        self._set(prog, "u_pose_layout", self.layout)
        self._set(prog, "u_batch_count", n)
        self.local_tex.use(_LOCAL_UNIT)
        self.skeleton_tex.use(_SKELETON_UNIT)
        self.batch_tex.use(_BATCH_UNIT)
        self.pose_tex.bind_to_image(0, read=False, write=True)
        prog.run(-(-n // SKIN_GROUP))
        self.ctx.memory_barrier()
        return n * 16, n

    def _bind_draw(self, program, view_projection, draw):
        """Uniforms of one draw; ``draw`` = (list base, agents, vertices a copy, copies)."""
        self._pose_uniforms(program)
        if "u_view_proj" in program:
            program["u_view_proj"].write(np.asarray(view_projection, np.float32).T.tobytes())
        self._set(program, "u_light", self.light)
        self._set(program, "u_draw", tuple(int(v) for v in draw))

    def _bind_textures(self, list_tex):
        self.pose_tex.use(_POSE_UNIT)
        self.agent_tex.use(_AGENT_UNIT)
        list_tex.use(_LIST_UNIT)

    def render(self, camera: Camera, target=None, clear=(0.62, 0.66, 0.72, 1.0)) -> FrameStats:
        """Draw the crowd as seen by ``camera`` (its ``view_projection``) into ``target``
        (a moderngl framebuffer; default: this renderer's offscreen image, read with
        :meth:`read_image`); LODs follow the target's viewport height."""
        view_projection = camera.view_projection
        fbo = target or self.fbo
        pixels_high = fbo.viewport[3]                  # LOD: the viewport's height
        if (camera, pixels_high) != self._list_camera:
            self.stats.list_bytes += sum(
                _write(self.list_tex, r) for r in self.lists.rebuild(
                    self.crowd.agent_position, view_projection, pixels_high, self.culling))
            self._list_camera = (camera, pixels_high)
        fbo.use()
        if clear is not None:
            fbo.clear(*clear, depth=1.0)
        self.ctx.enable(self._mgl.DEPTH_TEST)
        self._bind_textures(self.list_tex)
        s = self.stats
        s.draws = s.instances = s.vertices = 0
        for g in self.lists.groups:
            mesh = self.meshes[g.skeleton, g.lod]
            self._bind_draw(mesh.draw_program, view_projection,
                            (g.base, g.count, mesh.buffers.vertex_count, mesh.copies))
            mesh.draw.render(self._mgl.TRIANGLES, instances=-(-g.count // mesh.copies))
            s.draws += 1
            s.instances += g.count
            s.vertices += g.count * mesh.buffers.vertex_count
        return s

    # ---------------------------------------------------------------- read-back
    def read_image(self) -> np.ndarray:
        """The offscreen image ``(H, W, 4)`` uint8 RGBA, first row at the top."""
        w, h = self.size
        data = self.fbo.read(components=4, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(h, w, 4)[::-1].copy()

    def read_pose_texture(self) -> np.ndarray:
        """The pose texture ``(height, width, 4)`` float32 as the GPU holds it."""
        st = self.crowd.storage
        return np.frombuffer(self.pose_tex.read(), np.float32).reshape(st.height, st.width, 4)

    def skinned_positions(self, agents, lod: int = 0) -> np.ndarray:
        """World positions ``(n, V, 3)`` float32 of ``agents`` (all of one skeleton)
        skinned by the draw program's vertex stage with LOD ``lod``, read back by
        transform feedback."""
        agents, mesh = capture_mesh(self.crowd, self.lists, self.meshes, agents, lod)
        count = mesh.buffers.vertex_count
        width = min(agents.size, self.lists.width)
        ids_image = np.zeros(-(-agents.size // width) * width, np.int32)
        ids_image[:agents.size] = agents
        ids = self._texture((width, ids_image.size // width), ids_image, 1, "i4")
        out = self.ctx.buffer(reserve=agents.size * count * 12)
        self.fbo.use()          # a surfaceless context draws nothing without a framebuffer
        self._bind_textures(ids)
        self._bind_draw(mesh.capture_program, np.eye(4), (0, agents.size, count, 1))
        mesh.capture.transform(out, self._mgl.POINTS, vertices=count, instances=agents.size)
        result = np.frombuffer(out.read(), np.float32).reshape(agents.size, -1, 3).copy()
        out.release()
        ids.release()
        return result

    def release(self):
        """Free this renderer's GL objects, and its context when :meth:`standalone` made
        it (an attached context belongs to its owner and stays)."""
        objects = [self.pose_tex, self.local_tex, self.agent_tex, self.list_tex, self.fbo,
                   *self._attachments, self.skin_program, getattr(self, "skeleton_tex", None),
                   getattr(self, "batch_tex", None)]
        objects += [p for pair in self.programs.values() for p in pair]
        for m in self.meshes.values():
            objects += [m.draw, m.capture, m.vbo, m.ibo]
        for obj in objects:
            if obj is not None:
                obj.release()
        if self._owns_context:
            self.ctx.release()


def _layout(vbo, program):
    """``(buffer, format, names...)`` of the interleaved proxy vertices for ``program``;
    attributes its compiler dropped (the capture program needs no normals) are skipped
    as padding bytes."""
    parts = [fmt if name in program else f"{size}x" for name, fmt, size in INTERLEAVED_FORMAT]
    return (vbo, " ".join(parts), *(n for n, _, _ in INTERLEAVED_FORMAT if n in program))

