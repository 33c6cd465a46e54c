"""The frame sequence every backend shares: :class:`CrowdRenderer`.

A backend (:mod:`.moderngl_backend`, :mod:`.blender_backend`) subclasses
:class:`CrowdRenderer` and implements only its primitives, all in its own GPU API:

* ``_create_texture(spec)`` -- a texture from a :class:`~.frame_plan.TextureSpec`;
* ``_write_rows(texture, block_rows, regions)`` -- whole rows of a block-laid
  RGBA32F texture; returns the bytes sent;
* ``_write_ints(texture, region)`` -- a rectangle of an R32I texture; returns bytes;
* ``_create_mesh(buffers, copies)`` -- the GPU form of one proxy level;
* ``_skin(work)`` -- the skinning-rows compute pass (:class:`~.frame_plan.SkinningWork`);
  returns the batch bytes sent;
* ``_turn_looks(uniforms, groups)`` -- the look turns compute pass
  (:data:`~.programs.LOOK_TURNS`, into the ``look_turns`` texture);
* ``_bind_target(target, clear)`` -- a context manager: bind and clear a draw
  target, set the draw state, yield the viewport's height in pixels, restore;
* ``_draw(mesh, draw)`` -- one instanced call (:class:`~.frame_plan.Draw`);
* ``_create_scene(geometry)`` / ``_draw_scene(scene, uniforms)`` -- the GPU form of
  a :class:`~.scene_geometry.SceneGeometry` and its draw (:data:`~.programs.SCENE_DRAW`);
* ``_create_shadow_map(size)`` -- a depth-only target and its depth texture (``.texture``,
  read through ``shadow_tex``); ``_bind_shadow(shadow_map)`` -- a context manager:
  bind and clear it, then give the enclosing target back; ``_matrix_texture(texels)``
  -- the 4 x 1 RGBA32F texture of the sun's matrix (:mod:`.shadows`); optionally
  ``_save_depth(shadow_map)`` / ``_restore_depth(shadow_map, saved)`` (a copy of the
  map's depth kept on the GPU, and written back; ``_save_depth`` returning None, the
  default, means no copies) with ``_bind_shadow(shadow_map, clear=False)``: the
  static scene is then drawn into the map once, not every frame;
* ``_capture(mesh, capture)`` -- world positions of the crowd's vertex stage
  (:class:`~.frame_plan.Capture`) as ``(n, V, 3)`` float32;
* ``_read_texture(texture)`` -- a float texture's texels, flat float32;
* ``read_image()``, ``finish()``, ``device``, ``_release()``.

Everything else -- sizes, which texture gets which upload, the agent rows that
changed, LOD groups, uniform values, statistics -- comes from the
:class:`~.frame_plan.FramePlan`, in the order :meth:`CrowdRenderer.sync` and
:meth:`CrowdRenderer.render` give here.
"""

from __future__ import annotations

import numpy as np

from ..core.base.errors import CrowdError
from ..core.runtime.pose_storage import TextureRegion
from .frame_plan import Draw, FramePlan, FrameStats, TextureSpec, gl_matrix
from .programs import LOOK_GROUP
from .shadows import LIT_VIEW, SHADOW_SIZE, sun_view, view_texels

__all__ = ["CrowdRenderer", "BACKGROUND"]

#: The default clear colour of :meth:`CrowdRenderer.render`.
BACKGROUND = (0.62, 0.66, 0.72, 1.0)


class CrowdRenderer:
    """Draws one crowd by instanced skinning from the pose texture (subclasses supply
    the GPU API, see the module docstring).

    Parameters
    ----------
    view : the crowd's :class:`~crowd_addon.core.runtime.frame_view.FrameView` (``crowd.view``);
        call :meth:`sync` after each ``crowd.step()``. The renderer consumes the
        crowd's upload regions and skinning batches: one renderer per crowd (a sync
        after another reader took them is a CrowdError: it would draw stale poses).
    max_texture_size : the GPU's largest texture side in texels.
    light : (x, y, z, ambient): direction towards the light and ambient level.
    culling : leave out agents outside the camera's view.
    shadows : cast the sun's shadows (:mod:`.shadows`): the scene and the agents the
        camera draws, onto both.
    max_int : integers the backend's int texture writes keep exact (None: all int32).
    lod : False: every agent drawn with its full mesh (:meth:`set_lod`).
    copies : draw small meshes several agents an instance (:class:`~.frame_plan.FramePlan`;
        False for a backend that feeds its agents as per-instance attributes).

    Attributes
    ----------
    plan : the :class:`~.frame_plan.FramePlan` (draw lists, instance data, layout).
    textures : ``{name: texture}`` of the plan's textures (``pose``, ``agents``,
        ``lists``; with GPU skinning ``local`` and ``skeletons``).
    meshes : ``{(skeleton, lod): mesh}``.
    stats : :class:`~.frame_plan.FrameStats` of the last sync and render.
    scene : the :class:`~.scene_geometry.SceneGeometry` drawn under the crowd, or None
        (:meth:`set_scene`).
    """

    #: Most regions of agent rows written a frame (None: one per run of changed agents).
    MAX_ROW_WRITES = None

    def __init__(self, view, max_texture_size, light=(0.4, -0.6, 0.8, 0.35), culling=True,
                 max_int=None, shadows=False, lod=True, copies=True):
        self.view = view
        self.culling = bool(culling)
        self.light = tuple(float(v) for v in light)
        self.shadows = bool(shadows)
        self.stats = FrameStats()
        self.scene, self._scene, self._shadow_map = None, None, None
        self._scene_bounds = None
        #: (sun matrix bytes, the map's depth with the scene alone) once drawn
        self._shadow_scene = None
        self.plan = FramePlan(view, max_texture_size, max_int, lod=lod, copies=copies)
        #: the highest bind-pose point of any proxy (metres): the shadow casters' reach
        self._tallest = self.plan.max_scale * max(
            (float(buf.extent[1, 2]) for levels in self.plan.proxies for buf in levels),
            default=2.0)
        self.textures = {s.name: self._create_texture(s)
                         for s in self.plan.take_initial_textures()}
        self._lit = (self._create_texture(TextureSpec("shadow", (1, 1), "RGBA32F",
                                                      np.ones((1, 1, 4), np.float32))),
                     self._create_texture(TextureSpec("shadow_view", (4, 1), "RGBA32F",
                                                      view_texels(LIT_VIEW))))
        self.textures["shadow"], self.textures["shadow_view"] = self._lit
        #: whether the draws now read the shadow map (the programs' ``SHADOWS``)
        self.sampling_shadows = False
        #: whether the crowd draw now needs the look stage (``LOOKS``; a backend may
        #: always compile it in)
        self.draw_looks = True
        #: (looking flags (N,), {(body, LOD): agents not looking, listed first}) while
        #: some agent looks (:meth:`_list_lookers_last`)
        self._lookers = None
        #: whether the draws now write sRGB-encoded colours (the programs'
        #: ``ENCODE_SRGB``, gpu_shaders/crowd_frag.glsl): into this renderer's own
        #: image, yes; into a framebuffer the caller passes or has bound (Blender's
        #: viewport overlay, an sRGB buffer that encodes on write), no
        self.encoding_srgb = True
        self.meshes = {key: self._create_mesh(buf, copies)
                       for key, (buf, copies) in self.plan.meshes().items()}
        work = self.plan.take_skinning()          # GPU skinning: fill the pose texture
        if work is not None:
            self._skin(work)
        self._looks_turned()
        self._takes = view.takes                  # the crowd's changes seen so far

    # -------------------------------------------------------------------- frame
    def sync(self) -> FrameStats:
        """Bring the GPU up to the crowd's current frame: core's upload regions (pose
        rows, or with GPU skinning local-pose rows), the rows of agents the crowd
        changed, and with GPU skinning the skinning-rows pass; returns the bytes
        sent (:attr:`stats`)."""
        plan, s = self.plan, FrameStats()
        if self.view.takes != self._takes:
            raise CrowdError("another renderer (or reader) of this crowd took its pose "
                             "changes since this renderer last synced, so it would draw "
                             "stale poses: a crowd's changes go to one renderer; release "
                             "the other, or draw a second Crowd of the same configuration")
        written = self._write_rows(self.textures[plan.upload_target], plan.layout.height,
                                   plan.take_pose_regions())
        if plan.on_gpu:
            s.local_bytes = written
        else:
            s.pose_bytes = written
        s.instance_bytes = self._write_rows(self.textures["agents"],
                                            plan.instances.block_rows,
                                            plan.take_instance_regions(self.MAX_ROW_WRITES))
        s.look_bytes = self._write_rows(self.textures["looks"], plan.looks.block_rows,
                                        plan.take_look_regions(self.MAX_ROW_WRITES))
        work = plan.take_skinning()
        if work is not None:
            s.batch_bytes, s.skinned_rows = self._skin(work), work.count
        self._looks_turned()
        self._takes = self.view.takes
        self.stats = s
        return s

    def _looks_turned(self):
        """The look turns pass of the current frame, when some agent looks: each
        looking agent's turns worked out once, after its pose rows are in place."""
        uniforms = self.plan.look_turns()
        if uniforms is not None:
            self._turn_looks(uniforms, -(-self.view.agent_count // LOOK_GROUP))

    def set_scene(self, geometry) -> None:
        """Draw ``geometry`` (a :class:`~.scene_geometry.SceneGeometry`, or None for no
        scene) under the crowd in every later :meth:`render`: same camera, same light,
        same depth buffer. A viewport that draws its scene itself needs none."""
        self._release_scene()
        self._scene_bounds = None
        self._shadow_scene = None
        if geometry is not None and geometry.triangle_count:
            self._scene = self._create_scene(geometry)
            self._scene_bounds = geometry.bounds()     # once: the shadows' depth range
        self.scene = geometry

    def set_lod(self, on: bool):
        """Levels of detail on (the default), or off: every agent drawn with its full
        mesh (``crowd preview --lod off``), from the next :meth:`render`."""
        self.plan.set_lod(on)

    def render(self, camera, target=None, clear=BACKGROUND) -> FrameStats:
        """Draw the crowd as seen by ``camera`` (anything with ``view_projection``
        (4, 4), OpenGL clip space) into ``target`` (the backend's framebuffer type;
        None: this renderer's offscreen image, or for a renderer without one the
        framebuffer bound now), over its scene when one is set (:meth:`set_scene`).
        LODs follow the target's viewport height. ``clear``: RGBA to clear colour and
        depth to first, None to draw over what is there (its depth hides agents).
        Colours go to the renderer's own image sRGB-encoded (as Blender's Standard view
        transform shows them), to any other target linear (:attr:`encoding_srgb`)."""
        vp = np.asarray(camera.view_projection, np.float64)
        s = self.stats
        s.draws = s.instances = s.vertices = 0
        self.encoding_srgb = target is None and self._owns_image()
        with self._bind_target(target, clear) as pixels_high:
            regions = self.plan.regroup(vp, pixels_high, self.culling)
            for region in regions + self._list_lookers_last(bool(regions)):
                s.list_bytes += self._write_ints(self.textures["lists"], region)
            self.sampling_shadows = False
            if self.shadows:
                self._shadow_pass()
                self.sampling_shadows = True
            # the crowd before the scene: the stands' fragments behind the agents then
            # fail the depth test before they are shaded (-40% of the scene pass on
            # llvmpipe at 65k; only depth ties, a few pixels, can tell the orders apart)
            for whole in self.plan.draws(vp, self.light):
                for draw, self.draw_looks in self._look_parts(whole):
                    self._draw(self.meshes[draw.key], draw)
                    s.draws += 1
                    s.instances += draw.agents
                    s.vertices += draw.vertices
            if self._scene is not None:
                self._draw_scene(self._scene, {"u_view_proj": gl_matrix(vp),
                                               "u_light": self.light})
        return s

    def _list_lookers_last(self, rebuilt: bool) -> list:
        """While some agent looks, each draw group's looking agents listed after the
        others (stably), so a group is drawn in two calls and only the second runs the
        look stage (llvmpipe would run it for every vertex of a call: the demo's 5,782
        looking fans of 21,470 drawn); returns the list texture regions to write."""
        frame, looks = self.view.frame, self.plan.looks
        if not looks.active(frame):
            self._lookers = None
            return []
        flags = looks.looking(frame)
        if not rebuilt and self._lookers is not None \
                and np.array_equal(flags, self._lookers[0]):
            return []
        lists = self.plan.lists
        flat, first = lists.image.reshape(-1), {}
        for g in lists.groups:
            ids = flat[g.base:g.base + g.count]
            on = flags[ids]
            flat[g.base:g.base + g.count] = ids[np.argsort(on, kind="stable")]
            first[(g.body, g.lod)] = g.count - int(on.sum())
        self._lookers = (flags, first)
        used = sum(g.count for g in lists.groups)
        rows = max(1, -(-used // lists.width))
        return [TextureRegion(0, 0, lists.width, rows, lists.image[:rows])]

    def _look_parts(self, draw) -> list:
        """``[(draw, looks)]``: ``draw`` whole without the look stage when no agent
        looks, else its agents not looking and those looking as two calls."""
        if self._lookers is None:
            return [(draw, False)]
        base, count, verts, copies = draw.uniforms["u_draw"]
        k = self._lookers[1].get(draw.key, 0)
        parts = []
        for start, n, looks in ((base, k, False), (base + k, count - k, True)):
            if n > 0:
                parts.append((Draw(draw.key, -(-n // copies), n, n * verts,
                                   {**draw.uniforms, "u_draw": (start, n, verts, copies)}),
                              looks))
        return parts

    def _fragment_defines(self) -> dict:
        """The fragment stage's defines for the draws now: ``SHADOWS`` and
        ``ENCODE_SRGB``."""
        return {"SHADOWS": int(self.sampling_shadows), "ENCODE_SRGB": int(self.encoding_srgb)}

    def _shadow_pass(self):
        """Draw the sun's shadow map (the scene, then the agents of the current draw
        lists as their coarsest level) and bind it for the frame's draws."""
        pos = np.asarray(self.view.agents.position, np.float64)
        if pos.size == 0:
            return
        light_vp = sun_view(self.light, pos.min(0), pos.max(0) + (0.0, 0.0, self._tallest),
                            self._scene_bounds)
        if self._shadow_map is None:
            self._shadow_map = self._create_shadow_map(SHADOW_SIZE)
        # the map's own pass reads no shadow map (SHADOWS 0, stand-in textures bound)
        self.textures["shadow"], self.textures["shadow_view"] = self._lit
        self.sampling_shadows = False
        # the static scene's depth is drawn once for a sun matrix and copied back each
        # frame (a 2048^2 depth write costs about what the clear did; the scene's
        # triangles ~65 ms on llvmpipe); the agents are drawn over it every frame
        key = light_vp.tobytes()
        cached = self._scene is not None and self._shadow_scene is not None \
            and self._shadow_scene[0] == key
        if cached:
            self._restore_depth(self._shadow_map, self._shadow_scene[1])
        with self._bind_shadow(self._shadow_map, **({"clear": False} if cached else {})):
            if self._scene is not None and not cached:
                self._draw_scene(self._scene, {"u_view_proj": gl_matrix(light_vp),
                                               "u_light": self.light})
                saved = self._save_depth(self._shadow_map)
                self._shadow_scene = None if saved is None else (key, saved)
            self.draw_looks = self._lookers is not None
            for draw in self.plan.caster_draws(light_vp, self.light):
                self._draw(self.meshes[draw.key], draw)
        self.textures["shadow"] = self._shadow_map.texture
        self.textures["shadow_view"] = self._matrix_texture(view_texels(light_vp))

    # ---------------------------------------------------------------- read-back
    def read_pose_texture(self) -> np.ndarray:
        """The pose texture ``(height, width, 4)`` float32 as the GPU holds it."""
        lay = self.plan.layout
        return self._read_texture(self.textures["pose"]).reshape(lay.height, lay.width, 4)

    def skinned_positions(self, agents, lod: int = 0) -> np.ndarray:
        """World positions ``(n, V, 3)`` float32 of ``agents`` (all of one body: the
        same skeleton, mesh variant and props) skinned by the draw program's vertex
        stage with LOD ``lod``."""
        capture = self.plan.capture(agents, lod)
        return self._capture(self.meshes[capture.key], capture)

    def release(self):
        """Free this renderer's GPU objects."""
        self._release_scene()
        self._release()
        self.textures, self.meshes = {}, {}

    # --------------------------------------------------------------- primitives
    def _create_texture(self, spec):
        raise NotImplementedError

    def _write_rows(self, texture, block_rows, regions) -> int:
        raise NotImplementedError

    def _turn_looks(self, uniforms, groups):
        raise NotImplementedError

    def _write_ints(self, texture, region) -> int:
        raise NotImplementedError

    def _create_mesh(self, buffers, copies):
        raise NotImplementedError

    def _skin(self, work) -> int:
        raise NotImplementedError

    def _bind_target(self, target, clear):
        raise NotImplementedError

    def _owns_image(self) -> bool:
        """Whether ``render`` without a target draws into this renderer's own image."""
        raise NotImplementedError

    def _draw(self, mesh, draw):
        raise NotImplementedError

    def _capture(self, mesh, capture) -> np.ndarray:
        raise NotImplementedError

    def _create_scene(self, geometry):
        raise NotImplementedError

    def _draw_scene(self, scene, uniforms):
        raise NotImplementedError

    def _release_scene(self):
        """Free the scene's GPU objects (a backend whose objects free themselves with
        their Python wrappers only drops them)."""
        self._scene = None

    def _create_shadow_map(self, size):
        raise NotImplementedError

    def _bind_shadow(self, shadow_map):
        raise NotImplementedError

    def _matrix_texture(self, texels):
        raise NotImplementedError

    def _save_depth(self, shadow_map):
        """A copy of ``shadow_map``'s depth to restore later, or None: this backend
        keeps none, and draws the scene into the map every frame."""
        return None

    def _restore_depth(self, shadow_map, saved):
        raise NotImplementedError

    def _read_texture(self, texture) -> np.ndarray:
        raise NotImplementedError

    def read_image(self) -> np.ndarray:
        """The offscreen image ``(H, W, 4)`` uint8 RGBA, first row at the top."""
        raise NotImplementedError

    def finish(self):
        """Wait until the GPU has done everything asked of it (for timing)."""
        raise NotImplementedError

    @property
    def device(self) -> str:
        """The GPU (or software renderer) the backend reports."""
        raise NotImplementedError

    def _release(self):
        raise NotImplementedError
