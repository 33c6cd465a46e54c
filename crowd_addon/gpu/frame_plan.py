"""What a renderer does for a crowd each frame, worked out once for every backend.

A :class:`FramePlan` reads a crowd's :class:`~crowd_addon.core.runtime.frame_view.FrameView`
and turns it into plain data, with no GPU API: the size checks, the textures to make
at the start (:class:`TextureSpec`), the texture regions to write each frame (which
texture the pose uploads go to depends on the skinning mode), the agent rows that
changed (:class:`~.instances.InstanceData`, from the crowd's change log), the draw
lists and LOD groups (:class:`~.draw_lists.DrawLists`), the skinning batch
(:class:`SkinningWork`), one :class:`Draw` per instanced call with its uniform
values, and vertex read-back requests (:class:`Capture`). :class:`FrameStats` counts
what a frame sent and drew. :class:`~.renderer.CrowdRenderer` sequences the plan over
a backend's primitives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.base.errors import CrowdError
from ..core.meshes.lod import agent_heights, switch_pixels
from ..core.runtime.pose_storage import TextureRegion
from .draw_lists import DrawLists, proxy_bounds
from .instances import InstanceData
from .look_data import LookData
from .programs import SKIN_GROUP
from .proxies import copies_per_instance, crowd_proxies
from .skeleton_data import batch_image, fill_batch, skeleton_image

__all__ = ["FramePlan", "FrameStats", "TextureSpec", "SkinningWork", "Draw", "Capture",
           "DRAW_SAMPLERS", "SKIN_SAMPLERS", "gl_matrix"]

#: Sampler of the draw and look-turns programs -> name of the texture it reads.
DRAW_SAMPLERS = {"pose_tex": "pose", "agent_tex": "agents", "agent_list_tex": "lists",
                 "shadow_tex": "shadow", "shadow_view_tex": "shadow_view",
                 "look_tex": "looks", "look_target_tex": "look_targets",
                 "look_chain_tex": "look_chains", "look_turn_tex": "look_turns"}
#: Sampler of the skinning-rows program -> name of the texture it reads (``batch``: the
#: batch texture the backend keeps or makes for :class:`SkinningWork`).
SKIN_SAMPLERS = {"local_tex": "local", "skeleton_tex": "skeletons", "batch_tex": "batch"}


@dataclass
class FrameStats:
    """What the last ``sync`` / ``render`` of a renderer did.

    ``pose_bytes``/``local_bytes``: pose / local-pose texture bytes written;
    ``instance_bytes``, ``list_bytes``, ``batch_bytes``, ``look_bytes``: agent
    texture, draw list, skinning batch and looks texture bytes (the last only in a
    frame where a look started or stopped); ``skinned_rows``: pose rows the compute shader wrote;
    ``draws``, ``instances``, ``vertices``: instanced calls, agents and skinned
    vertices of the last render. Bytes are what the backend sent (a backend without
    partial texture writes adds a row number to each row).
    """

    pose_bytes: int = 0
    local_bytes: int = 0
    instance_bytes: int = 0
    list_bytes: int = 0
    batch_bytes: int = 0
    look_bytes: int = 0
    skinned_rows: int = 0
    draws: int = 0
    instances: int = 0
    vertices: int = 0

    @property
    def upload_bytes(self) -> int:
        return (self.pose_bytes + self.local_bytes + self.instance_bytes + self.list_bytes
                + self.batch_bytes + self.look_bytes)


@dataclass(frozen=True)
class TextureSpec:
    """A texture to make: ``name``, ``size`` (width, height) in texels, ``format``
    (``"RGBA32F"`` or ``"R32I"``) and its first contents ``image`` (height, width,
    channels), or None for an empty texture."""

    name: str
    size: tuple
    format: str
    image: np.ndarray | None = None


@dataclass(frozen=True)
class SkinningWork:
    """One skinning-rows compute pass: ``count`` batch entries; ``image`` the whole
    texel rows of the batch texture that hold them, ``regions`` the same entries as
    exact rectangles (full rows, then the last part row); ``uniforms`` and ``groups``
    (work groups) of the dispatch."""

    count: int
    image: np.ndarray
    regions: list
    uniforms: dict
    groups: int


@dataclass(frozen=True)
class Draw:
    """One instanced call: the mesh of ``key`` = (body, LOD), ``instances``
    instances drawing ``agents`` agents (``vertices`` skinned vertices), ``uniforms``
    of the draw program."""

    key: tuple
    instances: int
    agents: int
    vertices: int
    uniforms: dict


@dataclass(frozen=True)
class Capture:
    """A vertex read-back: ``agents`` (n,) int64 of one body, the mesh ``key``,
    ``ids`` (their ids laid out like the draw list, an R32I region at the origin),
    and the capture pass's ``uniforms`` (no view: world positions)."""

    agents: np.ndarray
    key: tuple
    ids: TextureRegion
    uniforms: dict


class FramePlan:
    """The backend-independent part of drawing the crowd behind ``view``.

    Parameters
    ----------
    view : the crowd's :class:`~crowd_addon.core.runtime.frame_view.FrameView`.
    max_texture_size : the GPU's largest texture side in texels.
    max_int : integers an int texture write keeps exact (None: any int32); the
        agent count must stay below it.
    lod : False draws every agent with its full mesh (``crowd preview --lod off``: the
        judge of what the levels lose).
    copies : small meshes drawn as several copies an instance
        (:func:`~.proxies.copies_per_instance`, for a draw that reads its agents from
        textures); False: one agent an instance, every mesh (the agents fed as
        per-instance attributes, docs/gpu.md, *Two feeds*).
    """

    def __init__(self, view, max_texture_size: int, max_int: int | None = None,
                 lod: bool = True, copies: bool = True):
        lay = view.layout
        limit = int(max_texture_size)
        if max(lay.width, lay.height) > limit:
            raise CrowdError(f"pose texture {lay.width} x {lay.height} texels exceeds this "
                             f"GPU's max texture size {limit}; set "
                             f"CrowdConfig.max_texture_size = {limit}")
        if max_int is not None and view.agent_count >= max_int:
            raise CrowdError(f"this renderer draws at most {max_int - 1} agents, the crowd "
                             f"has {view.agent_count}")
        self.view, self.layout, self.max_texture_size = view, lay, limit
        self.copies = bool(copies)
        self.on_gpu = bool(view.skinning.on_gpu)
        #: the texture core's upload regions go to
        self.upload_target = "local" if self.on_gpu else "pose"
        #: ``u_pose_layout`` of every program reading the pose texture
        self.pose_layout = (lay.height, lay.row_texels, lay.max_offset, lay.streams)
        self.instances = InstanceData(view, limit)
        #: the looks' textures (:mod:`.look_data`)
        self.looks = LookData(view, limit)
        self.proxies = crowd_proxies(view)
        #: the largest agent scale: bounds and reaches grow with it
        self.max_scale = float(view.agents.scale.max(initial=1.0))
        self.lists = DrawLists(view.agent_body, [len(p) for p in self.proxies],
                               [tuple(self.max_scale * np.asarray(proxy_bounds(p[0].extent)))
                                if p else (0.0, 0.0) for p in self.proxies],
                               switch_pixels(view.config), min(4096, limit), lod=lod,
                               heights=agent_heights(self.proxies, view.agent_body,
                                                     view.agents.scale))
        self.batch_image = batch_image(lay.row_count) if self.on_gpu else None
        self._list_key = None

    # -------------------------------------------------------------------- start
    def take_initial_textures(self) -> list:
        """The textures to make (:class:`TextureSpec`), holding everything the CPU
        keeps now; core's pending upload regions are taken (they are in there). With
        GPU skinning the pose texture starts empty: the first :meth:`take_skinning`
        fills it."""
        lay, view = self.layout, self.view
        size = (lay.width, lay.height)
        image = view.texture_image()
        view.take_upload_regions()
        specs = [TextureSpec("pose", size, "RGBA32F", None if self.on_gpu else image)]
        if self.on_gpu:
            skeletons = skeleton_image(view.skeletons, lay.bones)
            specs += [TextureSpec("local", size, "RGBA32F", image),
                      TextureSpec("skeletons", skeletons.shape[1::-1], "RGBA32F", skeletons)]
        inst = self.instances
        specs += [TextureSpec("agents", (inst.width, inst.height), "RGBA32F",
                              inst.texture_image()),
                  TextureSpec("lists", (self.lists.width, self.lists.height), "R32I")]
        looks = self.looks
        specs += [TextureSpec("looks", (looks.width, looks.height), "RGBA32F",
                              looks.texture_image()),
                  TextureSpec("look_targets", looks.targets_image.shape[1::-1], "RGBA32F",
                              looks.targets_image),
                  TextureSpec("look_chains", looks.chains_image.shape[1::-1], "RGBA32F",
                              looks.chains_image),
                  TextureSpec("look_turns", looks.turns_size, "RGBA32F")]
        return specs

    def meshes(self) -> dict:
        """``{(body, lod): (ProxyBuffers, copies an instance)}`` of every level."""
        return {(k, lod): (buf, self._copies(buf))
                for k, levels in enumerate(self.proxies) for lod, buf in enumerate(levels)}

    def _copies(self, buf) -> int:
        return copies_per_instance(buf.vertex_count) if self.copies else 1

    @property
    def batch_size(self) -> tuple:
        """(width, height) of the skinning batch texture (GPU skinning)."""
        return self.batch_image.shape[1::-1]

    # ------------------------------------------------------------------- frame
    def pose_regions(self) -> tuple:
        """``u_pose_regions``: (first unique row, first slot row, ring slice, frame);
        the frame is what the looks are worked out at (gpu_shaders/look_at.glsl)."""
        return (self.layout.unique_base, self.layout.slot_base, self.view.ring_slice,
                int(self.view.frame))

    def take_pose_regions(self) -> list:
        """Core's upload regions since the last take, for :attr:`upload_target`."""
        return self.view.take_upload_regions()

    def take_instance_regions(self, max_regions: int | None) -> list:
        """Agent texture regions of the agents changed since the last take (the
        crowd's change log: nothing per agent when none changed); at most
        ``max_regions`` writes (None: one per run of changed agents). Agents that
        moved make the next render rebuild the draw lists."""
        regions = self.instances.update(self.view, max_regions)
        if self.instances.moved:
            self._list_key = None
        return regions

    def take_look_regions(self, max_regions: int | None) -> list:
        """Looks texture regions of the agents whose look state changed since the last
        take (nothing unless ``looks.version`` moved)."""
        return self.looks.update(self.view, max_regions)

    def look_turns(self) -> dict | None:
        """The uniforms of the look turns pass (:data:`~.programs.LOOK_TURNS`) for the
        current frame, or None when no agent looks then (nothing to work out)."""
        if not self.looks.active(self.view.frame):
            return None
        return {"u_pose_layout": self.pose_layout, "u_pose_regions": self.pose_regions(),
                "u_draw": (0, 0, 0, 0), "u_looks": (self.view.agent_count, 0, 0, 0)}

    def take_skinning(self) -> SkinningWork | None:
        """The skinning-rows pass for the rows pending in core (GPU skinning), or None
        when there is nothing to skin."""
        if not self.on_gpu:
            return None
        image = self.batch_image
        n, texel_rows = fill_batch(image, self.view.take_skinning_batch())
        if n == 0:
            return None
        width = image.shape[1]
        full, rest = divmod(n, width)           # whole texel rows, then the last part
        regions = [TextureRegion(0, 0, width, full, image[:full])] if full else []
        if rest:
            regions.append(TextureRegion(0, full, rest, 1, image[full:full + 1, :rest]))
        return SkinningWork(n, image[:texel_rows], regions,
                            {"u_pose_layout": self.pose_layout, "u_batch_count": n},
                            -(-n // SKIN_GROUP))

    def set_lod(self, on: bool):
        """Levels of detail on, or off (every agent its full mesh) from the next
        render."""
        self.lists.use_lod = bool(on)
        self._list_key = None

    def regroup(self, view_projection, pixels_high: int, cull: bool) -> list:
        """Draw list regions to write before drawing through ``view_projection`` (4, 4)
        into a viewport ``pixels_high`` pixels high; empty when neither the view, the
        height nor an agent moved since the last regrouping."""
        vp = np.asarray(view_projection, np.float64)
        key = (vp.tobytes(), int(pixels_high), bool(cull))
        if key == self._list_key:
            return []
        self._list_key = key
        return self.lists.rebuild(self.view.agents.position, vp, pixels_high, cull)

    def draws(self, view_projection, light) -> list:
        """One :class:`Draw` per (body, LOD) group of the current draw lists."""
        common = self._draw_uniforms(view_projection, light)
        return [self._draw(g, g.lod, common) for g in self.lists.groups]

    def caster_draws(self, view_projection, light) -> list:
        """The shadow map's crowd draws (:mod:`.shadows`), seen through the sun's
        ``view_projection``: the agents of the current draw lists, each group as its
        body's coarsest level, except those drawn at a far level (a card, or boxes
        per part: far away, a few pixels tall, their shadows would not show, and at
        65k agents they are nearly all of them)."""
        from ..core.meshes.bodies import is_card
        common = self._draw_uniforms(view_projection, light)
        out = []
        for g in self.lists.groups:
            levels = self.view.bodies[g.body].levels
            coarsest = len(levels) - 1
            if coarsest == 0 or not is_card(levels[g.lod]) and g.lod < coarsest:
                out.append(self._draw(g, coarsest, common))
        return out

    def _draw_uniforms(self, view_projection, light) -> dict:
        return {"u_pose_layout": self.pose_layout, "u_pose_regions": self.pose_regions(),
                "u_view_proj": gl_matrix(view_projection),
                "u_light": tuple(float(v) for v in light)}

    def _draw(self, group, lod: int, common: dict) -> Draw:
        """The instanced call drawing ``group``'s agents with level ``lod``."""
        buf = self.proxies[group.body][lod]
        copies = self._copies(buf)
        return Draw((group.body, lod), -(-group.count // copies), group.count,
                    group.count * buf.vertex_count,
                    {**common, "u_draw": (group.base, group.count, buf.vertex_count, copies)})

    def capture(self, agents, lod: int) -> Capture:
        """Check a vertex read-back request: ``agents`` (ids of one body: the same mesh
        variant and props) at ``lod``. Raises CrowdError naming what is wrong."""
        agents = np.asarray(agents, np.int64).reshape(-1)
        n = self.view.agent_count
        if agents.size == 0 or agents.min() < 0 or agents.max() >= n:
            raise CrowdError(f"skinned_positions: agent ids must be in 0..{n - 1}")
        body = np.unique(self.lists.agent_body[agents])
        if body.size != 1:
            names = [self.view.bodies[int(b)].name for b in body]
            raise CrowdError(f"skinned_positions: the agents have several bodies {names} "
                             "(skeletons, mesh variants or props); ask for one body's "
                             "agents at a time")
        k = int(body[0])
        if not 0 <= lod < len(self.proxies[k]):
            raise CrowdError(f"skinned_positions: body {self.view.bodies[k].name!r} has no "
                             f"LOD {lod}")
        width = min(agents.size, self.lists.width)
        ids = np.zeros(-(-agents.size // width) * width, np.int32)
        ids[:agents.size] = agents
        ids = ids.reshape(-1, width, 1)
        count = self.proxies[k][lod].vertex_count
        return Capture(agents, (k, int(lod)),
                       TextureRegion(0, 0, width, ids.shape[0], ids),
                       {"u_pose_layout": self.pose_layout,
                        "u_pose_regions": self.pose_regions(),
                        "u_view_proj": gl_matrix(np.eye(4)),
                        "u_draw": (0, int(agents.size), count, 1)})


def gl_matrix(m) -> tuple:
    """A (4, 4) matrix as 16 floats in column-major order (GLSL ``mat4``)."""
    return tuple(float(v) for v in np.asarray(m, np.float64).T.reshape(-1))
