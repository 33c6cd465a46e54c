"""The moderngl backend: :class:`~.renderer.CrowdRenderer`'s primitives in moderngl.

Headless on EGL (:meth:`ModernGLRenderer.standalone`, Mesa llvmpipe needs no GPU)
or inside an already-current GL context such as Blender's OpenGL viewport
(:meth:`ModernGLRenderer.attach`). Regions are written with ``texture.write``
(``viewport=``), the skinning rows by a compute shader writing the pose texture as
an image, vertices read back by transform feedback of the draw program's vertex
stage (``v_world``).
"""

from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

from ..core.base.errors import CrowdError
from .assembler import gl_sources
from .frame_plan import DRAW_SAMPLERS, SKIN_SAMPLERS, TextureSpec
from .programs import (AGENT_GATHER, AGENT_INPUTS, AGENT_RECORD_TEXELS, CROWD_DRAW,
                       GATHER_GROUP, LOOK_TURNS, SCENE_DRAW, SKIN_ROWS, for_influences,
                       with_agent_attributes)
from .renderer import CrowdRenderer

__all__ = ["ModernGLRenderer", "GL_VERSION", "AGENT_FEEDS"]

GL_VERSION = 430
_FORMATS = {"RGBA32F": (4, "f4"), "R32I": (1, "i4")}
#: How a draw's vertex stage gets its agents' records: read from the agent textures by
#: every vertex, or as per-instance vertex attributes gathered once a frame
#: (docs/gpu.md, *Two feeds*).
AGENT_FEEDS = ("attributes", "texture")
_RECORD_BYTES = AGENT_RECORD_TEXELS * 16      # and 4 bytes of agent id, in a buffer apart


class _Mesh:
    """GL objects of one (skeleton, LOD) proxy: vertex arrays for drawing (indexed
    triangles, ``copies`` agents an instance; one per draw program variant, made when
    first drawn: with and without shadows, sRGB-encoded or linear, its agents read
    from textures or fed as attributes) and for transform-feedback capture (the first
    copy's vertices, one agent an instance)."""

    def __init__(self, ctx, buffers, copies, draw_program, capture_program):
        self.ctx, self.buffers, self.copies = ctx, buffers, copies
        self.draw_program, self.capture_program = draw_program, capture_program
        batch = buffers.batched(copies)
        #: a closed surface facing out (:attr:`~.proxies.ProxyBuffers.closed`): its
        #: back faces are culled (hidden anyway; llvmpipe skips half the triangles)
        self.cull = buffers.closed
        self.vbo = ctx.buffer(batch.interleaved().tobytes())
        self.ibo = ctx.buffer(batch.indices.tobytes())
        self.draws = {}
        self.capture = ctx.vertex_array(capture_program,
                                        [_layout(self.vbo, capture_program, buffers.format)])

    def draw(self, defines: dict):
        """(program, vertex array) of the draw variant of the fragment ``defines``
        (:meth:`~.renderer.CrowdRenderer._fragment_defines`)."""
        key = tuple(sorted(defines.items()))
        if key not in self.draws:
            prog = self.draw_program(defines)
            self.draws[key] = prog, self.ctx.vertex_array(
                prog, [_layout(self.vbo, prog, self.buffers.format)], self.ibo,
                index_element_size=4)
        return self.draws[key]

    def objects(self):
        return [vao for _, vao in self.draws.values()] + [self.capture, self.vbo, self.ibo]


class _ShadowMap:
    """The shadow map's depth-only framebuffer and its depth texture."""

    def __init__(self, fbo, texture):
        self.fbo, self.texture = fbo, texture
        self.saved = None           # a GPU buffer: the depth of the scene alone


class ModernGLRenderer(CrowdRenderer):
    """Draws one crowd with moderngl.

    Parameters
    ----------
    view : the crowd's ``FrameView`` (see :class:`~.renderer.CrowdRenderer`).
    ctx : a moderngl context with OpenGL 4.3 (compute shaders and ``binding``
        layouts).
    size : (width, height) of the offscreen image in pixels.
    light, culling, shadows : see :class:`~.renderer.CrowdRenderer`.
    owns_context : release ``ctx`` with the renderer.
    samples : anti-aliasing of the offscreen image: samples a pixel (0 or 1: none),
        taken as a k x k grid, k = the whole square root of ``samples``, at least 2
        (supersampling: the image is drawn k times as wide and high and each pixel is
        the mean of its k x k samples, by :meth:`read_image`). Not multisampling:
        llvmpipe rasterises a multisampled target's many sub-pixel crowd triangles at
        about 2.5 times the cost (docs/gpu.md, "Anti-aliasing").
    agent_feed : how the draws get their agents' records (:data:`AGENT_FEEDS`):
        ``"attributes"`` (default), gathered once a frame into per-instance vertex
        attributes, every mesh drawn one agent an instance; or ``"texture"``, read by
        every vertex from the agent, look and list textures, small meshes drawn several
        agents an instance, as Blender's ``gpu`` module must. The same pictures;
        docs/gpu.md, *Two feeds*.
    """

    MAX_ROW_WRITES = 1024       # a few hundred small writes cost less than whole blocks

    def __init__(self, view, ctx, size=(640, 360), light=(0.4, -0.6, 0.8, 0.35),
                 culling=True, owns_context=False, samples=0, shadows=False, lod=True,
                 agent_feed="attributes"):
        import moderngl
        self._mgl = moderngl
        if ctx.version_code < GL_VERSION:
            raise CrowdError(f"moderngl renderer: needs OpenGL 4.3, the context has "
                             f"{ctx.version_code / 100:.1f}")
        if agent_feed not in AGENT_FEEDS:
            raise CrowdError(f"moderngl renderer: agent_feed must be one of "
                             f"{', '.join(AGENT_FEEDS)}, got {agent_feed!r}")
        self.agent_feed = agent_feed
        self._records, self._records_fresh = None, False    # (records, ids) buffers
        self.ctx, self._owns_context = ctx, bool(owns_context)
        self.size = (int(size[0]), int(size[1]))
        self._programs = {}
        #: the k of the k x k samples a pixel (1: none)
        self.scale = max(2, math.isqrt(int(samples))) if samples > 1 else 1
        largest = min(ctx.info["GL_MAX_TEXTURE_SIZE"], ctx.info["GL_MAX_RENDERBUFFER_SIZE"])
        self.scale = max(1, min(self.scale, largest // max(self.size)))
        self.samples = self.scale ** 2 if self.scale > 1 else 0
        drawn = (self.size[0] * self.scale, self.size[1] * self.scale)
        colour = ctx.texture(drawn, 4) if self.scale > 1 else ctx.renderbuffer(drawn, 4)
        self._attachments = (colour, ctx.depth_renderbuffer(drawn))
        self.fbo = ctx.framebuffer(color_attachments=[self._attachments[0]],
                                   depth_attachment=self._attachments[1])
        self._resolved = None               # the image read_image reads, when supersampled
        self._resolve = None                # (program, vertex array) of the mean
        self._shadow_view = None
        if self.scale > 1:
            colour.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._attachments += (ctx.renderbuffer(self.size, 4),)
            self._resolved = ctx.framebuffer(color_attachments=[self._attachments[2]])
        # fed as attributes, every mesh is drawn one agent an instance (no copies)
        super().__init__(view, ctx.info["GL_MAX_TEXTURE_SIZE"], light, culling,
                         shadows=shadows, lod=lod, copies=agent_feed == "texture")

    # ------------------------------------------------------------------ contexts
    @classmethod
    def standalone(cls, view, size=(640, 360), backend="egl", **kwargs):
        """A renderer with its own headless context (EGL: works without a GPU on Mesa)."""
        import moderngl
        try:
            ctx = moderngl.create_standalone_context(backend=backend, require=GL_VERSION)
        except Exception as e:                        # moderngl raises plain Exception
            raise CrowdError(f"moderngl renderer: cannot create a headless {backend} "
                             f"OpenGL {GL_VERSION / 100:.1f} context ({e})") from None
        try:
            return cls(view, ctx, size, owns_context=True, **kwargs)
        except BaseException:
            ctx.release()                 # nobody else will
            raise

    @classmethod
    def attach(cls, view, size=(640, 360), **kwargs):
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
        return cls(view, ctx, size, **kwargs)

    # ---------------------------------------------------------------- primitives
    def _create_texture(self, spec):
        self._records_fresh = False
        components, dtype = _FORMATS[spec.format]
        tex = self.ctx.texture(spec.size, components, dtype=dtype)
        tex.filter = (self._mgl.NEAREST, self._mgl.NEAREST)
        if spec.image is not None:
            tex.write(np.ascontiguousarray(spec.image))
        return tex

    def _write(self, texture, region) -> int:
        self._records_fresh = False         # an agent, look or list texel may change
        texture.write(np.ascontiguousarray(region.data),
                      viewport=(region.x, region.y, region.width, region.height))
        return region.nbytes

    def _write_rows(self, texture, block_rows, regions) -> int:
        return sum(self._write(texture, r) for r in regions)

    _write_ints = _write

    def _program(self, spec, defines, capture=False):
        """``spec`` compiled with ``defines`` (the draw program's vertex stage alone
        with ``v_world`` captured when ``capture``), once per renderer."""
        key = (spec.name, tuple(sorted(defines.items())), capture)
        if key not in self._programs:
            src = gl_sources(spec, defines)
            if "compute_shader" in src:
                prog = self.ctx.compute_shader(src["compute_shader"])
            elif capture:
                prog = self.ctx.program(vertex_shader=src["vertex_shader"],
                                        varyings=["v_world"])
            else:
                prog = self.ctx.program(**src)
            self._programs[key] = prog
        return self._programs[key]

    def _create_mesh(self, buffers, copies):
        n = buffers.influences
        spec = for_influences(CROWD_DRAW, n)

        def draw_program(defines):
            fed = with_agent_attributes(spec) if defines["AGENT_ATTRIBUTES"] else spec
            return self._program(fed, {"INFLUENCES": n, **defines})
        return _Mesh(self.ctx, buffers, copies, draw_program,
                     self._program(spec, {"INFLUENCES": n, "SHADOWS": 0, "ENCODE_SRGB": 0},
                                   True))

    def _skin(self, work) -> int:
        if "batch" not in self.textures:
            self.textures["batch"] = self._create_texture(
                TextureSpec("batch", self.plan.batch_size, "RGBA32F"))
        sent = sum(self._write(self.textures["batch"], r) for r in work.regions)
        prog = self._program(SKIN_ROWS, {"MAX_BONES": self.plan.layout.bones})
        _set_uniforms(prog, work.uniforms)
        for slot, _, name in SKIN_ROWS.samplers:
            self.textures[SKIN_SAMPLERS[name]].use(slot)
        self.textures["pose"].bind_to_image(0, read=False, write=True)
        prog.run(work.groups)
        self.ctx.memory_barrier()
        return sent

    def _turn_looks(self, uniforms, groups):
        prog = self._program(LOOK_TURNS, {})
        _set_uniforms(prog, uniforms)
        for slot, _, name in LOOK_TURNS.samplers:
            self.textures[DRAW_SAMPLERS[name]].use(slot)
        self.textures["look_turns"].bind_to_image(0, read=False, write=True)
        prog.run(groups)
        self.ctx.memory_barrier()

    def _owns_image(self) -> bool:
        return True

    @contextmanager
    def _bind_target(self, target, clear):
        fbo = target or self.fbo
        fbo.use()
        if clear is not None:
            fbo.clear(*clear, depth=1.0)
        self.ctx.enable(self._mgl.DEPTH_TEST)
        # LOD: the viewport's height (the image's, not its supersampled drawing's)
        yield fbo.viewport[3] if fbo is not self.fbo else self.size[1]

    def _bind(self, program, uniforms, list_texture):
        _set_uniforms(program, uniforms)
        for slot, _, name in CROWD_DRAW.samplers:
            tex = list_texture if name == "agent_list_tex" else \
                self.textures[DRAW_SAMPLERS[name]]
            tex.use(slot)

    def _draw(self, mesh, draw):
        looks = int(self.draw_looks)           # LOOKS 0: no agent of this call looks
        fed = self.agent_feed == "attributes"        # then every mesh has copies 1
        program, vao = mesh.draw({**self._fragment_defines(), "LOOKS": looks,
                                  "AGENT_ATTRIBUTES": int(fed)})
        self._bind(program, draw.uniforms, self.textures["lists"])
        if fed:
            self._feed(vao, draw.uniforms["u_draw"][0])
        if mesh.cull:
            self.ctx.enable(self._mgl.CULL_FACE)
        vao.render(self._mgl.TRIANGLES, instances=draw.instances)
        if mesh.cull:
            self.ctx.disable(self._mgl.CULL_FACE)

    def _feed(self, vao, base):
        """Bind the gathered records and ids of the draw list entries from ``base`` on
        as ``vao``'s per-instance :data:`~.programs.AGENT_INPUTS`."""
        records, ids = self._gathered()
        for k, (slot, kind, _) in enumerate(AGENT_INPUTS):
            if kind == "INT":
                vao.bind(slot, "i", ids, "i", offset=base * 4, stride=4, divisor=1)
            else:
                vao.bind(slot, "f", records, "4f", offset=base * _RECORD_BYTES + k * 16,
                         stride=_RECORD_BYTES, divisor=1)

    def _gathered(self):
        """The records and ids buffers (:data:`~.programs.AGENT_GATHER`), gathered again
        when an agent, look or list texel was written since they last were: one compute
        pass a frame over the entries of the draw lists, whatever the number of draws."""
        lists = self.plan.lists
        if self._records is None:
            capacity = lists.width * lists.height
            self._records = (self.ctx.buffer(reserve=capacity * _RECORD_BYTES),
                             self.ctx.buffer(reserve=capacity * 4))
        if not self._records_fresh:
            entries = max((g.base + g.count for g in lists.groups), default=0)
            if entries:
                prog = self._program(AGENT_GATHER, {})
                _set_uniforms(prog, {"u_draw": (0, entries, 0, 0)})
                for slot, _, name in AGENT_GATHER.samplers:
                    self.textures[DRAW_SAMPLERS[name]].use(slot)
                for binding, buffer in enumerate(self._records):
                    buffer.bind_to_storage_buffer(binding)
                prog.run(-(-entries // GATHER_GROUP))
                self.ctx.memory_barrier()
            self._records_fresh = True
        return self._records

    def _capture(self, mesh, capture) -> np.ndarray:
        n, count = capture.agents.size, mesh.buffers.vertex_count
        ids = self._create_texture(TextureSpec("ids", (capture.ids.width, capture.ids.height),
                                               "R32I", capture.ids.data))
        out = self.ctx.buffer(reserve=n * count * 12)
        self.fbo.use()          # a surfaceless context draws nothing without a framebuffer
        self._bind(mesh.capture_program, capture.uniforms, ids)
        mesh.capture.transform(out, self._mgl.POINTS, vertices=count, instances=n)
        result = np.frombuffer(out.read(), np.float32).reshape(n, -1, 3).copy()
        out.release()
        ids.release()
        return result

    def _create_scene(self, geometry):
        vbo = self.ctx.buffer(geometry.interleaved().tobytes())
        return {"vbo": vbo}

    def _draw_scene(self, scene, uniforms):
        defines = self._fragment_defines()
        key = tuple(sorted(defines.items()))
        if key not in scene:                      # one vertex array a program variant
            prog = self._program(SCENE_DRAW, defines)
            scene[key] = self.ctx.vertex_array(
                prog, [(scene["vbo"], "3f 3f 3f", "pos", "nor", "col")])
        vao = scene[key]
        _set_uniforms(vao.program, uniforms)
        for slot, _, name in SCENE_DRAW.samplers:
            self.textures[DRAW_SAMPLERS[name]].use(slot)
        vao.render(self._mgl.TRIANGLES)

    def _release_scene(self):
        if self._scene is not None:
            for key, obj in self._scene.items():
                if key != "vbo":
                    obj.release()
            self._scene["vbo"].release()
        self._scene = None

    def _create_shadow_map(self, size):
        tex = self.ctx.depth_texture((size, size))
        tex.compare_func = ""                       # read as depth, not compared
        tex.filter = (self._mgl.NEAREST, self._mgl.NEAREST)
        return _ShadowMap(self.ctx.framebuffer(depth_attachment=tex), tex)

    @contextmanager
    def _bind_shadow(self, shadow_map, clear=True):
        outer = self.ctx.fbo
        shadow_map.fbo.use()
        if clear:
            shadow_map.fbo.clear(depth=1.0)
        try:
            yield
        finally:
            outer.use()

    def _save_depth(self, shadow_map):
        if shadow_map.saved is None:
            shadow_map.saved = self.ctx.buffer(reserve=shadow_map.texture.size[0]
                                               * shadow_map.texture.size[1] * 4)
        shadow_map.texture.read_into(shadow_map.saved)
        return shadow_map.saved

    def _restore_depth(self, shadow_map, saved):
        shadow_map.texture.write(saved)

    def _matrix_texture(self, texels):
        if self._shadow_view is None:
            self._shadow_view = self._create_texture(
                TextureSpec("shadow_view", (4, 1), "RGBA32F", texels))
        else:
            self._shadow_view.write(np.ascontiguousarray(texels, np.float32))
        return self._shadow_view

    def _read_texture(self, texture) -> np.ndarray:
        return np.frombuffer(texture.read(), np.float32)

    def read_image(self) -> np.ndarray:
        w, h = self.size
        fbo = self.fbo
        if self._resolved is not None:
            self._mean_samples()
            fbo = self._resolved
        data = fbo.read(components=4, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(h, w, 4)[::-1].copy()

    def _mean_samples(self):
        """Each pixel of the image the mean of its ``scale`` x ``scale`` samples (the
        colours as drawn, sRGB-encoded: as a multisample resolve averages them)."""
        if self._resolve is None:
            prog = self.ctx.program(vertex_shader=_RESOLVE_VERTEX,
                                    fragment_shader=_RESOLVE_FRAGMENT)
            self._resolve = prog, self.ctx.vertex_array(prog, [])
        prog, vao = self._resolve
        prog["scale"].value = self.scale
        self._resolved.use()
        self._attachments[0].use(0)
        self.ctx.disable(self._mgl.DEPTH_TEST | self._mgl.CULL_FACE)
        vao.render(self._mgl.TRIANGLES, vertices=3)
        self.ctx.enable(self._mgl.DEPTH_TEST)

    def finish(self):
        self.ctx.finish()

    @property
    def device(self) -> str:
        return self.ctx.info["GL_RENDERER"]

    def _release(self):
        """Free the GL objects, and the context when :meth:`standalone` made it (an
        attached context belongs to its owner and stays)."""
        objects = [*self.textures.values(), self.fbo, self._resolved, *self._attachments,
                   *self._programs.values(), *self._lit, self._shadow_view,
                   *(self._resolve or ()), *(self._records or ())]
        if self._shadow_map is not None:
            objects += [self._shadow_map.fbo, self._shadow_map.texture,
                        self._shadow_map.saved]
        objects = list({id(o): o for o in objects}.values())     # each once
        for m in self.meshes.values():
            objects += m.objects()
        for obj in objects:
            if obj is not None:
                obj.release()
        self._programs = {}
        if self._owns_context:
            self.ctx.release()


#: a triangle over the whole target, and the mean of each pixel's k x k samples
_RESOLVE_VERTEX = """#version 430 core
void main()
{
  vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""
_RESOLVE_FRAGMENT = """#version 430 core
uniform sampler2D image;
uniform int scale;
out vec4 color;
void main()
{
  ivec2 origin = ivec2(gl_FragCoord.xy) * scale;
  vec4 sum = vec4(0.0);
  for (int y = 0; y < scale; y++) {
    for (int x = 0; x < scale; x++) {
      sum += texelFetch(image, origin + ivec2(x, y), 0);
    }
  }
  color = sum / float(scale * scale);
}
"""


def _set_uniforms(program, uniforms: dict):
    """Set the uniforms the GLSL compiler kept (it drops unused ones); ``mat4`` values
    are 16 floats in column-major order."""
    for name, value in uniforms.items():
        if name in program:
            program[name].value = value


def _layout(vbo, program, layout):
    """``(buffer, format, names...)`` of the interleaved proxy vertices (``layout``:
    ``ProxyBuffers.format``) for ``program``; attributes its compiler dropped (the
    capture program needs no normals) or it does not declare are skipped as padding
    bytes."""
    parts = [fmt if name in program else f"{size}x" for name, fmt, size in layout]
    return (vbo, " ".join(parts), *(n for n, _, _ in layout if n in program))
