#!/usr/bin/env bash
# The GPU figures the open issues ask for, on a lent NVIDIA machine, in one run of a
# few minutes (docs/performance.md, "On an NVIDIA GPU"): the 65k stadium's frame with
# and without LODs (`lod_speedup_65k`, issue 36), and benchmarks/gpu_frame.py at
# 65,000 and 1,000,000 agents (real work against the plain prototype, frame times,
# `look_at_overhead` of issue 34). Prepared here by benchmarks/device_prepare.sh;
# run there as
#   run(command="bash benchmarks/device_check.sh", carry=[".gl", ".whl", ".lodc"],
#       timeout_s=540)
# Logs go to $OUT (the device tool's folder) or benchmarks/out/device; the last line
# is one JSON object of the figures. Without an NVIDIA GPU it rehearses here on this
# machine's GL (FRAME_ARGS="--quick --agents 2000" keeps that short).
set -uo pipefail
cd "$(dirname "$0")/.."
out=${OUT:-benchmarks/out/device}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
if command -v nvidia-smi > /dev/null; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl || exit 1
    export PYTHONPATH=/tmp/site
    py=python3
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader \
        | tee "$out/device.txt"
else                                  # a rehearsal here: this machine's GL, as it is
    py=.venv/bin/python
    echo "no NVIDIA GPU here: a rehearsal with $py" | tee "$out/device.txt"
fi

step() {
    local name=$1
    shift
    echo "== $name: $py $*"
    timeout 300 "$py" "$@" 2>&1 | tee "$out/$name.log"
}
step lod benchmarks/lod_quality.py --cases stadium_65k_1920x1080 --cache .lodc
# shellcheck disable=SC2086
step frame benchmarks/gpu_frame.py ${FRAME_ARGS:---agents 65000,1000000}

"$py" - "$out" <<'PY'
import json, pathlib, sys
out = pathlib.Path(sys.argv[1])
figures = {"device": (out / "device.txt").read_text().strip()}
for name in ("lod", "frame"):
    lines = [l for l in (out / f"{name}.log").read_text().splitlines() if l.startswith("{")]
    if lines:
        figures[name] = json.loads(lines[-1])
keep = {"lod": ("lod_speedup_65k", "frame_ms_65k", "lod_image_error_max"),
        "frame": ("device", "real_work_fraction", "real_work_fraction_texture_feed",
                  "ms_per_frame", "look_at_overhead",
                  "look_at_ms_65k", "fps_65k_lod")}
print(json.dumps({"device": figures["device"],
                  **{f"{n}.{k}": figures.get(n, {}).get(k) for n, ks in keep.items()
                     for k in ks}}))
PY
