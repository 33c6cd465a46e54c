"""``python -m crowd_addon <command> ...``: see :mod:`crowd_addon.cli`."""

from .cli import console

raise SystemExit(console())
