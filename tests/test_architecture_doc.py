"""docs/architecture.md stays true of the tree: its module table names every module of
``crowd_addon/`` and nothing else, every file it names exists, and its list of modules
over 400 lines is the tree's (at most 8, none over 600, the crowd facade at most 450:
issue 32's limits)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "crowd_addon"
DOC = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
LONG, MOST_LONG, LONGEST, FACADE = 400, 8, 600, 450


def section(title: str, doc: str = DOC) -> str:
    start = doc.index(f"\n## {title}\n")
    end = doc.find("\n## ", start + 1)
    return doc[start:end if end >= 0 else None]


def modules() -> dict:
    """``{path relative to crowd_addon: line count}`` of every module but ``__init__``
    and ``__main__``."""
    return {p.relative_to(PACKAGE).as_posix(): len(p.read_text(encoding="utf-8").splitlines())
            for p in PACKAGE.rglob("*.py")
            if "__pycache__" not in p.parts and p.name not in ("__init__.py", "__main__.py")}


def named(text: str) -> set:
    """Module paths named in backticks with their folder (``core/shots/crowd.py``,
    ``crowd_addon/api.py``; a bare ``frame.py`` is a name in passing)."""
    paths = set()
    for m in re.finditer(r"`((?:crowd_addon/)?[a-z_]+(?:/[a-z_]+)+\.py)`", text):
        path = m.group(1).removeprefix("crowd_addon/")
        if not path.startswith(("tests/", "benchmarks/", "sample_scenes/")):
            paths.add(path)
    return paths


def table_problems(doc: str) -> tuple:
    """``(modules missing from the table, modules the table names that are gone)``."""
    table = {m.group(1) for m in re.finditer(r"^\| `([^`]+\.py)` \|",
                                             section("Modules", doc), re.M)}
    on_disk = set(modules())
    return sorted(on_disk - table), sorted(table - on_disk)


def test_the_module_table_names_every_module_and_nothing_else():
    assert table_problems(DOC) == ([], [])


def test_every_module_the_doc_names_exists():
    gone = {p for p in named(DOC) if not (PACKAGE / p).is_file()}
    assert not gone, f"docs/architecture.md names files that do not exist: {sorted(gone)}"


def test_the_long_modules_are_the_ones_listed_and_within_the_limits():
    sizes = modules()
    long = {p for p, n in sizes.items() if n > LONG}
    listed = set(re.findall(r"^- `([^`]+\.py)`:", section("Modules over 400 lines"), re.M))
    assert long == listed, (f"over {LONG} lines but not explained: {sorted(long - listed)}; "
                            f"listed but not long: {sorted(listed - long)}")
    assert len(long) <= MOST_LONG, sorted(long)
    assert max(sizes.values()) <= LONGEST, max(sizes, key=sizes.get)
    assert sizes["core/shots/crowd.py"] <= FACADE


def test_the_checks_see_a_stale_doc():
    """A table that misses a module, or names one that is gone, is caught."""
    row = "| `core/shots/driver.py` |"
    assert row in DOC
    stale = DOC.replace(row, "| `core/shots/gone.py` |")
    assert table_problems(stale) == (["core/shots/driver.py"], ["core/shots/gone.py"])
    assert "core/shots/gone.py" in named(stale) and not (PACKAGE / "core/shots/gone.py").exists()
    assert "core/shots/crowd.py" in named("see `crowd_addon/core/shots/crowd.py` here")
