"""``crowd build-extension``: the Blender extension zip with its bundled wheels, its
subparser and handler, on :mod:`crowd_addon.packaging`.
"""

from __future__ import annotations

import sys

from ..cli_args import path_arg

__all__ = ["add_build_extension"]


def add_build_extension(subparsers) -> None:
    p = subparsers.add_parser(
        "build-extension",
        help="build the Blender extension zip with its bundled wheels",
        description="Download the moderngl/glcontext wheels for every platform and "
                    "Python Blender ships (cached in build/wheels) and build the "
                    "extension zip with Blender's own extension tool (from the bpy "
                    "module). Install it with Blender > Preferences > Get Extensions > "
                    "Install from Disk, or blender --command extension install-file --repo "
                    "user_default --enable ZIP (docs/user_guide_blender.md, Install).")
    p.add_argument("--out", default="dist", type=path_arg, metavar="DIR",
                   help="folder for the zip (default: %(default)s)")
    p.add_argument("--split-platforms", action="store_true",
                   help="one zip per platform instead of one for all")
    p.add_argument("--wheels", type=path_arg, metavar="DIR", default=None,
                   help="take the wheels from this folder only, without network (every "
                        "platform and Python must be there; default: download into "
                        "build/wheels when missing)")
    p.set_defaults(handler=_run_build_extension)


def _run_build_extension(args) -> int:
    from ..packaging import build_extension

    for z in build_extension(args.out, wheel_cache=args.wheels, offline=args.wheels is not None,
                             split_platforms=args.split_platforms,
                             progress=lambda m: print(f"crowd build-extension: {m}",
                                                      file=sys.stderr, flush=True)):
        print(z)
    return 0
