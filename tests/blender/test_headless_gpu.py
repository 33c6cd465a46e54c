"""Blender's ``gpu`` module woken in background mode (``init_headless_gpu``) without
Blender's EGL noise on the console (issue 35, item 6): on a headless Mesa display
Blender reports every EGL configuration it tries and lets go as ``EGL Error (0x3009):
EGL_BAD_MATCH: ...`` on stderr, though it then draws. The oracle is the process's
own stderr (a fresh process: the GPU is woken once per process) and Blender's ``gpu``
module drawing afterwards."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy")

ROOT = Path(__file__).resolve().parents[2]


def test_waking_the_gpu_prints_no_egl_bad_match_and_the_gpu_draws():
    code = textwrap.dedent("""
        import sys
        import bpy
        from crowd_addon.blender.headless_gpu import init_headless_gpu
        print("before", file=sys.stderr, flush=True)
        init_headless_gpu()
        import gpu
        off = gpu.types.GPUOffScreen(8, 8)
        with off.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.25, 0.5, 0.75, 1.0))
            px = fb.read_color(0, 0, 1, 1, 4, 0, "FLOAT").to_list()
        off.free()
        print("after", [round(v, 2) for v in px[0][0]], file=sys.stderr, flush=True)
    """)
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "EGL_BAD_MATCH" not in run.stderr, run.stderr[-3000:]
    lines = run.stderr.splitlines()
    assert "before" in lines and "after [0.25, 0.5, 0.75, 1.0]" in lines


def test_only_the_egl_mismatch_lines_are_dropped(capfd):
    from crowd_addon.blender.headless_gpu import _without_egl_mismatches
    with _without_egl_mismatches():
        os.write(2, b"EGL Error (0x3009): EGL_BAD_MATCH: Arguments are inconsistent.\n")
        os.write(2, b"EGL Error (0x3003): EGL_BAD_ALLOC: a real one\n")
        print("from Python", file=sys.stderr)
        os.write(1, b"stdout is left alone\n")
    out, err = capfd.readouterr()
    assert sorted(err.splitlines()) == ["EGL Error (0x3003): EGL_BAD_ALLOC: a real one",
                                        "from Python"]
    assert out == "stdout is left alone\n"
