"""GPU frame cost at the paper's configuration (Paduraru s.5), on whatever GL is here.

256 streams, M = 60, 800 transition slots kept busy (27 requests a frame, 30-frame
blends), skinned and blended by the compute shader (``Crowd(config, skinning="gpu")``:
the CPU uploads local poses, paper s.4.5),
82-bone ``core.synthetic`` humanoid with ``humanoid_mesh``; agents on a 0.9 m grid
seen by the camera that frames the whole crowd (``core.camera.frame_crowd``).
LODs on: ``CrowdConfig.add_mesh``'s defaults -- the mesh (2,058 vertices), 25 % and
6 % of its triangles (1,135 and 639), a box per body part and the boxes joined, each
kept only where its silhouette stays within a pixel of the full mesh's over the clips
(this humanoid's box level departs 2 px at the 30 px it would switch in at, so the 6 %
level is drawn down to 15 px, then the joined boxes, 168 vertices) -- switched by the
agents' projected height (``core.lod.DEFAULT_LOD_PIXELS``); LODs off: the full mesh for
every agent. Prints:

* skinned vertices per second on a 2,000-agent full-mesh frame: a plain
  instanced-skinning prototype (per-instance attributes, no agent texture, no draw
  lists; moderngl only), this renderer's draw alone, and the real work (pose and
  local-pose upload + instance updates + skinning-rows compute shader + agent gather
  + draw); and the vertex stage alone (rasterizer discard) of the prototype and the
  draw; with moderngl the same for a renderer reading its agents from the agent
  textures (``agent_feed="texture"``, as Blender's ``gpu`` module must;
  ``real_work_fraction_texture_feed``);
* ms per frame for 1k / 10k / 65k agents (``--agents`` for others, 1M say) with LODs
  on and off (GPU side: sync +
  draw + finish; ``Crowd.step`` on the CPU is shown apart, see core_frame.py);
* bytes uploaded per frame against the minimum for GPU skinning: the new local-pose
  slice and unique rows, the StartP row of each transition that started, 16 B of
  batch entry per row the GPU skins (slice, uniques, active slots), 48 B (three agent
  texels: placement, reference and scale, palette colours) per agent
  whose animation changed;
* whether 65,000 agents reach 10 frames per second with LODs;
* the scene pass: 65,000 agents with LODs drawn alone and inside a stadium-like scene
  (a ground plane and 24 terraces around the crowd, ~9k triangles, more than the
  demo's 5,436), interleaved; the extra time over the crowd alone (target <= 25%),
  and with the sun's shadows on as well;
* ``look_at_overhead``: 65,000 agents with LODs all looking at a target circling
  above the crowd (necks and heads turned by the look turns pass and the vertex stage)
  over none looking, same crowd and renderer, interleaved (target <= 1.10;
  ``--look-only`` prints just it);
* with the ``bpy`` module, the Render Crowd path (``crowd_addon.blender.render_crowd``:
  pose meshes skinned on the CPU and written into Blender meshes for F12) at 2,000 and
  65,000 agents through the camera above: the first sync (meshes made) and the
  median of the next frames, with the pose meshes in use; against the alternative of
  one mesh holding every agent's skinned vertices (all as cards);

then one line of JSON with the figures.

    .venv/bin/python benchmarks/gpu_frame.py [--quick] [--look-only] [--backend moderngl|blender]
                                             [--size 960x540] [--agents 1000,10000,65000]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig  # noqa: E402
from crowd_addon.core.runtime.look_at import LookRig, LookTarget  # noqa: E402
from crowd_addon.core.authoring.synthetic import humanoid, humanoid_mesh, periodic_clip  # noqa: E402
from crowd_addon.gpu.backends import BACKENDS, make_renderer  # noqa: E402
from crowd_addon.gpu.programs import AGENT_TEXELS  # noqa: E402
from crowd_addon.core.base.camera import frame_crowd  # noqa: E402
from crowd_addon.gpu.scene_geometry import SceneGeometry  # noqa: E402

STREAMS, M, SLOTS, BONES = 256, 60, 800, 82
BLEND = 30                                   # frames per transition
PER_FRAME = SLOTS // BLEND + 1               # requests a frame: keeps every slot busy
THROUGHPUT_AGENTS = 2_000


def build(agents: int, lods: bool, looks: bool = False) -> Crowd:
    """The benchmark crowd; ``looks``: with a neck-head look rig and a look target
    circling above the crowd (:func:`look_cost`)."""
    sk = humanoid("fan", BONES)
    cfg = CrowdConfig(max_offset=M, transition_slots=SLOTS, seed=1)
    if looks:
        side = 0.9 * np.sqrt(agents)
        t = np.arange(2_000.0)
        cfg.look_rigs["fan"] = LookRig(("neck", "head"), (0.4, 0.6))
        cfg.look_targets["ball"] = LookTarget(
            "ball", 0, np.c_[side / 2 + side * 0.4 * np.cos(t / 40),
                             side / 2 + side * 0.4 * np.sin(t / 40), 3 + np.sin(t / 9)])
    cfg.add_skeleton(sk)
    for i in range(12):
        cfg.add_clip(periodic_clip(sk, f"clip{i}", frames=90 + 20 * i, seed=i, amplitude=0.3))
    for s in range(STREAMS):
        cfg.add_stream(f"stream{s}", "fan", ClipPlayer(f"clip{s % 12}"))
    side = int(np.ceil(np.sqrt(agents)))
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:agents]
    rng = np.random.default_rng(2)
    cfg.add_agents(agents, positions=np.c_[grid * 0.9, np.zeros(agents)],
                   headings=rng.uniform(-0.4, 0.4, agents) - np.pi / 2)
    mesh = humanoid_mesh(sk)
    if lods:
        cfg.add_mesh(mesh)
    else:
        cfg.add_mesh(mesh, lods=())
    return Crowd(cfg, skinning="gpu")


# -------------------------------------------------------------------- measuring
def request(crowd, rng):
    """Keep the slots busy; returns how many transitions started now."""
    r = crowd.transition_to_streamed(rng.integers(0, crowd.agents.count, PER_FRAME),
                                     int(rng.integers(STREAMS)), BLEND)
    return int(r.started.size)


def frames(crowd, renderer, camera, count, rng, warm=40) -> dict:
    """``warm`` frames to fill the slots (no draw, then one draw), then ``count``
    measured frames."""
    if warm:
        for _ in range(warm):
            request(crowd, rng)
            crowd.step()
            renderer.sync()
        renderer.render(camera)
        renderer.finish()
    step, gpu, sent, minimum, vertices = [], [], [], [], 0
    row_bytes = crowd.view.layout.row_texels * 16
    for _ in range(count):
        started = request(crowd, rng)
        t0 = time.perf_counter()
        report = crowd.step()
        t1 = time.perf_counter()
        stats = renderer.sync()
        renderer.render(camera)
        renderer.finish()
        t2 = time.perf_counter()
        step.append((t1 - t0) * 1e3)
        gpu.append((t2 - t1) * 1e3)
        sent.append(stats.upload_bytes)
        started += report.transitions_started
        own = crowd.streams.count + crowd.uniques.count
        minimum.append((own + started) * row_bytes + 16 * (own + report.transitions_active)
                       + 16 * AGENT_TEXELS * (started + report.transitions_finished))
        vertices = renderer.stats.vertices
    return {"step_ms": statistics.median(step), "gpu_ms": statistics.median(gpu),
            "bytes": int(statistics.median(sent)), "minimum": int(statistics.median(minimum)),
            "vertices": vertices, "active": report.transitions_active,
            "lods": {g.lod: g.count for g in renderer.plan.lists.groups}}


PROTOTYPE_VS = """#version 430 core
layout(location = 0) in vec3 pos;
layout(location = 1) in vec3 nor;
layout(location = 2) in uvec4 bone_idx;
layout(location = 3) in vec4 bone_w;
layout(location = 4) in vec4 agent;          /* per instance: x, y, heading, pose row */
uniform mat4 u_view_proj;
uniform sampler2D pose_tex;
smooth out vec3 v_normal;
flat out vec3 v_color;
void main() {
  int row = int(agent.w);
  vec4 r0 = vec4(0.0), r1 = vec4(0.0), r2 = vec4(0.0);
  for (int i = 0; i < INFLUENCES; i++) {
    int x = 3 * int(bone_idx[i]);
    r0 += bone_w[i] * texelFetch(pose_tex, ivec2(x, row), 0);
    r1 += bone_w[i] * texelFetch(pose_tex, ivec2(x + 1, row), 0);
    r2 += bone_w[i] * texelFetch(pose_tex, ivec2(x + 2, row), 0);
  }
  vec4 p = vec4(pos, 1.0);
  vec3 q = vec3(dot(r0, p), dot(r1, p), dot(r2, p));
  vec3 n = vec3(dot(r0.xyz, nor), dot(r1.xyz, nor), dot(r2.xyz, nor));
  float c = cos(agent.z), s = sin(agent.z);
  v_normal = vec3(c * n.x - s * n.y, s * n.x + c * n.y, n.z);
  v_color = vec3(0.8);
  gl_Position = u_view_proj * vec4(c * q.x - s * q.y + agent.x, s * q.x + c * q.y + agent.y,
                                   q.z, 1.0);
}
"""
PROTOTYPE_FS = """#version 430 core
smooth in vec3 v_normal;
flat in vec3 v_color;
out vec4 frag_color;
void main() {
  vec3 n = normalize(gl_FrontFacing ? v_normal : -v_normal);
  frag_color = vec4(v_color * (0.35 + 0.65 * max(dot(n, normalize(vec3(0.4, -0.6, 0.8))),
                                                  0.0)), 1.0);
}
"""


class Prototype:
    """A plain instanced-skinning draw of the same agents, mesh and pose texture: one
    indexed instanced call, per-instance attributes, nothing else (moderngl)."""

    def __init__(self, ctx, crowd, camera, size):
        from crowd_addon.gpu.proxies import proxy_buffers
        buf = proxy_buffers(crowd.config.meshes["fan"][0])
        view = crowd.view
        lay = view.layout
        self.ctx, self.count = ctx, view.agent_count
        self.vertices = view.agent_count * buf.vertex_count
        self.pose = ctx.texture((lay.width, lay.height), 4, view.texture_image().tobytes(),
                                dtype="f4")
        rows = view.agent_rows_index() % lay.height
        inst = np.c_[crowd.agents.position[:, :2], crowd.agents.heading, rows].astype("f4")
        self.prog = ctx.program(vertex_shader=PROTOTYPE_VS.replace(
            "INFLUENCES", str(buf.influences)), fragment_shader=PROTOTYPE_FS)
        self.prog["u_view_proj"].write(np.asarray(camera.view_projection, "f4").T.tobytes())
        self.vbo = ctx.buffer(buf.interleaved().tobytes())
        self.ibo = ctx.buffer(buf.indices.tobytes())
        self.ivbo = ctx.buffer(inst.tobytes())
        self.vao = ctx.vertex_array(
            self.prog, [(self.vbo, "3f 3f 4u2 4f 4x", "pos", "nor", "bone_idx", "bone_w"),
                        (self.ivbo, "4f/i", "agent")], self.ibo, index_element_size=4)
        self.fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer(size, 4)],
                                   depth_attachment=ctx.depth_renderbuffer(size))

    def seconds(self) -> float:
        """One frame: clear, draw, wait."""
        self.fbo.use()
        self.fbo.clear(depth=1.0)
        self.ctx.enable(self.ctx.DEPTH_TEST)
        self.pose.use(0)
        t = time.perf_counter()
        self.vao.render(instances=self.count)
        self.ctx.finish()
        return time.perf_counter() - t

    def release(self):
        for obj in (self.vao, self.vbo, self.ibo, self.ivbo, self.prog, self.fbo, self.pose):
            obj.release()


def throughput(backend, size, rounds, rng) -> dict:
    """Skinned vertices per second on the full-mesh throughput frame, best of
    ``rounds`` interleaved rounds (the machine is shared: interleaving keeps the
    figures under the same load): the plain prototype, this renderer's draw alone,
    and one real frame (request, step, sync, draw; the rate counts sync + draw). With
    moderngl the renderer feeds its agents as per-instance attributes (the default) and
    a second one, of a second crowd driven alike, reads them from the agent textures
    (``agent_feed="texture"``, Blender's way): the ``_texture`` figures."""
    feeds = {"": {}}
    if backend == "moderngl":
        feeds["_texture"] = {"agent_feed": "texture"}
    sides = {}
    for suffix, kw in feeds.items():
        crowd = build(THROUGHPUT_AGENTS, lods=False)
        sides[suffix] = crowd, make_renderer(crowd.view, backend, size, **kw)
    crowd, r = sides[""]
    print(f"gpu_frame: {backend} on {r.device}, {size[0]}x{size[1]}, {STREAMS} streams, "
          f"M={M}, {SLOTS} slots busy, {BONES} bones, GPU skinning", flush=True)
    camera = frame_crowd(crowd, aspect=size[0] / size[1])
    for c, rr in sides.values():
        frames(c, rr, camera, 1, rng)                          # fill the slots, warm up
    ctx = getattr(r, "ctx", None)                 # a moderngl context: the prototype too
    proto = Prototype(ctx, crowd, camera, size) if ctx is not None else None
    best = dict.fromkeys(("prototype", "prototype_vertex_stage")
                         + tuple(k + suffix for suffix in sides
                                 for k in ("draw_only", "real_work", "draw_vertex_stage")), 0.0)

    def draw_rate(rr):
        t = time.perf_counter()
        rr.render(camera)
        rr.finish()
        return rr.stats.vertices / (time.perf_counter() - t)

    def keep(key, value):
        best[key] = max(best[key], value)

    for _ in range(rounds):
        if proto is not None:
            keep("prototype", proto.vertices / proto.seconds())
        for suffix, (c, rr) in sides.items():
            keep("draw_only" + suffix, draw_rate(rr))
            real = frames(c, rr, camera, 1, rng, warm=0)
            keep("real_work" + suffix, real["vertices"] / real["gpu_ms"] * 1e3)
        if proto is not None:          # the vertex stage alone: rasterizer discard
            ctx.enable(ctx.RASTERIZER_DISCARD)
            keep("prototype_vertex_stage", proto.vertices / proto.seconds())
            for suffix, (_, rr) in sides.items():
                keep("draw_vertex_stage" + suffix, draw_rate(rr))
            ctx.disable(ctx.RASTERIZER_DISCARD)
    if proto is not None:
        proto.release()
    device = r.device
    for _, rr in sides.values():
        rr.release()
    return best, device


def sizes(backend, size, quick, rng, counts=(1_000, 10_000, 65_000)) -> dict:
    """ms per frame for each agent count in ``counts``, LODs on and off (``quick``: no
    full-mesh frame from 65k agents up)."""
    n_on, n_off = (2, 1) if quick else (5, 2)
    table = {}
    for agents in counts:
        for lods in (True, False):
            if agents >= 65_000 and not lods and quick:
                continue
            t = time.perf_counter()
            crowd = build(agents, lods)
            r = make_renderer(crowd.view, backend, size)
            count = n_on if lods else max(1, n_off - (agents >= 65_000))
            res = frames(crowd, r, frame_crowd(crowd, aspect=size[0] / size[1]), count, rng)
            r.release()
            table[agents, lods] = res
            print(f"  {agents:>6} agents, LODs {'on ' if lods else 'off'}: "
                  f"{res['gpu_ms']:8.1f} ms/frame GPU side ({1e3 / res['gpu_ms']:5.1f} fps), "
                  f"step {res['step_ms']:5.1f} ms, {res['vertices']:>11,} skinned vertices, "
                  f"LOD counts {res['lods']} ({time.perf_counter() - t:.0f} s with the "
                  f"build)", flush=True)
    return table


def stadium_around(crowd, rows=24, segments=24) -> SceneGeometry:
    """A ground plane under the crowd and ``rows`` terraces (0.8 m tread, 0.45 m
    riser) around its box, ``segments`` quads a side: the stands of a stadium."""
    pos = crowd.agents.position
    lo, hi = pos[:, :2].min(0) - 3.0, pos[:, :2].max(0) + 3.0
    quads = []
    for r in range(rows):
        a, b = lo - 0.8 * r, hi + 0.8 * r               # the row's inner rectangle
        z0, z1 = 0.45 * r, 0.45 * (r + 1)
        corners = [(a[0], a[1]), (b[0], a[1]), (b[0], b[1]), (a[0], b[1])]
        for k in range(4):
            p, q = np.array(corners[k]), np.array(corners[(k + 1) % 4])
            out = np.array([q[1] - p[1], p[0] - q[0]]) / np.linalg.norm(q - p)
            for t in range(segments):
                u, v = p + (q - p) * t / segments, p + (q - p) * (t + 1) / segments
                riser = [(*u, z0), (*v, z0), (*v, z1), (*u, z1)]
                uo, vo = u + 0.8 * out, v + 0.8 * out
                tread = [(*u, z1), (*v, z1), (*vo, z1), (*uo, z1)]
                quads += [riser, tread]
    big = 4 * float(np.ptp(pos[:, :2], 0).max() + 100)
    quads.append([(-big, -big, -0.01), (big, -big, -0.01), (big, big, -0.01),
                  (-big, big, -0.01)])
    q = np.asarray(quads, np.float32)                       # (Q, 4, 3)
    tri = q[:, [0, 1, 2, 0, 2, 3]].reshape(-1, 3)
    n = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    colors = np.where(np.abs(n[:, 2:3]) > 0.5, (0.55, 0.55, 0.52), (0.45, 0.1, 0.1))
    colors[-1] = (0.12, 0.45, 0.12)
    return SceneGeometry(tri, np.repeat(n, 6, 0), np.repeat(colors, 6, 0).astype(np.float32))


def scene_cost(backend, size, rounds, rng) -> dict:
    """ms per frame at 65k agents with LODs, alone and inside :func:`stadium_around`,
    interleaved ``rounds`` times (median of each)."""
    crowd = build(65_000, True)
    r = make_renderer(crowd.view, backend, size)
    camera = frame_crowd(crowd, aspect=size[0] / size[1])
    stadium = stadium_around(crowd)
    frames(crowd, r, camera, 1, rng)                        # warm: fill the slots
    alone, inside, shaded = [], [], []
    for _ in range(rounds):
        r.set_scene(None)
        r.shadows = False
        alone.append(frames(crowd, r, camera, 2, rng, warm=0)["gpu_ms"])
        r.set_scene(stadium)
        inside.append(frames(crowd, r, camera, 2, rng, warm=0)["gpu_ms"])
        r.shadows = True
        shaded.append(frames(crowd, r, camera, 2, rng, warm=0)["gpu_ms"])
    r.release()
    res = {"alone_ms": statistics.median(alone), "scene_ms": statistics.median(inside),
           "shadows_ms": statistics.median(shaded), "triangles": stadium.triangle_count}
    res["overhead"] = res["scene_ms"] / res["alone_ms"] - 1
    res["shadow_overhead"] = res["shadows_ms"] / res["alone_ms"] - 1
    return res


def look_cost(backend, size, rounds, rng, agents=65_000) -> dict:
    """ms per frame at ``agents`` agents with LODs, every agent looking at a target
    circling above the crowd (a neck-head chain turned in the vertex stage) and none
    looking, same crowd and renderer, interleaved ``rounds`` times (median of each);
    the frame after each switch (the looks' texels going up) is not measured."""
    crowd = build(agents, True, looks=True)
    r = make_renderer(crowd.view, backend, size)
    camera = frame_crowd(crowd, aspect=size[0] / size[1])
    everyone = np.arange(crowd.agents.count)
    frames(crowd, r, camera, 1, rng)                        # warm: fill the slots
    on, off = [], []
    for _ in range(rounds):
        crowd.look_at(everyone, "ball", blend=0)
        on.append(frames(crowd, r, camera, 2, rng, warm=1)["gpu_ms"])
        assert (crowd.looks.weights(crowd.frame, everyone) == 1).all()
        crowd.look_away(everyone, blend=0)
        off.append(frames(crowd, r, camera, 2, rng, warm=1)["gpu_ms"])
        assert not crowd.looks.weights(crowd.frame, everyone).any()
    r.release()
    res = {"looking_ms": statistics.median(on), "still_ms": statistics.median(off)}
    res["overhead"] = res["looking_ms"] / res["still_ms"]
    return res


def render_crowd_cost(agents, size, rng, count=3) -> dict | None:
    """ms of ``render_crowd.sync`` for the crowd of :func:`build` (LODs on) seen by
    :func:`frame_crowd`'s camera as the scene camera; None without ``bpy``."""
    try:
        import bpy
        from mathutils import Vector
    except ImportError:
        return None
    from crowd_addon.blender import render_crowd
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    crowd = build(agents, True)
    view = frame_crowd(crowd, aspect=size[0] / size[1])
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.sensor_fit = "VERTICAL"
    cam.data.lens = cam.data.sensor_height / 2 / np.tan(view.fov_y / 2)
    cam.data.clip_start, cam.data.clip_end = view.near, view.far
    cam.location = Vector(view.eye)
    cam.rotation_euler = (Vector(view.target) - Vector(view.eye)).to_track_quat(
        "-Z", "Y").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    bpy.context.view_layer.update()
    try:
        for _ in range(40):                               # fill the slots
            request(crowd, rng)
            crowd.step()
        t = time.perf_counter()
        first = render_crowd.sync(scene, crowd)
        first_ms = (time.perf_counter() - t) * 1e3
        times = []
        for _ in range(count):
            request(crowd, rng)
            crowd.step()
            t = time.perf_counter()
            stats = render_crowd.sync(scene, crowd)
            times.append((time.perf_counter() - t) * 1e3)
        one_mesh_ms = one_mesh_cost(crowd)
    finally:
        render_crowd.remove(scene)
    return {"first_ms": first_ms, "ms": statistics.median(times), "poses": stats.poses,
            "first_poses": first.poses, "vertices": stats.vertices,
            "skinned": stats.skinned,
            "one_mesh_ms": one_mesh_ms}


def one_mesh_cost(crowd) -> float:
    """ms of the alternative to pose meshes: every agent's vertices skinned into one
    Blender mesh, every agent as its coarsest level (the card: the cheapest case for
    it), written with one ``foreach_set``."""
    import bpy
    from crowd_addon.core.base.skinning import skin_vertices
    mesh = crowd.config.meshes["fan"][-1]
    t = time.perf_counter()
    world = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights,
                          crowd.view.agent_rows(np.arange(crowd.agents.count)))
    target = bpy.data.meshes.new("one_mesh")
    target.vertices.add(world.shape[0] * world.shape[1])
    target.vertices.foreach_set("co", world.astype(np.float32).ravel())
    target.update()
    ms = (time.perf_counter() - t) * 1e3
    bpy.data.meshes.remove(target)
    return ms


# ------------------------------------------------------------------------- main
def report_looks(backend, size, rounds, rng) -> dict:
    lk = look_cost(backend, size, rounds, rng)
    print(f"  look_at_overhead at 65,000 agents with LODs, all looking at a moving "
          f"target over none: {lk['overhead']:.3f} ({lk['looking_ms']:.1f} ms against "
          f"{lk['still_ms']:.1f} ms; {'met' if lk['overhead'] <= 1.10 else 'NOT met'}, "
          f"target <= 1.10)", flush=True)
    return lk


def report_render_crowd(size, quick, rng) -> dict:
    rc = {}
    for agents in (2_000, 65_000):
        res = render_crowd_cost(agents, size, rng, 2 if quick else 3)
        if res is None:
            print("  Render Crowd: needs the bpy module, not measured")
            break
        rc[agents] = res
        print(f"  Render Crowd at {agents:,} agents: {res['ms']:,.0f} ms a frame for "
              f"{res['poses']:,} pose meshes, {res['skinned']:,} of them skinned again "
              f"({res['vertices']:,} vertices); first frame {res['first_ms']:,.0f} ms "
              f"(meshes made); one mesh of every agent instead, all as the coarsest "
              f"level: {res['one_mesh_ms']:,.0f} ms", flush=True)
    return rc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: fewer frames, no 65k full-mesh frame")
    ap.add_argument("--backend", choices=BACKENDS, default="moderngl")
    ap.add_argument("--size", default="960x540", help="image WIDTHxHEIGHT (default 960x540)")
    ap.add_argument("--agents", default="1000,10000,65000",
                    help="comma-separated agent counts of the ms-per-frame table; 65000 is "
                         "always among them (the upload and fps figures are read there); "
                         "default 1000,10000,65000")
    ap.add_argument("--look-only", action="store_true",
                    help="only the look-at overhead at 65,000 agents")
    ap.add_argument("--render-crowd-only", action="store_true",
                    help="only Render Crowd's frame at 2,000 and 65,000 agents (bpy)")
    args = ap.parse_args(argv)
    try:
        counts = sorted({int(v) for v in args.agents.split(",") if v.strip()} | {65_000})
    except ValueError:
        ap.error(f"--agents takes whole numbers separated by commas, got {args.agents!r}")
    if counts[0] < 1:
        ap.error(f"--agents: each count must be at least 1, got {counts[0]}")
    size = tuple(int(v) for v in args.size.lower().split("x"))
    backend = args.backend
    if backend == "blender":                  # bpy in background mode: wake its GPU
        from crowd_addon.blender.headless_gpu import init_headless_gpu
        init_headless_gpu()
    rng = np.random.default_rng(7)
    if args.look_only:
        lk = report_looks(backend, size, 2 if args.quick else 4, rng)
        print(json.dumps({"backend": backend, "size": list(size),
                          "look_at_overhead": round(lk["overhead"], 4),
                          "look_at_ms_65k": round(lk["looking_ms"], 2),
                          "no_look_ms_65k": round(lk["still_ms"], 2)}))
        return
    if args.render_crowd_only:
        rc = report_render_crowd(size, args.quick, rng)
        print(json.dumps({"render_crowd_ms": {str(a): round(v["ms"], 1)
                                              for a, v in rc.items()} or None,
                          "render_crowd_skinned": {str(a): v["skinned"]
                                                   for a, v in rc.items()} or None}))
        return
    best, device = throughput(backend, size, 3 if args.quick else 5, rng)
    proto, raw, real = best["prototype"] or None, best["draw_only"], best["real_work"]
    limit = proto or raw
    print(f"  skinned vertices/s, {THROUGHPUT_AGENTS:,} agents x 2,058 vertices, best of "
          f"interleaved rounds: " + (f"plain prototype {proto / 1e6:.1f} M, " if proto else "")
          + f"draw only {raw / 1e6:.1f} M, real work {real / 1e6:.1f} M = {real / limit:.0%} "
          f"of the {'prototype' if proto else 'draw only'} (target >= 80%)", flush=True)
    if proto:
        print(f"  vertex stage alone (rasterizer discard): plain prototype "
              f"{best['prototype_vertex_stage'] / 1e6:.1f} M, this renderer's draw "
              f"{best['draw_vertex_stage'] / 1e6:.1f} M skinned vertices/s", flush=True)
    texture = best.get("real_work_texture") or None
    if texture:
        print(f"  agents read from textures instead (agent_feed='texture', Blender's way): "
              f"draw only {best['draw_only_texture'] / 1e6:.1f} M, real work "
              f"{texture / 1e6:.1f} M = {texture / limit:.0%}, vertex stage "
              f"{best['draw_vertex_stage_texture'] / 1e6:.1f} M", flush=True)
    table = sizes(backend, size, args.quick, rng, counts)
    big = table[65_000, True]
    ratio = big["bytes"] / big["minimum"]
    print(f"  upload per frame at 65k: {big['bytes']:,} B, minimum {big['minimum']:,} B "
          f"(ratio {ratio:.3f}, target <= 1.1), {big['active']} active transitions")
    fps = 1e3 / big["gpu_ms"]
    fps_all = 1e3 / (big["gpu_ms"] + big["step_ms"])
    print(f"  65,000 agents with LODs: {fps:.1f} fps GPU side, {fps_all:.1f} fps with "
          f"Crowd.step: {'met' if fps >= 10 else 'NOT met'} (target >= 10 fps)")
    sc = scene_cost(backend, size, 2 if args.quick else 4, rng)
    print(f"  scene pass at 65k with LODs: {sc['alone_ms']:.1f} ms alone, "
          f"{sc['scene_ms']:.1f} ms inside a {sc['triangles']:,}-triangle stadium: "
          f"{sc['overhead']:+.1%} ({'met' if sc['overhead'] <= 0.25 else 'NOT met'}, "
          f"target <= +25%); with the sun's shadows {sc['shadows_ms']:.1f} ms "
          f"({sc['shadow_overhead']:+.1%})", flush=True)
    lk = report_looks(backend, size, 2 if args.quick else 4, rng)
    rc = report_render_crowd(size, args.quick, rng)
    print(json.dumps({
        "backend": backend, "device": device, "size": list(size),
        "prototype_vertices_per_s": proto, "draw_only_vertices_per_s": raw,
        "real_work_vertices_per_s": real, "real_work_fraction": real / limit,
        "vertex_stage_prototype_per_s": best["prototype_vertex_stage"] or None,
        "vertex_stage_draw_per_s": best["draw_vertex_stage"] or None,
        "real_work_fraction_texture_feed": texture / limit if texture else None,
        "vertex_stage_draw_texture_feed_per_s": best.get("draw_vertex_stage_texture") or None,
        "ms_per_frame": {f"{a}_{'lod' if lods else 'full'}": round(v["gpu_ms"], 2)
                         for (a, lods), v in table.items()},
        "step_ms_65k": round(big["step_ms"], 2),
        "bytes_per_frame_65k": big["bytes"], "bytes_minimum_65k": big["minimum"],
        "bytes_ratio": round(ratio, 4), "fps_65k_lod": round(fps, 2),
        "fps_65k_lod_with_step": round(fps_all, 2), "fps_target_met": fps >= 10,
        "scene_pass_ms_65k": round(sc["scene_ms"], 2),
        "scene_pass_overhead": round(sc["overhead"], 4),
        "shadows_ms_65k": round(sc["shadows_ms"], 2),
        "shadows_overhead": round(sc["shadow_overhead"], 4),
        "look_at_overhead": round(lk["overhead"], 4),
        "look_at_ms_65k": round(lk["looking_ms"], 2),
        "render_crowd_ms": {str(a): round(v["ms"], 1) for a, v in rc.items()} or None,
        "render_crowd_one_mesh_ms": {str(a): round(v["one_mesh_ms"], 1)
                                     for a, v in rc.items()} or None}))


if __name__ == "__main__":
    main()
