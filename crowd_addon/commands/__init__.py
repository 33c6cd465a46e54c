"""The ``crowd`` program's commands (:mod:`crowd_addon.cli` builds the parser and runs
one): per command an ``add_<name>(subparsers)`` that builds its subparser and a
``_run_<name>(args)`` handler, grouped by what they call: :mod:`.planning` (``budget``,
``plan``), :mod:`.export` (``export``, ``snapshot``, ``stitch``, ``farm``),
:mod:`.preview`, :mod:`.demo` and :mod:`.extension` (``build-extension``). Handlers
import their heavy modules, and :mod:`crowd_addon.blender` (only for ``--blend``),
inside themselves, so ``crowd --help`` stays fast and never needs Blender.
"""
