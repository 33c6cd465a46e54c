#!/usr/bin/env bash
# Prepare here what benchmarks/device_check.sh needs on a lent NVIDIA machine, which
# reaches no network (docs/performance.md, "On an NVIDIA GPU"):
#   .gl/    the GL and EGL loader libraries (Debian packages; the machine has the
#           NVIDIA driver but no loaders)
#   .whl/   moderngl and glcontext wheels for the machine's Python 3.12
#   .lodc/  the 65k stadium of benchmarks/lod_quality.py (built here with Blender)
# All three are git-ignored and travel with the run's `carry` (about 22 MB in all):
#   bash benchmarks/device_prepare.sh
#   then, with the device tool: run(command="bash benchmarks/device_check.sh",
#   carry=[".gl", ".whl", ".lodc"], timeout_s=540)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python

mkdir -p .gl /tmp/amd64/partial
o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64)
apt-get "${o[@]}" -qq update
(cd .gl && apt-get "${o[@]}" -qq download libegl1 libglvnd0 libopengl0 libgl1 libglx0 \
    libgles2)

mkdir -p .whl
versions=$("$PY" -c "import importlib.metadata as m; print(' '.join(f'{p}=={m.version(p)}' for p in ('moderngl', 'glcontext')))")
# shellcheck disable=SC2086
"$PY" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 -d .whl $versions

"$PY" benchmarks/lod_quality.py --cases stadium_65k_1920x1080 --cache .lodc
du -sh .gl .whl .lodc
