"""Suite-wide pytest hooks.

Blender's ``gpu`` module (initialised in-process by the viewport-preview tests) and
moderngl's standalone EGL contexts (the GPU tests) live in one test process. Each
makes its own context current; at interpreter exit Blender frees its GPU resources
assuming its context is still current, and libepoxy aborts the process (SIGABRT)
after every test has passed. Users never mix the two in one process (the viewport
path attaches moderngl to Blender's own context), so once the session is over and
reported, a process that imported ``bpy`` leaves with ``os._exit`` and pytest's exit
status, skipping only that teardown.
"""

import os
import sys

_status = {}


def pytest_sessionfinish(session, exitstatus):
    _status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    if "bpy" in sys.modules and "code" in _status:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_status["code"])
