"""The layering rules of ``crowd_addon`` (tests/layering.py, docs/testing.md).

The real package must keep them; the checker itself is tested on a small fake
package with one deliberate violation of each rule.
"""

import ast
import os
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import layering  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "crowd_addon"

@pytest.fixture(scope="module")
def real():
    """The real package read once: its imports and every violation (nothing ignored)."""
    found = layering.imports(PACKAGE)
    return SimpleNamespace(imports=found, graph=layering.graph(PACKAGE, found),
                           violations=layering.find(PACKAGE, found=found))


def test_crowd_addon_keeps_the_layering_rules(real):
    problems = [str(v) for v in real.violations]
    assert not problems, "layering rules broken (docs/testing.md):\n" + "\n".join(problems)


def test_the_walk_sees_the_whole_package(real):
    """Guards the checker against silently reading nothing: every import statement
    anywhere in the package (module level, functions, classes, try, if, with) is
    there, lazy ones and relative ones resolved to ours among them."""
    seen = {(i.path, i.line) for i in real.imports}
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                assert (rel, node.lineno) in seen, f"{rel}:{node.lineno} not read"
    lazy = {(i.module, i.target) for i in real.imports if i.lazy}
    assert ("crowd_addon", "crowd_addon.blender.registration") in lazy    # register()
    assert any(i.module.startswith("crowd_addon.usd") and i.top == "pxr" and not i.lazy
               for i in real.imports)
    assert "core" in real.graph["gpu"] and "core" in real.graph["usd"]


# --- the checker on a fake package -------------------------------------------------

FAKE = {
    "__init__.py": """
        from . import core                   # a subpackage, relatively
        VERSION = 1

        def register():
            from .blender import ops          # lazy, fine
            ops.go()
        """,
    "core/__init__.py": "from .high.leaky import later  # the facade may import any part\n",
    "core/low/__init__.py": "",
    "core/low/pure.py": """
        import numpy as np
        from . import sibling                # within a sub-package is fine
        from .sibling import helper
        """,
    "core/low/sibling.py": "def helper(): pass\n",
    "core/low/upward.py": """
        from ..high import leaky             # low comes before high
        from fake.core import later          # core's facade, from inside core

        def lazily():
            from ..high.leaky import later   # lazy, still against the order
        """,
    "core/high/__init__.py": "",
    "core/high/leaky.py": """
        from ...gpu import render            # core imports ours
        from fake.usd.writer import Thing    # absolute, also ours
        import moderngl
        from pxr import Usd
        import gpu                           # Blender's gpu module
        from ..low import pure               # high may import low

        def later():
            import bpy                       # lazy, still a violation
            import importlib
            return importlib.import_module("mathutils")
        """,
    "core/stray.py": "",                     # a module at core's top
    "core/extra/__init__.py": "",            # a sub-package missing from the order
    "gpu/__init__.py": "",
    "gpu/render.py": """
        import numpy as np                   # (no gpu -> core edge: core -> gpu above
                                             # would make it a second cycle)

        def draw():
            import gpu                       # the Blender backend, lazily: allowed
            from gpu_extras.batch import batch_for_shader
            return gpu, batch_for_shader
        """,
    "gpu/eager.py": """
        import gpu                           # module level: not allowed
        """,
    "gpu/leans_on_blender.py": """
        from fake.blender import ops         # gpu -> blender
        """,
    "usd/__init__.py": "",
    "usd/writer.py": """
        from pxr import Usd                  # usd may import pxr
        import mathutils                     # Blender API outside blender

        class Thing:
            pass

        def sneak():
            from ..blender.ops import go     # usd -> blender, lazily
        """,
    "blender/__init__.py": "",
    "blender/ops.py": """
        from typing import TYPE_CHECKING

        import bpy                           # blender may
        from bpy_extras.io_utils import ExportHelper
        import gpu

        if TYPE_CHECKING:
            from ..demo import show          # never runs: no edge, no cycle

        def go():
            from .. import cli               # blender -> cli ...
            cli.main()
        """,
    "demo/__init__.py": "",
    "demo/show.py": """
        from ..blender import ops
        from .. import VERSION               # a name, not a module: imports fake
        """,
    "cli.py": """
        from .blender import ops             # ... and cli -> blender: a cycle

        def main():
            from bpy_extras import io_utils  # Blender API in cli, lazily
        """,
}


def make_fake(tmp_path, files=FAKE, name="fake"):
    pkg = tmp_path / name
    for rel, text in files.items():
        path = pkg / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    return pkg


FAKE_ORDER = ("low", "high")


def test_checker_reports_each_rule_on_a_fake_package(tmp_path):
    pkg = make_fake(tmp_path)
    found = layering.find(pkg, core_order=FAKE_ORDER)
    keys = {(v.rule, v.key) for v in found}
    assert keys == {
        ("core", "fake.core.high.leaky -> fake.gpu"),
        ("core", "fake.core.high.leaky -> fake.usd"),
        ("core", "fake.core.high.leaky -> moderngl"),
        ("core", "fake.core.high.leaky -> pxr"),
        ("core", "fake.core.high.leaky -> gpu"),
        ("core", "fake.core.high.leaky -> bpy"),            # lazy
        ("core", "fake.core.high.leaky -> mathutils"),      # importlib.import_module
        ("core-order", "fake.core.low.upward -> fake.core.high"),   # eager and lazy
        ("core-order", "fake.core.low.upward -> fake.core"),        # the facade
        ("core-order", "fake.core.stray (at core's top)"),
        ("core-order", "fake.core.extra (not in CORE_ORDER)"),
        ("backend-imports-blender", "fake.gpu.leans_on_blender -> fake.blender"),
        ("backend-imports-blender", "fake.usd.writer -> fake.blender"),   # lazy
        ("blender-api", "fake.gpu.eager -> gpu"),
        ("blender-api", "fake.usd.writer -> mathutils"),
        ("blender-api", "fake.cli -> bpy_extras"),     # lazy
        ("cycle", "cycle: blender <-> cli"),
    }, "\n".join(map(str, found))
    upward = [v for v in found if v.key == "fake.core.low.upward -> fake.core.high"]
    assert [(i.line, i.lazy) for v in upward for i in v.imports] == [(2, False), (6, True)]
    assert "core.low comes before core.high (low < high)" in str(upward[0])
    messages = layering.check(pkg, core_order=FAKE_ORDER)
    assert any("fake/core/high/leaky.py:10: fake.core.high.leaky lazily imports bpy" in m
               for m in messages), messages
    cycle = next(m for m in messages if m.startswith("[cycle]"))
    assert "fake/blender/ops.py:12 fake.blender.ops -> fake.cli" in cycle
    assert "fake/cli.py:2 fake.cli -> fake.blender.ops" in cycle


def test_checker_resolves_relative_imports(tmp_path):
    pkg = make_fake(tmp_path)
    got = {(i.module, i.target, i.lazy, i.type_checking) for i in layering.imports(pkg)}
    assert ("fake.core.high.leaky", "fake.gpu.render", False, False) in got  # a module
    assert ("fake.core.low.pure", "fake.core.low.sibling", False, False) in got
    assert ("fake.usd.writer", "fake.blender.ops", True, False) in got
    assert ("fake", "fake.blender.ops", True, False) in got     # from __init__
    assert ("fake.blender.ops", "fake.demo.show", False, True) in got
    assert ("fake", "fake.core", False, False) in got           # from . import core
    assert ("fake.demo.show", "fake", False, False) in got      # from .. import VERSION
    assert ("fake.blender.ops", "fake.cli", True, False) in got


def test_ignored_edge_breaks_only_its_cycle(tmp_path):
    pkg = make_fake(tmp_path)
    assert not [v for v in layering.find(pkg, ignore_edges={("blender", "cli")},
                                         core_order=FAKE_ORDER) if v.rule == "cycle"]
    # a second cycle, not through that edge, is still reported
    files = dict(FAKE)
    files["packaging.py"] = "def build():\n    from .api import wrap\n"
    files["api.py"] = "from . import packaging\n"
    pkg = make_fake(tmp_path / "two", files)
    cycles = [v.key for v in layering.find(pkg, ignore_edges={("blender", "cli")},
                                           core_order=FAKE_ORDER) if v.rule == "cycle"]
    assert cycles == ["cycle: api <-> packaging"]


def test_a_clean_package_has_no_violations(tmp_path):
    clean = {k: v for k, v in FAKE.items()
             if k not in ("core/high/leaky.py", "core/low/upward.py", "core/stray.py",
                          "core/extra/__init__.py", "core/__init__.py", "gpu/eager.py",
                          "gpu/leans_on_blender.py")}
    clean["usd/writer.py"] = "from pxr import Usd\nfrom ..core.low import pure\n"
    clean["blender/ops.py"] = "import bpy\nimport mathutils\nimport gpu\nfrom .. import core\n"
    clean["cli.py"] = "from .blender import ops\n"
    assert layering.check(make_fake(tmp_path, clean), core_order=FAKE_ORDER) == []
