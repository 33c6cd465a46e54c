"""Build the Blender extension zip with its bundled wheels (``crowd build-extension``).

Blender extensions cannot ``pip install`` at run time, so the zip carries the wheels
of moderngl and glcontext for every platform and Python that Blender ships: Python
3.11 (Blender 4.2-5.0) and 3.13 (Blender 5.1+) on ``linux-x64``, ``windows-x64`` and
``macos-arm64`` (moderngl 5.13 publishes no other desktop wheels). The wheels are
downloaded with ``pip download`` into a cache directory once; the extension is built
in a staging copy of the sources by Blender's own extension tool (``blender_ext.py
build``, shipped inside the ``bpy`` module), whose manifest gains the ``wheels`` and
``platforms`` fields, so the repository's ``blender_manifest.toml`` stays
platform-neutral. The zip is written to a temporary name and renamed when complete;
a failed build leaves no output folder it created.
"""

from __future__ import annotations

import glob
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile

from .core.base.errors import CrowdError
from .core.base.files import folders_made, write_atomic

__all__ = ["WHEELS", "PLATFORMS", "PYTHONS", "fetch_wheels", "build_extension",
           "extension_tool", "REPO_ROOT"]

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WHEELS = ("moderngl==5.13.0", "glcontext==3.1.0")
PYTHONS = ("3.11", "3.13")
# Blender platform -> pip platform tags to try (newest manylinux tags accepted too)
PLATFORMS = {
    "linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64",
                  "manylinux_2_5_x86_64", "manylinux1_x86_64"),
    "windows-x64": ("win_amd64",),
    "macos-arm64": ("macosx_11_0_arm64",),
}
# what goes into the extension besides the manifest and wheels
_SOURCES = ("__init__.py", "crowd_addon", "gpu_shaders", "LICENSE", "README.md")


def extension_tool() -> str:
    """Path of Blender's ``blender_ext.py`` inside the installed ``bpy`` module."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise CrowdError("build-extension needs the bpy module (pip install bpy==5.0.1) for "
                         "Blender's extension tool")
    root = list(spec.submodule_search_locations)[0]
    found = sorted(glob.glob(os.path.join(root, "*", "scripts", "addons_core", "bl_pkg",
                                          "cli", "blender_ext.py")))
    if not found:
        raise CrowdError(f"Blender's extension tool (blender_ext.py) is not in {root}")
    return found[-1]


def fetch_wheels(cache_dir, progress=print, download=True) -> list:
    """Download the wheels for every (platform, Python) into ``cache_dir`` (kept
    between builds); returns their paths. With ``download`` False nothing is
    downloaded: the folder must hold them all. Raises CrowdError naming what is
    missing."""
    if download:
        os.makedirs(cache_dir, exist_ok=True)
    elif not os.path.isdir(cache_dir):
        raise CrowdError(f"--wheels {cache_dir}: no such folder")
    for platform, tags in PLATFORMS.items():
        for py in PYTHONS:
            for req in WHEELS:
                name = req.split("==")[0]
                abi = "cp" + py.replace(".", "")
                have = [w for w in glob.glob(os.path.join(cache_dir, f"{name}-*-{abi}-*.whl"))
                        if any(t in os.path.basename(w) for t in tags)]
                if have:
                    continue
                if not download:
                    raise CrowdError(f"--wheels {cache_dir}: no {req} wheel for {platform} / "
                                     f"Python {py} (tags {', '.join(tags)}); fill the folder "
                                     "where there is network (a build's build/wheels, or pip "
                                     "download --only-binary=:all:)")
                progress(f"downloading {req} for {platform}, Python {py}")
                cmd = [sys.executable, "-m", "pip", "download", "-q",
                       "--disable-pip-version-check", req, "--only-binary=:all:",
                       "--no-deps", "--python-version", py, "-d", cache_dir]
                for t in tags:
                    cmd += ["--platform", t]
                run = subprocess.run(cmd, capture_output=True, text=True)
                if run.returncode != 0:
                    raise CrowdError(f"cannot download {req} for {platform} / Python {py}: "
                                     f"{run.stderr.strip().splitlines()[-1:]}")
    wheels = sorted(glob.glob(os.path.join(cache_dir, "*.whl")))
    wanted = {r.split("==")[0] + "-" + r.split("==")[1] for r in WHEELS}
    return [w for w in wheels if "-".join(os.path.basename(w).split("-")[:2]) in wanted]


def _manifest_with_wheels(text: str, wheels: list) -> str:
    lines = []
    for line in text.splitlines():
        if line.startswith(("wheels", "platforms")):
            raise CrowdError("blender_manifest.toml: leave 'wheels' and 'platforms' to "
                             "build-extension")
        lines.append(line)
        if line.startswith("blender_version_min"):
            lines.append("platforms = [" + ", ".join(f'"{p}"' for p in PLATFORMS) + "]")
            lines.append("wheels = [")
            lines += [f'  "./wheels/{os.path.basename(w)}",' for w in wheels]
            lines.append("]")
    return "\n".join(lines) + "\n"


def build_extension(out_dir, wheel_cache=None, source=REPO_ROOT, progress=print,
                    split_platforms=False, offline=False) -> list:
    """Build the extension zip(s) into ``out_dir``; returns the zip paths. The wheels
    come from ``wheel_cache`` (default ``build/wheels``), downloaded into it when
    missing, or with ``offline`` only from it (no network). Each zip is written whole
    or not at all; when the build fails, the output folders it created are removed."""
    out_dir = os.path.abspath(out_dir)
    if os.path.lexists(out_dir) and not os.path.isdir(out_dir):
        raise CrowdError(f"{out_dir}: exists and is not a folder (--out names the folder "
                         "the zip goes to)")
    wheel_cache = wheel_cache or os.path.join(source, "build", "wheels")
    with folders_made(out_dir):
        wheels = fetch_wheels(wheel_cache, progress, download=not offline)
        tool = extension_tool()
        with tempfile.TemporaryDirectory(prefix="crowd_ext_") as stage:
            zips = [_copy_zip(z, out_dir) for z in
                    _build_zips(stage, source, wheels, tool, split_platforms, progress)]
        if not zips:
            raise CrowdError("Blender's extension tool produced no zip")
    return zips


def _build_zips(stage, source, wheels, tool, split_platforms, progress) -> list:
    """Stage the sources, wheels and manifest in ``stage`` and build the zip(s) there
    with Blender's tool; returns their paths."""
    pkg = os.path.join(stage, "crowd_animation")
    os.makedirs(os.path.join(pkg, "wheels"))
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for item in _SOURCES:
        src = os.path.join(source, item)
        if os.path.isdir(src):
            shutil.copytree(src, os.path.join(pkg, item), ignore=ignore)
        elif os.path.isfile(src):
            shutil.copy2(src, pkg)
    for w in wheels:
        shutil.copy2(w, os.path.join(pkg, "wheels"))
    with open(os.path.join(source, "blender_manifest.toml"), encoding="utf-8") as f:
        manifest = _manifest_with_wheels(f.read(), wheels)
    with open(os.path.join(pkg, "blender_manifest.toml"), "w", encoding="utf-8") as f:
        f.write(manifest)
    build_out = os.path.join(stage, "out")
    os.makedirs(build_out)
    cmd = [sys.executable, tool, "build", "--source-dir", pkg, "--output-dir", build_out]
    if split_platforms:
        cmd.append("--split-platforms")
    progress("building with Blender's extension tool")
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        raise CrowdError(f"Blender's extension tool failed:\n{run.stdout}{run.stderr}")
    return sorted(glob.glob(os.path.join(build_out, "*.zip")))


def _copy_zip(built, out_dir) -> str:
    """Copy the zip ``built`` into ``out_dir`` whole or not at all (a zip of that name
    there stays as it was when the copy fails); returns its path there."""
    target = os.path.join(out_dir, os.path.basename(built))
    with open(built, "rb") as src:
        write_atomic(target, lambda f: shutil.copyfileobj(src, f), "the extension zip")
    return target
