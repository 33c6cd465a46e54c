"""Native Blender playback against the crowd: the comparison a Blender user would make.

Both sides play the fan's action (``sample_scenes/stadium.blend``, "FanRig" with its
skinned "FanBody", 23 bones, 590 vertices) on N characters on a 1 m grid, each
delayed by its own offset (the same offsets, uniform in 0..M-1 with M = 60, on both
sides), frame after frame through ``scene.frame_set``:

* native: N copies of FanRig (armature data shared, its own pose) with an NLA track
  holding one repeated strip of the action shifted by the offset, each with a copy of
  FanBody (mesh data shared) whose Armature modifier targets that copy. A frame is
  ``scene.frame_set(f)``: Blender's depsgraph evaluates every pose and every skinned
  mesh. Nothing is drawn (background mode has no viewport), so the native figure is
  a lower bound of what a viewport shows; a sanity check outside the timing makes
  sure the evaluated meshes really move and that the offsets really differ.
* crowd: the extension registered, the scene's Crowd settings authored as an animator
  would (FanRig, FanBody, one stream playing the action, an agent-source mesh of N
  vertices with an INT ``offset`` attribute), the preview started
  (``preview.start``: bake, ``Crowd(config, skinning="gpu")``). A frame is ``scene.frame_set(f)``
  (the preview's frame-change handler steps the crowd) and ``preview.draw_scene``
  (the viewport draw handler's own function: renderer sync + draw with whatever
  renderer the viewport would use here) into a bound ``gpu.types.GPUOffScreen``
  cleared first, then one pixel read back through Blender's framebuffer, which waits
  for the GPU to finish the frame. The camera frames every agent
  (``core.camera.frame_crowd``, so it backs off as N grows) and the crowd's own LODs
  apply (the Crowd settings' defaults: 25 % and 6 % of the triangles and the 8-vertex
  card, 590, 127, 32 and 8 vertices, from 30, 90 and 150 m in the 1080-pixel reference
  view, so at half those depths in a 540-pixel image): the agents per LOD and the
  vertices drawn are printed. A sanity check outside the timing makes sure the draw covered
  pixels and the poses change from frame to frame.

The scene's own objects (stands, FanRig playing its action, the mocap rig) are there
on both sides, and the extension is registered for both. ms per frame is the median
over the timed frames (after warm-up frames), best of ``--rounds`` rounds that
alternate native and crowd counts (the machine is shared: load only adds time). For
each side ``ms(N) = a + b N`` is fitted by least squares on relative errors (each
point weighted by 1/ms, so small and large N count alike), and for a frame budget of
33.3 ms (30 fps) and 100 ms (10 fps) the agents each side holds, ``(budget - a) /
b``, and their ratio crowd / native (target: 100x) are printed; so are the same read
off the measurements (where the measured curve first goes over the budget, linear
between the two points around it), since the costs are not quite linear in N. Then
one line of JSON. The crowd's CPU side alone (frame_set + step, no draw) is reported
too, against the native side that draws nothing either.

    .venv/bin/python benchmarks/vs_native.py [--quick] [--native 10,50,100,200,400,1000]
                                             [--crowd 100,1000,3000,10000,65000]
                                             [--frames 20] [--rounds 3] [--size 960x540]
                                             [--action idle_seated_a]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

BLEND = ROOT / "sample_scenes" / "stadium.blend"
RIG, BODY = "FanRig", "FanBody"
M = 60                       # frames of offset (the demo's max_offset)
SPACING = 1.0                # metres between agents on the grid
WARM = 3                     # frames before the timed ones
BUDGETS = {"33ms": 1000 / 30, "100ms": 100.0}
TARGET = 100.0


def fail(msg: str):
    print(f"vs_native: error: {msg}", file=sys.stderr, flush=True)
    sys.stdout.flush()
    os._exit(2)


# ------------------------------------------------------------------------ the scene
def open_stadium(blend: Path, action: str):
    """Open the stadium and return (scene, rig, body, action); fails loudly when the
    file or any object or action the benchmark needs is missing."""
    import bpy
    if not blend.is_file():
        fail(f"{blend} not found (build it: .venv/bin/python sample_scenes/build_stadium.py "
             f"--out {blend})")
    sys.stdout.flush()                     # Blender logs the load on fd 1: mute it
    saved, devnull = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend))
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
    rig, body = bpy.data.objects.get(RIG), bpy.data.objects.get(BODY)
    act = bpy.data.actions.get(action)
    if rig is None or rig.type != "ARMATURE":
        fail(f"{blend}: no armature object {RIG!r}")
    if body is None or body.type != "MESH":
        fail(f"{blend}: no mesh object {BODY!r}")
    if not any(m.type == "ARMATURE" and m.object == rig for m in body.modifiers):
        fail(f"{blend}: {BODY!r} has no Armature modifier on {RIG!r}")
    if act is None:
        fail(f"{blend}: no action {action!r} (have {sorted(a.name for a in bpy.data.actions)})")
    scene = bpy.context.scene
    scene.frame_set(scene.frame_start)
    return scene, rig, body, act


def grid(n: int) -> np.ndarray:
    side = int(np.ceil(np.sqrt(n)))
    ij = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n]
    return np.c_[ij * SPACING, np.zeros(n)]


def offsets(n: int) -> np.ndarray:
    return np.random.default_rng(11).integers(0, M, n)


def evaluated_vertices(obj, depsgraph) -> np.ndarray:
    mesh = obj.evaluated_get(depsgraph).data
    co = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


# --------------------------------------------------------------------------- native
def native_scene(blend, action, n):
    """The stadium with N characters playing ``action`` through NLA strips shifted by
    their offsets; returns (scene, bodies, offsets)."""
    import bpy
    scene, rig, body, act = open_stadium(blend, action)
    start, end = act.frame_range
    length = end - start
    coll = bpy.data.collections.new("NativeCrowd")
    scene.collection.children.link(coll)
    pos, off = grid(n), offsets(n)
    bodies = []
    for i in range(n):
        r = bpy.data.objects.new(f"NativeRig{i}", rig.data)
        r.location = pos[i]
        coll.objects.link(r)
        track = r.animation_data_create().nla_tracks.new()
        # action frame x plays at scene frame x + offset - length (so every timed
        # frame is inside the strip): pose(f) = action(f - offset), like an agent
        strip = track.strips.new(act.name, int(scene.frame_start - length + off[i]), act)
        strip.repeat = 8.0
        b = bpy.data.objects.new(f"NativeBody{i}", body.data)
        b.parent = r
        coll.objects.link(b)
        mod = b.modifiers.new("Armature", "ARMATURE")
        mod.object = r
        bodies.append(b)
    return scene, bodies, off


def native_check(scene, bodies, off):
    """The evaluated meshes move from frame to frame, and two characters with
    different offsets are in different poses (outside the timing)."""
    import bpy
    dg = bpy.context.evaluated_depsgraph_get()
    f = scene.frame_current
    a = evaluated_vertices(bodies[0], dg)
    scene.frame_set(f + 1)
    b = evaluated_vertices(bodies[0], dg)
    rest = np.array([v.co for v in bodies[0].data.vertices], np.float32)
    moved = float(np.abs(b - a).max())
    if moved < 1e-4 or float(np.abs(b - rest).max()) < 1e-3:
        fail(f"native: the skinned mesh is not evaluated (moved {moved:.2e} m in a frame)")
    other = next((i for i in range(1, len(bodies)) if off[i] != off[0]), None)
    if other is not None:
        c = evaluated_vertices(bodies[other], dg)
        if float(np.abs(c - b).max()) < 1e-4:
            fail("native: characters with different NLA offsets are in the same pose")
    return moved


def run_native(blend, action, n, frames):
    scene, bodies, off = native_scene(blend, action, n)
    f = scene.frame_start
    for _ in range(WARM):                         # relations, first evaluation
        f += 1
        scene.frame_set(f)
    native_check(scene, bodies, off)
    f = scene.frame_current
    times = []
    for _ in range(frames):
        f += 1
        t = time.perf_counter()
        scene.frame_set(f)
        times.append((time.perf_counter() - t) * 1e3)
    return {"ms": statistics.median(times), "frames": frames}


# ---------------------------------------------------------------------------- crowd
def crowd_scene(blend, action, n):
    """The stadium with the extension's Crowd settings for N agents playing
    ``action``, the preview started; returns (scene, preview)."""
    import bpy

    from crowd_addon.blender import preview
    scene, rig, body, act = open_stadium(blend, action)
    s = scene.crowd
    s.max_offset, s.seed = M, 1
    s.characters.clear()
    s.agent_sources.clear()
    fan = s.characters.add()
    fan.name, fan.armature, fan.body = "Fan", rig, body
    anim = fan.streams.add()
    anim.name = "play"
    node = anim.nodes.add()
    node.name, node.kind, node.action = "clip", "CLIP", act
    mesh = bpy.data.meshes.new("BenchAgents")
    mesh.vertices.add(n)
    mesh.vertices.foreach_set("co", grid(n).ravel())
    mesh.attributes.new("offset", "INT", "POINT").data.foreach_set("value", offsets(n))
    mesh.update()
    points = bpy.data.objects.new("BenchAgents", mesh)
    scene.collection.objects.link(points)
    src = s.agent_sources.add()
    src.name, src.object, src.mode = "grid", points, "VERTICES"
    src.heading_mode, src.heading = "FIXED", 0.0
    src.stream_mode, src.stream_name = "FIXED", "play"
    src.offset_mode, src.offset_attribute = "ATTRIBUTE", "offset"
    pv = preview.start(scene)
    if pv.crowd.agents.count != n:
        fail(f"crowd: {pv.crowd.agents.count} agents built from {n} points")
    if not np.array_equal(np.asarray(pv.crowd.config.agent_offset), offsets(n)):
        fail("crowd: the agents' offsets are not the ones written on the points")
    return scene, pv


def crowd_frame(scene, pv, f, offscreen, view, proj, full=False):
    """One frame: frame_set (the handler steps the crowd), the viewport draw into the
    bound offscreen, one pixel read back (waits for the GPU). Returns the ms of the
    two parts, and the whole image when ``full``."""
    import gpu

    from crowd_addon.blender import preview
    t0 = time.perf_counter()
    scene.frame_set(f)
    t1 = time.perf_counter()
    with offscreen.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        if not preview.draw_scene(scene, view, proj):
            fail(f"crowd: the viewport draw drew nothing: {pv.draw_error or pv.status()}")
        w, h = (offscreen.width, offscreen.height) if full else (1, 1)
        buf = fb.read_color(0, 0, w, h, 4, 0, "UBYTE")
    t2 = time.perf_counter()
    if pv.paused or pv.crowd.frame != f:
        fail(f"crowd: the preview did not follow frame {f}: {pv.status()}")
    image = None
    if full:
        buf.dimensions = w * h * 4
        image = np.frombuffer(buf, np.uint8).reshape(h, w, 4)
    return (t1 - t0) * 1e3, (t2 - t1) * 1e3, image


def run_crowd(blend, action, n, frames, size):
    import gpu

    from crowd_addon.blender import preview
    from crowd_addon.core.base.camera import frame_crowd
    scene, pv = crowd_scene(blend, action, n)
    cam = frame_crowd(pv.crowd, aspect=size[0] / size[1])
    view, proj = cam.view, cam.projection
    offscreen = gpu.types.GPUOffScreen(*size)
    try:
        f = scene.frame_current
        for _ in range(WARM):
            f += 1
            crowd_frame(scene, pv, f, offscreen, view, proj)
        # sanity (untimed): the draw covers pixels and the poses move
        before = pv.crowd.agent_poses()
        f += 1
        _, _, image = crowd_frame(scene, pv, f, offscreen, view, proj, full=True)
        covered = int((image[..., 3] > 0).sum())
        if covered < 50:
            fail(f"crowd: the draw covered {covered} pixels")
        if float(np.abs(pv.crowd.agent_poses() - before).max()) < 1e-6:
            fail("crowd: the agents' poses did not change from one frame to the next")
        step, draw = [], []
        for _ in range(frames):
            f += 1
            a, b, _ = crowd_frame(scene, pv, f, offscreen, view, proj)
            step.append(a)
            draw.append(b)
        r = pv.renderer
        renderer = type(r).__name__
        stats = getattr(r, "stats", None)
        lists = getattr(getattr(r, "plan", None), "lists", None)
        vertices = getattr(stats, "vertices", None)
        lods = {int(g.lod): int(g.count) for g in lists.groups} if lists is not None else None
    finally:
        offscreen.free()
        preview.stop(scene)
    total = [a + b for a, b in zip(step, draw)]
    return {"ms": statistics.median(total), "step_ms": statistics.median(step),
            "draw_ms": statistics.median(draw), "frames": frames, "pixels": covered,
            "renderer": renderer, "vertices": vertices, "lods": lods}


# -------------------------------------------------------------------------- fitting
def fit(points: dict) -> tuple[float, float, float]:
    """``ms = a + b N`` by least squares on relative errors; returns (a, b, the
    largest relative residual)."""
    n = np.array(list(points), np.float64)
    y = np.array(list(points.values()), np.float64)
    w = 1.0 / y
    (a, b), *_ = np.linalg.lstsq(np.c_[np.ones_like(n), n] * w[:, None], y * w, rcond=None)
    return float(a), float(b), float(np.abs((a + b * n) / y - 1).max())


def held(a: float, b: float, budget: float) -> float:
    """Agents that fit in ``budget`` ms per frame by the fit: 0 when even the fixed
    cost does not fit, ``inf`` when the fitted cost does not grow with N."""
    if a >= budget:
        return 0.0
    return float("inf") if b <= 0 else (budget - a) / b


def measured(points: dict, budget: float) -> tuple[float, str]:
    """Agents that fit in ``budget`` by the measurements themselves: N where the
    measured curve first goes over the budget, linear between the two points around
    it. Returns (N, "") inside the measured range, else (the nearest measured N, "<"
    or ">=")."""
    ns = sorted(points)
    if points[ns[0]] > budget:
        return float(ns[0]), "<"
    for lo, hi in zip(ns, ns[1:]):
        if points[hi] > budget:
            t = (budget - points[lo]) / (points[hi] - points[lo])
            return lo + t * (hi - lo), ""
    return float(ns[-1]), ">="


def show(value: float, bound: str = "", past: float | None = None) -> str:
    """``value`` agents; ``*`` marks a fit extrapolated past ``past`` (the largest N
    measured)."""
    if value == float("inf"):
        return "unbounded*"
    return f"{bound}{value:,.0f}" + ("*" if past is not None and value > past else "")


def ratio_of(crowd: tuple, native: tuple) -> tuple[float | None, str]:
    """crowd / native held agents, with the bound it is known to (">=", "<=", "")."""
    (c, cb), (n, nb) = crowd, native
    if n == 0 or c == float("inf") or nb == "<":
        return None, ""
    bound = {("", ""): "", (">=", ""): ">=", ("<", ""): "<", ("", ">="): "<=",
             ("<", ">="): "<"}.get((cb, nb))
    return (c / n, bound) if bound is not None else (None, "")


def ints(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        fail(f"expected comma-separated integers, got {text!r}")
    if len(values) < 2 or min(values) < 1:
        fail(f"need at least two agent counts >= 1 to fit a line, got {text!r}")
    return values


# ----------------------------------------------------------------------------- main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: fewer frames and smaller crowds (under a minute)")
    ap.add_argument("--native", help="native character counts (default 10,50,100,200,400,1000; "
                                     "quick 10,50,100,200)")
    ap.add_argument("--crowd", help="crowd agent counts (default 100,1000,3000,10000,30000,65000; "
                                    "quick 100,1000,5000)")
    ap.add_argument("--frames", type=int, help="timed frames per count (default 20, "
                                                "quick 6; at most 3 above 20,000 agents)")
    ap.add_argument("--rounds", type=int, help="interleaved rounds, best kept (default 3, "
                                                "quick 1)")
    ap.add_argument("--size", default="960x540", help="offscreen WIDTHxHEIGHT")
    ap.add_argument("--action", default="idle_seated_a", help="the FanRig action played")
    ap.add_argument("--blend", default=str(BLEND), help="the stadium .blend")
    args = ap.parse_args(argv)
    native_n = ints(args.native or ("10,50,100,200" if args.quick else "10,50,100,200,400,1000"))
    crowd_n = ints(args.crowd or ("100,1000,5000" if args.quick else
                                  "100,1000,3000,10000,30000,65000"))
    frames = args.frames if args.frames is not None else (6 if args.quick else 20)
    rounds = args.rounds if args.rounds is not None else (1 if args.quick else 3)
    if rounds < 1:
        fail(f"--rounds must be at least 1, got {rounds}")
    if frames < 1:
        fail(f"--frames must be at least 1, got {frames}")
    try:
        size = tuple(int(v) for v in args.size.lower().split("x"))
        assert len(size) == 2 and min(size) > 0
    except (ValueError, AssertionError):
        fail(f"--size must be WIDTHxHEIGHT, got {args.size!r}")
    blend = Path(args.blend)

    try:
        import bpy
        import gpu
    except ImportError as e:
        fail(f"Blender's bpy module is needed ({e}); run with .venv/bin/python")
    from crowd_addon.core.base.errors import CrowdError
    from crowd_addon.blender.headless_gpu import init_headless_gpu

    import crowd_addon
    if not hasattr(bpy.types.Scene, "crowd"):
        crowd_addon.register()             # for both sides: the same frame handlers
    try:
        init_headless_gpu()
    except CrowdError as e:
        fail(f"no GPU context for Blender here: {e}")
    device = f"{gpu.platform.backend_type_get()} {gpu.platform.renderer_get()}"
    print(f"vs_native: Blender {bpy.app.version_string}, action {args.action!r}, M={M}, "
          f"{os.cpu_count()} CPUs; crowd drawn by the viewport path on {device}, offscreen "
          f"{size[0]}x{size[1]}; best of {rounds} interleaved round(s) of the median of "
          f"{frames} frames (3 above 20,000 agents)", flush=True)
    native, crowd = {}, {}

    def keep(table, n, res):
        if n not in table or res["ms"] < table[n]["ms"]:
            table[n] = res

    try:
        for r in range(rounds):
            for i in range(max(len(native_n), len(crowd_n))):
                if i < len(native_n):
                    n = native_n[i]
                    res = run_native(blend, args.action, n, frames)
                    keep(native, n, res)
                    print(f"  [{r + 1}] native {n:>6} characters: {res['ms']:8.2f} ms/frame "
                          f"(frame_set)", flush=True)
                if i < len(crowd_n):
                    n = crowd_n[i]
                    res = run_crowd(blend, args.action, n,
                                    frames if n <= 20_000 else min(frames, 3), size)
                    keep(crowd, n, res)
                    print(f"  [{r + 1}] crowd  {n:>6} agents:     {res['ms']:8.2f} ms/frame "
                          f"(frame_set + step {res['step_ms']:.2f}, draw + finish "
                          f"{res['draw_ms']:.2f}; {res['vertices']:,} vertices drawn, agents "
                          f"per LOD {res['lods']}, {res['pixels']:,} pixels covered)",
                          flush=True)
    except CrowdError as e:
        fail(f"crowd: {e}")
    print("  best of the rounds, ms per frame:")
    for n, v in native.items():
        print(f"    native {n:>6}: {v['ms']:8.2f}")
    for n, v in crowd.items():
        print(f"    crowd  {n:>6}: {v['ms']:8.2f}  (frame_set + step {v['step_ms']:.2f}, "
              f"draw + finish {v['draw_ms']:.2f})")

    nf = fit({n: v["ms"] for n, v in native.items()})
    cf = fit({n: v["ms"] for n, v in crowd.items()})
    cpu = fit({n: v["step_ms"] for n, v in crowd.items()})
    print(f"  fit native: {nf[0]:.2f} ms + {nf[1] * 1e3:.2f} us x N "
          f"(worst point off by {nf[2]:.0%})")
    print(f"  fit crowd:  {cf[0]:.2f} ms + {cf[1] * 1e3:.3f} us x N "
          f"(worst point off by {cf[2]:.0%}); CPU side alone {cpu[0]:.2f} ms + "
          f"{cpu[1] * 1e3:.3f} us x N (off by {cpu[2]:.0%})")
    out = {"blender": bpy.app.version_string, "device": device, "size": list(size),
           "action": args.action, "max_offset": M, "rounds": rounds, "frames": frames,
           "native_ms": {str(n): round(v["ms"], 3) for n, v in native.items()},
           "crowd_ms": {str(n): round(v["ms"], 3) for n, v in crowd.items()},
           "crowd_step_ms": {str(n): round(v["step_ms"], 3) for n, v in crowd.items()},
           "crowd_draw_ms": {str(n): round(v["draw_ms"], 3) for n, v in crowd.items()},
           "crowd_vertices": {str(n): v["vertices"] for n, v in crowd.items()},
           "crowd_lods": {str(n): v["lods"] for n, v in crowd.items()},
           "renderer": next(iter(crowd.values()))["renderer"],
           "native_fit": {"a_ms": round(nf[0], 3), "b_us_per_agent": round(nf[1] * 1e3, 4)},
           "crowd_fit": {"a_ms": round(cf[0], 3), "b_us_per_agent": round(cf[1] * 1e3, 4)},
           "crowd_cpu_fit": {"a_ms": round(cpu[0], 3),
                             "b_us_per_agent": round(cpu[1] * 1e3, 4)}}
    pts = {"native": {n: v["ms"] for n, v in native.items()},
           "crowd": {n: v["ms"] for n, v in crowd.items()},
           "crowd_cpu_side": {n: v["step_ms"] for n, v in crowd.items()}}
    fits = {"native": nf, "crowd": cf, "crowd_cpu_side": cpu}
    print("  agents held at equal frame time (fit: a + b N; measured: where the measured "
          "curve crosses the budget, '>=' past the largest N measured)")
    print(f"  {'budget':>8} | {'':>9} | {'native':>9} | {'crowd':>9} | {'ratio':>7} | "
          f"{'crowd CPU side':>14} | {'ratio':>8}")
    for key, budget in BUDGETS.items():
        for how in ("fit", "measured"):
            # the CPU side barely grows with N: its fit would extrapolate to millions,
            # so it is only read off the measurements (a lower bound past 65k)
            sides = ("native", "crowd") if how == "fit" else tuple(pts)
            got = {side: ((held(*fits[side][:2], budget), "") if how == "fit"
                          else measured(pts[side], budget)) for side in sides}
            past = {side: (max(pts[side]) if how == "fit" else None) for side in sides}
            r, rb = ratio_of(got["crowd"], got["native"])
            rc, rcb = (ratio_of(got["crowd_cpu_side"], got["native"])
                       if "crowd_cpu_side" in got else (None, ""))
            cpu_held = (show(*got["crowd_cpu_side"]) if "crowd_cpu_side" in got else "-")
            print(f"  {budget:6.1f}ms | {how:>9} | {show(*got['native'], past['native']):>9} | "
                  f"{show(*got['crowd'], past['crowd']):>9} | "
                  f"{(rb + f'{r:.1f}x') if r is not None else '-':>7} | {cpu_held:>14} | "
                  f"{(rcb + f'{rc:.0f}x') if rc is not None else '-':>8}")
            suffix = "" if how == "fit" else "_measured"
            entry = {side: (None if v == float("inf") else round(v))
                     for side, (v, _) in got.items()}
            if how == "fit":
                entry["extrapolated"] = [side for side, (v, _) in got.items()
                                         if v > past[side]]
            else:
                entry["bounds"] = {side: b for side, (_, b) in got.items() if b}
                out[f"ratio_cpu_side_at_{key}{suffix}"] = None if rc is None else round(rc, 2)
                if rcb:
                    out[f"ratio_cpu_side_at_{key}{suffix}_bound"] = rcb
            out[f"agents_at_{key}{suffix}"] = entry
            out[f"ratio_at_{key}{suffix}"] = None if r is None else round(r, 2)
            if rb:
                out[f"ratio_at_{key}{suffix}_bound"] = rb
    print("  * extrapolated past the largest N measured (the fit, not a measurement)")
    r33 = out["ratio_at_33ms"]
    met = r33 is not None and r33 >= TARGET
    print(f"  ratio at 30 fps (fit): {r33 if r33 is None else f'{r33:.1f}x'}, "
          f"target {TARGET:.0f}x: {'met' if met else 'NOT met'}")
    out["target_ratio"], out["target_met"] = TARGET, met
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)       # skip Blender's GPU teardown at exit (see tests/conftest.py)
