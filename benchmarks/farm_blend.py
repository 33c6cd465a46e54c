"""A .blend's chunked export against its single-process export (issue 33, item 5, for
the shots TDs actually send to a farm: a .blend, not a saved configuration).

Builds the demo's stadium (``sample_scenes/build_stadium.py``, ``--agents`` seats) and
authors its crowd and show into the .blend as ``crowd demo`` does, then exports
``--frames`` frames of it: once in this process (``crowd export --blend``), then in
four chunks on a local Dask cluster of two workers (``crowd export --blend --workers
2 --chunk-frames F/4``), snapshot pass and stitch included. Prints the CPU of each side
(this process, and the workers' once the cluster closed), the per-task CPU, and their
ratio ``chunk_cpu_overhead_blend``; every task of a .blend used to bake it again.
Ends with one JSON line.

    .venv/bin/python benchmarks/farm_blend.py [--agents 2000] [--frames 120]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)


def cpu_with_children() -> float:
    """CPU seconds of this process and of its children that ended."""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=2000)
    ap.add_argument("--frames", type=int, default=120)
    args = ap.parse_args(argv)
    from crowd_addon.blender.stadium import author_stadium
    from crowd_addon.farm.chunks import export_chunk
    from crowd_addon.farm.cluster import farm_export
    from crowd_addon.shot_source import ShotSource
    with tempfile.TemporaryDirectory() as tmp:
        blend = os.path.join(tmp, "stadium.blend")
        run = subprocess.run([sys.executable, os.path.join(ROOT, "sample_scenes",
                                                           "build_stadium.py"),
                              "--out", blend, "--seats", str(args.agents), "--quiet"],
                             capture_output=True, text=True)
        if run.returncode:
            sys.exit(run.stderr[-2000:])
        author_stadium(blend, args.frames)
        source = ShotSource(blend=blend)
        span = (1, args.frames)
        cpu = time.process_time()
        _, single = export_chunk(source, span, os.path.join(tmp, "single", "shot.usdc"))
        cpu_single = time.process_time() - cpu
        cpu = cpu_with_children()
        result = farm_export(source, os.path.join(tmp, "farm", "shot.usdc"), span,
                             workers=2, chunk_frames=-(-args.frames // 4))
        cpu_farm = cpu_with_children() - cpu
    tasks = {k: round(v, 2) for k, v in result.cpu.items()}
    overhead = cpu_farm / cpu_single
    print(f"{args.agents:,} agents x {args.frames} frames of the stadium .blend: one "
          f"process {cpu_single:.1f} s of CPU; 4 chunks on 2 workers {cpu_farm:.1f} s "
          f"(tasks: {tasks}); chunk_cpu_overhead_blend {overhead:.2f} (target <= 1.3)")
    print(json.dumps({"benchmark": "farm_blend", "agents": args.agents,
                      "frames": args.frames, "cpu_single_s": round(cpu_single, 2),
                      "cpu_farm_s": round(cpu_farm, 2), "cpu_tasks": tasks,
                      "chunk_cpu_overhead_blend": round(overhead, 3)}))


if __name__ == "__main__":
    main()
