"""What the levels of detail lose, measured against the same frame at full detail.

Each case renders one frame twice with the moderngl backend, with the crowd's levels
of detail (the default) and with every agent drawn with its full mesh (``crowd preview
--lod off``), and compares them:

- ``lod_image_error[case]``: the mean absolute difference, over the pixels any agent
  covers in either frame (drawn again without the scene, on a transparent background:
  the alpha channel), of the two frames, both Gaussian-blurred with sigma 1 px, in
  sRGB 0..1 units (the mean over red, green and blue).
- ``lod_speedup_65k``: the 65k stadium's frame time (render + finish) with ``--lod off``
  over the default's.

Cases:

- ``demo_2k_960x540``, ``demo_2k_480x270``: the demo's stadium at 2,000 seats
  (``sample_scenes/build_stadium.py``, ``crowd_addon.blender.stadium.author_stadium``
  as ``crowd demo`` does), its scene, sun, shadows and camera, at the home goal's cheer
  (12 frames after the cue: arms up);
- ``boxy_480x270``: a boxy character built here (boxes for torso, head, arms, legs on
  11 bones, each box bound to its bone) cheering, 400 of them from 4 to 60 m;
- ``stadium_65k_1920x1080``: the stadium at 65,000 seats, as the first cases.

    .venv/bin/python benchmarks/lod_quality.py [--cases demo_2k_960x540,...] [--out DIR]
        [--cache DIR]

``--out`` writes each case's two frames and the blurred difference as PNGs;
``--cache`` keeps the built stadiums (config, camera, scene) between runs. Prints a
table and ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

CASES = ("demo_2k_960x540", "demo_2k_480x270", "boxy_480x270", "stadium_65k_1920x1080")
BEAT = 12                  # frames after the home goal's cue: the cheer, arms up
SIGMA = 1.0


# ------------------------------------------------------------------ the measure
def blur(image: np.ndarray, sigma: float = SIGMA) -> np.ndarray:
    """``image`` (H, W, C) float blurred by a Gaussian of ``sigma`` pixels (separable,
    edges repeated)."""
    r = int(np.ceil(3 * sigma))
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    k /= k.sum()
    out = image.astype(np.float64)
    for axis in (0, 1):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (r, r)
        p = np.pad(out, pad, mode="edge")
        n = out.shape[axis]
        out = sum(w * np.take(p, np.arange(i, i + n), axis=axis) for i, w in enumerate(k))
    return out


def image_error(lod_image, full_image, mask) -> float:
    """Mean absolute difference of the blurred sRGB images (uint8 RGBA) over ``mask``."""
    if not mask.any():
        return 0.0
    a = blur(lod_image[..., :3] / 255.0)
    b = blur(full_image[..., :3] / 255.0)
    return float(np.abs(a - b)[mask].mean())


# ------------------------------------------------------------------- the cases
def _build_stadium(seats: int, size, cache: Path | None):
    """``(config, camera, scene, light)`` of the stadium with ``seats`` seats, its
    camera framed for ``size``; from ``cache`` when it holds them."""
    key = cache / f"stadium_{seats}_{size[0]}x{size[1]}.pickle" if cache else None
    if key is not None and key.is_file():
        try:
            with open(key, "rb") as f:
                return pickle.load(f)
        except Exception as e:  # noqa: BLE001 - a cache of older code: build it again
            print(f"(cache {key.name} not read: {e}; building again)", file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        blend = Path(tmp) / "stadium.blend"
        run = subprocess.run([sys.executable, str(ROOT / "sample_scenes" / "build_stadium.py"),
                              "--out", str(blend), "--seats", str(seats), "--quiet"],
                             capture_output=True, text=True)
        if run.returncode != 0:
            raise SystemExit(f"building the stadium failed:\n{run.stderr[-2000:]}")
        from crowd_addon.blender.stadium import author_stadium
        st = author_stadium(blend, 240, size)
    made = (st.config, st.camera, st.scene, st.light)
    if key is not None:
        key.parent.mkdir(parents=True, exist_ok=True)
        try:
            with open(key, "wb") as f:
                pickle.dump(made, f)
        except Exception as e:  # noqa: BLE001 - a cache that cannot be kept is no error
            key.unlink(missing_ok=True)
            print(f"(not cached: {e})", file=sys.stderr)
    return made


def _cheer_frame(crowd) -> int:
    at = {c["name"]: c["frame"] for c in crowd.show.describe()} if crowd.show else {}
    return at.get("goal home", crowd.frame) + BEAT


BOXY_BONES = ("hips", "torso", "head", "upper_arm.L", "forearm.L", "upper_arm.R",
              "forearm.R", "thigh.L", "shin.L", "thigh.R", "shin.R")


def boxy_character(name="boxy"):
    """A boxy character: 11 bones, a box per body part bound rigidly to its bone
    (each face split 4 x 4, ~2,100 triangles), shirt, skin and trousers looks; and
    its cheer (arms up and down, a little hop)."""
    from crowd_addon.core.base import pose as sqt
    from crowd_addon.core.anim.clip import Clip
    from crowd_addon.core.meshes.mesh import Look, ProxyMesh
    from crowd_addon.core.base.skeleton import Skeleton

    parents = [-1, 0, 1, 1, 3, 1, 5, 0, 7, 0, 9]
    heads = np.array([[0, 0, 0.95], [0, 0, 1.0], [0, 0, 1.52], [0.24, 0, 1.45],
                      [0.24, 0, 1.17], [-0.24, 0, 1.45], [-0.24, 0, 1.17], [0.1, 0, 0.92],
                      [0.1, 0, 0.5], [-0.1, 0, 0.92], [-0.1, 0, 0.5]])
    bind = np.zeros((11, 10))
    bind[:, 0:3] = 1.0
    bind[:, 3] = 1.0
    for b, p in enumerate(parents):
        bind[b, 7:10] = heads[b] - (heads[p] if p >= 0 else 0.0)
    sk = Skeleton(name, BOXY_BONES, np.array(parents), bind)
    # boxes: (bone, min corner, max corner, look)
    boxes = [(1, (-0.19, -0.11, 0.98), (0.19, 0.11, 1.48), 0),      # torso: shirt
             (0, (-0.18, -0.1, 0.86), (0.18, 0.1, 0.99), 2),       # hips: trousers
             (2, (-0.1, -0.11, 1.5), (0.1, 0.11, 1.75), 1),        # head: skin
             (3, (0.2, -0.055, 1.16), (0.3, 0.055, 1.46), 0), (4, (0.2, -0.05, 0.9),
                                                               (0.29, 0.05, 1.17), 1),
             (5, (-0.3, -0.055, 1.16), (-0.2, 0.055, 1.46), 0), (6, (-0.29, -0.05, 0.9),
                                                                 (-0.2, 0.05, 1.17), 1),
             (7, (0.03, -0.07, 0.5), (0.17, 0.07, 0.9), 2), (8, (0.04, -0.06, 0.0),
                                                             (0.16, 0.08, 0.5), 2),
             (9, (-0.17, -0.07, 0.5), (-0.03, 0.07, 0.9), 2), (10, (-0.16, -0.06, 0.0),
                                                               (-0.04, 0.08, 0.5), 2)]
    pos, tri, bone, mat = [], [], [], []
    n = 4
    g = np.linspace(0.0, 1.0, n + 1)
    for b, lo, hi, look in boxes:
        lo, hi = np.array(lo), np.array(hi)
        for axis in range(3):
            u, v = [a for a in range(3) if a != axis]
            for side in (0, 1):
                base = sum(len(p) for p in pos)
                uu, vv = np.meshgrid(g, g, indexing="ij")
                q = np.zeros((n + 1, n + 1, 3))
                q[..., axis] = lo[axis] if side == 0 else hi[axis]
                q[..., u] = lo[u] + uu * (hi[u] - lo[u])
                q[..., v] = lo[v] + vv * (hi[v] - lo[v])
                pos.append(q.reshape(-1, 3))
                i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None]
                a, bq, c, d = i, i + n + 1, i + n + 2, i + 1
                t = np.stack([np.stack([a, bq, c], -1), np.stack([a, c, d], -1)], 2)
                t = t.reshape(-1, 3)
                # outward: the normal of (u, v) is +axis for an even permutation
                flip = (side == 0) == ((u, v) in ((0, 1), (1, 2), (2, 0)))
                tri.append(base + (t[:, ::-1] if flip else t))
                bone.append(np.full((n + 1) ** 2, b))
                mat.append(np.full(2 * n * n, look))
    pos = np.concatenate(pos)
    looks = (Look("shirt", (0.7, 0.1, 0.1, 1.0)), Look("skin", (0.8, 0.55, 0.4, 1.0)),
             Look("trousers", (0.1, 0.12, 0.25, 1.0)))
    mesh = ProxyMesh.from_influences(f"{name}_body", name, pos, np.concatenate(tri),
                                     np.concatenate(bone)[:, None], np.ones((pos.shape[0], 1)),
                                     bone_count=11, material=np.concatenate(mat),
                                     looks=looks)
    frames = 31
    t = np.arange(frames) / (frames - 1)
    lift = 0.15 + 2.65 * (0.5 - 0.5 * np.cos(2 * np.pi * t))       # radians
    keys = np.broadcast_to(bind, (frames, 11, 10)).copy()
    for b, s in ((3, -1.0), (5, 1.0)):           # upper arms swing out and up (about Y)
        keys[:, b, 3] = np.cos(s * lift / 2)
        keys[:, b, 5] = np.sin(s * lift / 2)
    for b, s in ((4, -1.0), (6, 1.0)):           # forearms bend a little
        keys[:, b, 3] = np.cos(s * 0.3 * lift / 2)
        keys[:, b, 5] = np.sin(s * 0.3 * lift / 2)
    keys[:, 0, 9] += 0.08 * np.sin(np.pi * t) ** 2
    keys[-1] = keys[0]
    del sqt
    return sk, mesh, Clip("cheer", keys, bone_names=BOXY_BONES)


def _boxy_case(size):
    from crowd_addon.core.authoring.config import CrowdConfig
    from crowd_addon.core.anim.controllers import ClipPlayer
    from crowd_addon.core.base.camera import Camera

    sk, mesh, clip = boxy_character()
    cfg = CrowdConfig(max_offset=30, transition_slots=0)
    cfg.add_skeleton(sk)
    cfg.add_clip(clip)
    cfg.add_stream("cheer", sk.name, ClipPlayer("cheer"))
    rows, cols = 20, 20
    depth = 4.0 + 56.0 * (np.arange(rows) / (rows - 1)) ** 1.3
    x, y = np.meshgrid(np.linspace(-1, 1, cols), depth)
    x = x * (1.0 + 0.45 * y)                     # the rows widen with the view
    n = rows * cols
    rng = np.random.default_rng(7)
    cfg.add_agents(n, streams=0, offsets=rng.integers(0, 30, n),
                   positions=np.c_[x.ravel(), y.ravel(), np.zeros(n)],
                   headings=np.full(n, np.pi) + rng.normal(0, 0.2, n),
                   colors=rng.uniform(0.2, 1.0, (n, 3)))
    cfg.add_mesh(mesh)
    camera = Camera((0.0, -4.0, 9.0), (0.0, 24.0, 0.0), aspect=size[0] / size[1])
    return cfg, camera, None, None, 15


def measure(cfg, camera, scene, light, size, frame=None, out=None, name="", timing=False):
    """``(error, default seconds, off seconds, levels used)`` of one frame."""
    from crowd_addon.core.shots.crowd import Crowd
    from crowd_addon.gpu.backends import make_renderer

    crowd = Crowd(cfg, skinning="gpu")
    options = {"shadows": scene is not None, "samples": 4}
    if light is not None:
        options["light"] = light
    r = make_renderer(crowd.view, "moderngl", size, **options)
    try:
        target = _cheer_frame(crowd) if frame is None else crowd.frame + frame
        while crowd.frame < target:
            crowd.step()
            r.sync()
        r.set_scene(scene)
        images, seconds = {}, {}
        for on in (True, False):
            r.set_lod(on)
            r.render(camera)                          # lists, shadow map: warm
            r.finish()
            reps = 2 if (timing and on) else 1
            t = time.perf_counter()
            for _ in range(reps):
                r.render(camera)
                r.finish()
            seconds[on] = (time.perf_counter() - t) / reps
            images[on] = r.read_image()
            if on:
                used = np.bincount(r.plan.lists.lod[r.plan.lists.lod >= 0], minlength=4)
        r.set_scene(None)
        mask = np.zeros(images[True].shape[:2], bool)
        for on in (True, False):
            r.set_lod(on)
            r.render(camera, clear=(0.0, 0.0, 0.0, 0.0))
            mask |= r.read_image()[..., 3] > 0
    finally:
        r.release()
    err = image_error(images[True], images[False], mask)
    if out is not None:
        from crowd_addon.gpu.png import write_png
        out.mkdir(parents=True, exist_ok=True)
        write_png(out / f"{name}_lod.png", images[True][..., :3])
        write_png(out / f"{name}_full.png", images[False][..., :3])
        d = np.abs(blur(images[True][..., :3] / 255.0) - blur(images[False][..., :3] / 255.0))
        write_png(out / f"{name}_diff.png",
                  (np.clip(d * 4, 0, 1) * 255 * mask[..., None]).astype(np.uint8))
    return err, seconds[True], seconds[False], used, float(mask.mean())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--cache", type=Path, default=None)
    args = ap.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    unknown = set(cases) - set(CASES)
    if unknown:
        raise SystemExit(f"unknown cases {sorted(unknown)} (known: {', '.join(CASES)})")
    errors, result = {}, {}
    print(f"{'case':<24} {'error':>8} {'covered':>8} {'lod ms':>9} {'off ms':>10}  levels used")
    for case in cases:
        size = tuple(int(v) for v in case.rsplit("_", 1)[1].split("x"))
        if case.startswith("boxy"):
            cfg, camera, scene, light, frame = _boxy_case(size)
        else:
            seats = 65000 if "65k" in case else 2000
            cfg, camera, scene, light = _build_stadium(seats, size, args.cache)
            frame = None
        err, lod_s, off_s, used, covered = measure(cfg, camera, scene, light, size, frame,
                                                   args.out, case, timing="65k" in case)
        errors[case] = round(err, 4)
        print(f"{case:<24} {err:8.4f} {covered:8.3f} {lod_s * 1e3:9.1f} {off_s * 1e3:10.1f}  "
              f"{used.tolist()}", flush=True)
        if "65k" in case:
            result["lod_speedup_65k"] = round(off_s / lod_s, 2)
            result["frame_ms_65k"] = {"lod": round(lod_s * 1e3, 1),
                                      "off": round(off_s * 1e3, 1)}
    if "lod_speedup_65k" in result:
        print(f"lod_speedup_65k: {result['lod_speedup_65k']}")
    print(json.dumps({"lod_image_error": errors,
                      "lod_image_error_max": max(errors.values(), default=0.0), **result}))


if __name__ == "__main__":
    main()
