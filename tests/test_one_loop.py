"""One loop steps a crowd: outside ``crowd_addon/core`` nothing calls a crowd's ``step``
or ``advance_to`` itself; every command, the viewport and the farm go through
``core.shots.driver.FrameDriver`` (docs/architecture.md, "The frame driver")."""

import ast
import re
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "crowd_addon"
#: receivers whose ``step``/``advance_to`` are not a crowd's: the driver itself, a
#: modal job's step, the public API handle (which drives its crowd with a FrameDriver)
NOT_A_CROWD = re.compile(r"^(FrameDriver\(.*\)|(.*\.)?(driver|job|handle))$")


def loops_outside_core(path: Path, source: str | None = None) -> list[str]:
    """``file:line receiver.method`` of each ``x.step()`` / ``x.advance_to(...)`` call
    whose receiver may be a crowd."""
    tree = ast.parse(path.read_text(encoding="utf-8") if source is None else source)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and node.func.attr in ("step", "advance_to"):
            receiver = ast.unparse(node.func.value)
            if not NOT_A_CROWD.match(receiver):
                out.append(f"{path.name}:{node.lineno} {receiver}.{node.func.attr}")
    return out


def test_nothing_outside_core_steps_a_crowd_itself():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if (PACKAGE / "core") in path.parents:
            continue
        found += loops_outside_core(path)
    assert not found, "step a crowd through core.shots.driver.FrameDriver:\n" + \
        "\n".join(found)


def test_the_check_sees_a_crowd_stepped_by_hand():
    source = textwrap.dedent("""
        def run(crowd, pv, driver, job):
            crowd.step()                       # flagged
            pv.crowd.advance_to(10)            # flagged
            self.crowd.step()                  # flagged
            driver.step()
            FrameDriver(crowd).seek(3)
            FrameDriver(crowd, hook).step()
            job.step()
            pv.handle.advance_to(4)
        """)
    got = loops_outside_core(Path("fake.py"), source)
    assert got == ["fake.py:3 crowd.step", "fake.py:4 pv.crowd.advance_to",
                   "fake.py:5 self.crowd.step"]
