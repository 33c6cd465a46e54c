"""``python -m crowd_addon <command> ...``: see :mod:`crowd_addon.cli`."""

from .cli import main

raise SystemExit(main())
