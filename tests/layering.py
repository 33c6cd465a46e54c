"""The package's layering rules, checked by walking every import with :mod:`ast`.

Every ``import x``, ``from x import y`` and relative import (resolved to an absolute
name) in every ``.py`` file of the package is read, at module level and inside
functions alike (a lazy import is still a dependency), as are
``importlib.import_module("x")`` / ``__import__("x")`` calls with a literal name.
The rules (docs/testing.md):

``core``
    imports nothing of ours outside ``core`` and none of Blender's modules
    (:data:`BLENDER_MODULES`, ``gpu`` included), ``moderngl``/``glcontext`` or ``pxr``.
core's sub-packages
    come in the order of :data:`CORE_ORDER` (``base``, ``anim``, ``bake``, ``meshes``,
    ``runtime``, ``variety``, ``authoring``, ``planning``, ``shots``): a module of one
    imports only its own sub-package and those before it, never ``<package>.core``
    itself (the facade that re-exports them). Every module of core is in a
    sub-package listed there (only ``core/__init__.py`` sits at core's top).
``gpu``, ``usd``
    never import ``<package>.blender``.
Blender's API (:data:`BLENDER_API`: ``bpy``, ``bpy_extras``, ``mathutils``, ``bmesh``...)
    is imported only by ``<package>.blender``. One exception: ``<package>.gpu`` is also
    the Blender ``gpu``-module backend, so it may import Blender's ``gpu`` and
    ``gpu_extras`` (:data:`BLENDER_GPU`), but only inside functions, so that importing
    ``<package>.gpu`` never needs Blender. Everywhere else those are Blender-only too.
no cycles
    between the package's nodes: each top-level module or subpackage (``core``,
    ``gpu``, ``usd``, ``blender``, ``demo``, ``api``, ``cli``, ``packaging``...) is a
    node, the package's own ``__init__`` is the node ``__init__``; an import of
    ``<package>.a.b`` from inside node ``c`` is the edge ``c -> a``. Imports under
    ``if TYPE_CHECKING:`` never run and make no edge (the other rules still apply).

A relative import that climbs above the package is reported too.

:func:`find` returns :class:`Violation` objects (``key`` is stable: no line numbers,
for allow-lists); :func:`check` returns their messages; :func:`graph` is the node graph.
Run as a script (``python tests/layering.py [PACKAGE_DIR]``) it prints the violations.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["BLENDER_API", "BLENDER_GPU", "BLENDER_MODULES", "CORE_FORBIDDEN", "CORE_ORDER",
           "Import",
           "Violation", "imports", "graph", "find", "check"]

#: Blender's Python API modules other than its ``gpu`` module.
BLENDER_API = frozenset({"bpy", "bpy_extras", "bpy_types", "mathutils", "bmesh", "bl_math",
                         "bl_ui", "bl_operators", "bl_keymap_utils", "addon_utils",
                         "rna_prop_ui", "bgl", "blf", "aud", "idprop", "imbuf", "freestyle"})
#: Blender's GPU drawing modules: the gpu package's Blender backend may import them lazily.
BLENDER_GPU = frozenset({"gpu", "gpu_extras"})
BLENDER_MODULES = BLENDER_API | BLENDER_GPU
#: What core never imports, besides the rest of the package.
CORE_FORBIDDEN = BLENDER_MODULES | {"moderngl", "glcontext", "_moderngl", "pxr"}
#: core's sub-packages, lowest first: each imports only itself and those before it.
CORE_ORDER = ("base", "anim", "bake", "meshes", "runtime", "variety", "authoring",
              "planning", "shots")


@dataclass(frozen=True)
class Import:
    """One import: ``target`` is absolute (``crowd_addon.core.base.pose`` or ``bpy.props``)."""

    module: str          # importing module, e.g. "crowd_addon.gpu.programs"
    path: str            # its file, relative to the package's parent folder
    line: int
    target: str
    lazy: bool           # inside a function (runs when called, not on import)
    type_checking: bool  # under ``if TYPE_CHECKING:`` (never runs)

    @property
    def top(self) -> str:
        return self.target.split(".")[0]

    def where(self) -> str:
        return f"{self.path}:{self.line}"


@dataclass(frozen=True)
class Violation:
    rule: str            # "core", "backend-imports-blender", "blender-api", "cycle"
    key: str             # stable description, no line numbers
    message: str
    imports: tuple = field(default=(), compare=False)

    def __str__(self) -> str:
        return self.message


def _module_name(package_dir: Path, path: Path) -> tuple[str, bool]:
    """(dotted module name, is a package ``__init__``)."""
    rel = path.relative_to(package_dir.parent).with_suffix("")
    parts = list(rel.parts)
    is_init = parts[-1] == "__init__"
    if is_init:
        parts.pop()
    return ".".join(parts), is_init


def _is_module(package_dir: Path, dotted: str) -> bool:
    """Whether ``dotted`` (inside the package) names a module or subpackage on disk."""
    rel = Path(*dotted.split(".")[1:]) if "." in dotted else Path()
    base = package_dir / rel
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file() \
        or (base.is_dir() and rel != Path())


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


class _Walker(ast.NodeVisitor):
    def __init__(self, package_dir, module, is_init, path):
        self.package_dir, self.module, self.is_init, self.path = \
            package_dir, module, is_init, path
        self.found: list[Import] = []
        self.depth = 0          # function nesting
        self.tc = 0             # TYPE_CHECKING nesting

    def _add(self, node, target):
        self.found.append(Import(self.module, self.path, node.lineno, target,
                                 self.depth > 0, self.tc > 0))

    def visit_FunctionDef(self, node):
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_AsyncFunctionDef = visit_FunctionDef
    visit_Lambda = visit_FunctionDef

    def visit_If(self, node):
        if _is_type_checking(node.test):
            self.tc += 1
            for n in node.body:
                self.visit(n)
            self.tc -= 1
            for n in node.orelse:
                self.visit(n)
        else:
            self.generic_visit(node)

    def visit_Import(self, node):
        for alias in node.names:
            self._add(node, alias.name)

    def visit_ImportFrom(self, node):
        if node.level:
            # the package this module is in (a package's __init__ is its own package)
            pkg = self.module.split(".")
            if not self.is_init:
                pkg = pkg[:-1]
            if node.level - 1 > len(pkg) - 1:
                self._add(node, "." * node.level + (node.module or ""))   # beyond the top
                return
            base = pkg[:len(pkg) - (node.level - 1)]
            mod = ".".join(base + ([node.module] if node.module else []))
        else:
            mod = node.module or ""
        for alias in node.names:
            sub = f"{mod}.{alias.name}"
            # ``from pkg import sub`` imports pkg.sub when that is a module of ours
            if alias.name != "*" and sub.split(".")[0] == self.package_dir.name \
                    and _is_module(self.package_dir, sub):
                self._add(node, sub)
            else:
                self._add(node, mod)

    def visit_Call(self, node):
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
        if name in ("import_module", "__import__") and node.args and \
                isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str) \
                and not node.args[0].value.startswith("."):
            self._add(node, node.args[0].value)
        self.generic_visit(node)


def imports(package_dir) -> list[Import]:
    """Every import in every ``.py`` file under ``package_dir`` (a package folder)."""
    package_dir = Path(package_dir)
    out = []
    for path in sorted(package_dir.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        module, is_init = _module_name(package_dir, path)
        rel = path.relative_to(package_dir.parent).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        w = _Walker(package_dir, module, is_init, rel)
        w.visit(tree)
        out += w.found
    return out


def _node(package: str, dotted: str) -> str | None:
    """The layering node of a module of ours: its first component under the package."""
    parts = dotted.split(".")
    if parts[0] != package:
        return None
    return parts[1] if len(parts) > 1 else "__init__"


def _core_part(package: str, dotted: str) -> str | None:
    """The core sub-package a module of ours is in (``"base"`` for
    ``<package>.core.base`` and ``<package>.core.base.pose``), ``""`` for core's own
    ``__init__``, None outside core."""
    parts = dotted.split(".")
    if parts[:2] != [package, "core"]:
        return None
    return parts[2] if len(parts) > 2 else ""


def _core_order(package: str, imp: Import, order) -> Violation | None:
    """The sub-package order rule for one import made inside a core sub-package."""
    src = _core_part(package, imp.module)
    parts = imp.target.split(".")
    if src not in order or parts[:2] != [package, "core"]:
        return None         # outside core, or core's facade (core/__init__.py)
    dst = parts[2] if len(parts) > 2 else ""
    if dst in order and order.index(dst) <= order.index(src):
        return None
    msg = f"{imp.where()}: {imp.module} {'lazily imports' if imp.lazy else 'imports'} " \
          f"{imp.target}"
    why = (f"{package}.core is the facade; import the module itself" if dst == ""
           else f"core.{src} comes before core.{dst} ({' < '.join(order)})"
           if dst in order else f"core.{dst} is not in CORE_ORDER")
    return Violation("core-order", f"{imp.module} -> {package}.core"
                     + (f".{dst}" if dst else ""), f"[core-order] {msg} ({why})", (imp,))


def _core_strays(package_dir: Path, order) -> list[Violation]:
    """Modules at core's top (other than its ``__init__``) and sub-packages of core
    that are not in the order."""
    core, out = package_dir / "core", []
    if not core.is_dir():
        return out
    for path in sorted(core.iterdir()):
        name = f"{package_dir.name}.core.{path.stem}"
        if path.suffix == ".py" and path.name != "__init__.py":
            out.append(Violation("core-order", f"{name} (at core's top)",
                                 f"[core-order] {name}: every module of core belongs to "
                                 f"a sub-package of CORE_ORDER", ()))
        elif (path / "__init__.py").is_file() and path.name not in order:
            out.append(Violation("core-order", f"{name} (not in CORE_ORDER)",
                                 f"[core-order] {name}: a sub-package of core missing from "
                                 f"CORE_ORDER ({', '.join(order)})", ()))
    return out


def _cycles(edges: dict) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan), sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []
    nodes = sorted(set(edges) | {b for bs in edges.values() for b in bs})

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in nodes:
        if v not in index:
            visit(v)
    return sorted(out)


def graph(package_dir, found=None) -> dict[str, dict[str, list[Import]]]:
    """``{node: {node it imports: [the imports]}}`` (no self edges, no TYPE_CHECKING);
    ``found``: the package's :func:`imports` when already read."""
    package_dir = Path(package_dir)
    pkg = package_dir.name
    edges: dict[str, dict[str, list[Import]]] = {}
    for imp in imports(package_dir) if found is None else found:
        src, dst = _node(pkg, imp.module), _node(pkg, imp.target)
        if src is not None and dst is not None and src != dst and not imp.type_checking:
            edges.setdefault(src, {}).setdefault(dst, []).append(imp)
    return edges


def find(package_dir, ignore_edges=(), found=None, core_order=CORE_ORDER) -> list[Violation]:
    """Every violation of the rules in the module doc, in a stable order.

    ``ignore_edges``: ``(node, node)`` pairs left out of the cycle search (a temporary
    allow-list names the one import edge being removed, so any other cycle still fails).
    ``found``: the package's :func:`imports` when already read. ``core_order``: core's
    sub-packages, lowest first.
    """
    package_dir = Path(package_dir)
    pkg = package_dir.name
    out: list[Violation] = []
    every = imports(package_dir) if found is None else found
    out += _core_strays(package_dir, tuple(core_order))
    for imp in every:
        wrong = _core_order(pkg, imp, tuple(core_order))
        if wrong is not None:
            out.append(wrong)
        src = _node(pkg, imp.module)
        dst = _node(pkg, imp.target)
        how = "lazily imports" if imp.lazy else "imports"
        msg = f"{imp.where()}: {imp.module} {how} {imp.target}"
        if imp.target.startswith("."):
            out.append(Violation("relative-beyond-top", f"{imp.module} -> {imp.target}",
                                 f"[relative-beyond-top] {msg}", (imp,)))
            continue
        if src == "core":
            if dst is not None and dst != "core":
                out.append(Violation("core", f"{imp.module} -> {pkg}.{dst}",
                                     f"[core] {msg} (core imports nothing of ours)", (imp,)))
            elif imp.top in CORE_FORBIDDEN:
                out.append(Violation("core", f"{imp.module} -> {imp.top}",
                                     f"[core] {msg} (core is pure numpy)", (imp,)))
        if src in ("gpu", "usd") and dst == "blender":
            out.append(Violation("backend-imports-blender", f"{imp.module} -> {pkg}.blender",
                                 f"[backend-imports-blender] {msg} ({pkg}.{src} never "
                                 f"imports {pkg}.blender)", (imp,)))
        if src not in ("blender", "core") and imp.top in BLENDER_MODULES:
            # core has its own, stricter message above
            if imp.top in BLENDER_GPU and src == "gpu" and imp.lazy:
                pass                # the gpu package's Blender backend, lazily
            else:
                why = (f"only {pkg}.blender imports Blender's API" if imp.top in BLENDER_API
                       else f"Blender's {imp.top} module: only {pkg}.blender, or {pkg}.gpu "
                            f"inside a function")
                out.append(Violation("blender-api", f"{imp.module} -> {imp.top}",
                                     f"[blender-api] {msg} ({why})", (imp,)))
    ignore = {tuple(e) for e in ignore_edges}
    edges = {a: {b: imps for b, imps in bs.items() if (a, b) not in ignore}
             for a, bs in graph(package_dir, every).items()}
    for comp in _cycles({a: set(bs) for a, bs in edges.items()}):
        inside = [imp for a in comp for b, imps in sorted(edges.get(a, {}).items())
                  if b in comp for imp in imps]
        detail = "; ".join(f"{imp.where()} {imp.module} -> {imp.target}" for imp in inside)
        out.append(Violation("cycle", "cycle: " + " <-> ".join(comp),
                             f"[cycle] {' <-> '.join(comp)}: {detail}", tuple(inside)))
    return sorted(out, key=lambda v: (v.rule, v.key, [(i.path, i.line) for i in v.imports]))


def check(package_dir, ignore_edges=(), core_order=CORE_ORDER) -> list[str]:
    """The messages of :func:`find` (empty when the package keeps the rules)."""
    return [str(v) for v in find(package_dir, ignore_edges, core_order=core_order)]


if __name__ == "__main__":       # python tests/layering.py [PACKAGE_DIR]
    import sys

    target = sys.argv[1] if len(sys.argv) > 1 else \
        str(Path(__file__).resolve().parents[1] / "crowd_addon")
    problems = check(target)
    print("\n".join(problems) or "layering: no violations")
    sys.exit(1 if problems else 0)
