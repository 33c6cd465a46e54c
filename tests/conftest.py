"""Suite-wide pytest hooks: the ``fast`` tier, ``CROWD_REQUIRE_ALL``, summaries and the
exit.

Tiers (docs/testing.md). ``tests/core/`` and the structural tests (``FAST``) need
numpy only; they are marked ``fast`` here by path, so ``pytest -m fast`` runs that tier alone
(and, for that exact expression, does not even import the other test modules, which
load bpy, moderngl and pxr). Everything else needs Blender's ``bpy`` module, headless
EGL (moderngl) or ``pxr``, and skips where one is missing.

``CROWD_REQUIRE_ALL=1`` (set by ``.ci/test``): in CI a missing dependency must fail the
run, not skip a third of it. Under it, every skip becomes a failure (a skipped
module or directory at collection becomes a collection error, which stops the run
before any test) except :data:`ALLOWED_SKIPS`, named one by one with their reason.

Summaries. A line a test records as the user property ``("summary", line)`` (the fuzz
test's counts, tests/test_fuzz.py) is printed under "summaries" at the end of the run,
whether the test passed or failed, so that it is in the CI log.

The exit. Blender's ``gpu`` module (initialised in-process by the viewport-preview
tests) and moderngl's standalone EGL contexts (the GPU tests) live in one test
process. Each makes its own context current; at interpreter exit Blender frees its
GPU resources assuming its context is still current, and libepoxy aborts the
process (SIGABRT) after every test has passed. Users never mix the two in one
process (the viewport path attaches moderngl to Blender's own context), so once the
session is over and reported, a process that imported ``bpy`` leaves with
``os._exit`` and pytest's exit status, skipping only that teardown.
"""

import os
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
#: The pure-core tier (``pytest -m fast``): folders and files under tests/.
FAST = ("core", "test_layering.py", "test_one_loop.py", "test_architecture_doc.py")
#: The environment switch that turns skips into failures.
REQUIRE_ALL = "CROWD_REQUIRE_ALL"
#: The only skips allowed under CROWD_REQUIRE_ALL: node id -> the skip's reason.
ALLOWED_SKIPS = {
    # none today: node id -> reason, for a test that truly cannot run in CI
}

_status = {}
#: Lines tests recorded for the terminal summary (pytest_terminal_summary).
_summaries = []


def _require_all() -> bool:
    return os.environ.get(REQUIRE_ALL, "") not in ("", "0")


def _is_fast(path) -> bool:
    try:
        rel = Path(path).resolve().relative_to(TESTS)
    except ValueError:
        return False
    return bool(rel.parts) and rel.parts[0] in FAST


def _fast_only(config) -> bool:
    return (config.getoption("markexpr", "") or "").strip() == "fast"


def pytest_report_header(config):
    if _require_all():
        return (f"{REQUIRE_ALL}=1: a skip is a failure, except "
                f"{', '.join(ALLOWED_SKIPS) or 'none'}")
    return None


def pytest_ignore_collect(collection_path, config):
    """``-m fast``: leave the other tiers' folders and modules (and the bpy, moderngl and
    pxr their conftests and modules import) alone; they would all be deselected."""
    if not _fast_only(config):
        return None
    try:
        rel = Path(collection_path).resolve().relative_to(TESTS)
    except ValueError:
        return None
    if len(rel.parts) == 1 and rel.parts[0] not in FAST and \
            (Path(collection_path).is_dir() or rel.name.startswith("test_")):
        return True
    return None


def pytest_collection_modifyitems(config, items):
    for item in items:
        if _is_fast(item.path):
            item.add_marker(pytest.mark.fast)


def _skip_reason(longrepr) -> str:
    if isinstance(longrepr, tuple) and len(longrepr) == 3:
        return str(longrepr[2]).removeprefix("Skipped: ")
    return str(longrepr)


def _fail_skip(rep, what):
    reason = _skip_reason(rep.longrepr)
    rep.outcome = "failed"
    rep.longrepr = (f"{REQUIRE_ALL}=1 (CI): {what} would have been skipped ({reason}); a "
                    f"missing dependency fails the run (bash .ci/setup installs them; "
                    f"docs/testing.md)")


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    rep = outcome.get_result()
    if rep.skipped and _require_all():
        _fail_skip(rep, f"collecting {rep.nodeid or collector.path}")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    if not (rep.skipped and _require_all()) or hasattr(rep, "wasxfail"):
        return
    allowed = ALLOWED_SKIPS.get(item.nodeid)
    if allowed is not None and _skip_reason(rep.longrepr) == allowed:
        return
    _fail_skip(rep, item.nodeid)


def pytest_runtest_logreport(report):
    if report.when == "call":
        _summaries.extend(value for key, value in report.user_properties if key == "summary")


def pytest_terminal_summary(terminalreporter):
    """Print, in the order the tests ran, the lines they recorded as ``("summary", line)``
    user properties (the fuzz test's counts, tests/test_fuzz.py), so that they are in
    the CI log when the tests pass too."""
    if _summaries:
        terminalreporter.write_sep("-", "summaries")
        for line in _summaries:
            terminalreporter.write_line(line)


def pytest_sessionfinish(session, exitstatus):
    _status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    if "bpy" in sys.modules and "code" in _status:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_status["code"])
