"""Argument converters and progress printing shared by the two command lines: the
headless ``crowd`` program (:mod:`crowd_addon.cli` and its :mod:`crowd_addon.commands`)
and Blender's ``-c crowd`` command (:mod:`crowd_addon.blender.cli_commands`). It imports nothing of this project
but core's vocabulary (``USD_LAYOUTS``), so both may use it without a cycle."""

from __future__ import annotations

import argparse
import math
import re
import sys

from .core.authoring.config import MAX_SUBSTEPS, USD_LAYOUTS

__all__ = ["int_at_least", "positive_float", "frame_range", "frame_number", "path_arg",
           "progress_printer", "add_shot_arguments", "add_trust_argument", "parse_command"]

#: The largest frame number in magnitude, as in configuration files (codec.MAX_INT).
MAX_FRAME = 2**31 - 1


def int_at_least(minimum: int, maximum: int | None = None):
    """An argparse type: an integer ``>= minimum`` (and ``<= maximum`` if given)."""
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be <= {maximum}, got {value}")
        return value
    convert.__name__ = "integer"
    return convert


def positive_float(text: str) -> float:
    """An argparse type: a finite number ``> 0``."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


#: ``FIRST-LAST`` or one frame, either negative, blanks around them allowed.
_FRAME_RANGE = re.compile(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?")


def frame_range(text: str) -> tuple:
    """An argparse type: ``"FIRST-LAST"`` (e.g. ``1-300``, ``-10-20``) or ``"N"`` ->
    ``(first, last)`` ints, ``first <= last``."""
    m = _FRAME_RANGE.fullmatch(text)
    if m is None:
        raise argparse.ArgumentTypeError(f"must be FIRST-LAST or a frame, got {text!r}")
    first = int(m.group(1))
    last = first if m.group(2) is None else int(m.group(2))
    if last < first:
        raise argparse.ArgumentTypeError(f"last frame {last} is before first frame {first}")
    return first, last


def frame_number(text: str) -> int:
    """An argparse type: an integer frame of magnitude at most :data:`MAX_FRAME`."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if abs(value) > MAX_FRAME:
        raise argparse.ArgumentTypeError(f"must be an integer of magnitude at most "
                                         f"{MAX_FRAME}, got {value}")
    return value


def path_arg(text: str) -> str:
    """An argparse type: a file or folder path, not empty (which would mean the current
    folder or nothing) and without a NUL character (which no file system accepts)."""
    if not text:
        raise argparse.ArgumentTypeError("must not be empty")
    if "\x00" in text:
        raise argparse.ArgumentTypeError(f"must not contain a NUL character, got {text!r}")
    return text


positive_float.__name__ = "number"
frame_range.__name__ = "frame range"
frame_number.__name__ = "frame"
path_arg.__name__ = "path"


def progress_printer(prefix: str):
    """``progress(stage, done, total)`` printing ``prefix: stage done/total`` to stderr
    about every 10% of each stage."""
    shown = {}

    def progress(stage, done, total):
        tenth = 10 if total <= 0 else done * 10 // total
        if shown.get(stage, -1) < tenth:
            shown[stage] = tenth
            print(f"{prefix}: {stage} {done}/{total}", file=sys.stderr, flush=True)
    return progress


def add_shot_arguments(parser) -> None:
    """The options every ``export`` command shares: ``--scene``, ``--out``, ``--frames``
    (None when not given), ``--agents``, ``--layout`` and ``--json``."""
    parser.add_argument("--scene", default=None, metavar="NAME",
                        help="scene of the .blend (default: the active scene)")
    parser.add_argument("--out", required=True, type=path_arg, metavar="SHOT_USD",
                        help="main layer to write (.usdc, .usd or .usda); its folder "
                             "is created if missing")
    parser.add_argument("--frames", type=frame_range, metavar="FIRST-LAST",
                        help="shot frames, inclusive; FIRST must not be before the "
                             "crowd's start frame (default, from a .blend: the scene's "
                             "frame range; with --config it must be given)")
    parser.add_argument("--agents", type=int_at_least(1), default=None, metavar="N",
                        help="export only the first N agents (ids 0..N-1); more than the "
                             "crowd has is an error (default: all)")
    parser.add_argument("--layout", choices=USD_LAYOUTS, default=USD_LAYOUTS[0],
                        help="instanced (default): agents are instanceable, renderers "
                             "share each character; blender: agents are not instanceable, "
                             "so Blender's own USD import plays their animation "
                             "and (Blender 4.5 and later) shows their colours")
    parser.add_argument("--substeps", type=int_at_least(1, MAX_SUBSTEPS), default=1, metavar="N",
                        help="poses written per frame, 1-%d (default 1): more adds samples "
                             "between frames, the crowd evaluated there, for renderers' "
                             "motion blur" % MAX_SUBSTEPS)
    parser.add_argument("--snapshots", type=path_arg, default=None, metavar="DIR",
                        help="snapshot folder (crowd snapshot, docs/snapshots.md): start "
                             "from this crowd's latest snapshot there before the first "
                             "frame instead of simulating from the start frame, and leave "
                             "one there at the last frame for the next chunk (the folder "
                             "is created if missing)")
    parser.add_argument("--animation-only", action="store_true",
                        help="for a chunk after a shot's first: write only what crowd "
                             "stitch reads (no agent prims, characters or offset "
                             "animations; not a stage to open on its own), which makes "
                             "the chunk several times cheaper (docs/snapshots.md)")
    add_repetition_arguments(parser)
    parser.add_argument("--json", action="store_true",
                        help="print the summary as one JSON object")
    add_trust_argument(parser)


def add_repetition_arguments(parser, frames: bool = True) -> None:
    """``--neighbours`` and (``frames``) ``--repetition-frames``: the repetition
    metric's settings (:func:`repetition_settings`)."""
    parser.add_argument("--neighbours", type=int_at_least(1), default=6, metavar="K",
                        help="repetition metric: screen-space neighbours compared per "
                             "agent (default 6; docs/variety.md)")
    if frames:
        parser.add_argument("--repetition-frames", type=int_at_least(0), default=8,
                            metavar="N", help="repetition metric: frames measured, spread "
                                              "over the shot (default 8; 0: not measured)")


def repetition_settings(args, **size):
    """The :class:`~crowd_addon.core.variety.repetition.RepetitionSettings` of parsed
    arguments (:func:`add_repetition_arguments`), None when ``--repetition-frames`` is
    0; ``size``: ``width``/``height`` of the screen."""
    from .core.variety.repetition import RepetitionSettings
    frames = getattr(args, "repetition_frames", 1)
    if frames == 0:
        return None
    return RepetitionSettings(k=args.neighbours, frames=frames, **size)


def add_trust_argument(parser) -> None:
    """``--trust-scripts``: run a .blend's crowd script in this command;
    ``--ignore-scripts``: go on without it (docs/show.md). Without either, a crowd
    script that is not trusted here stops the command with exit code 3."""
    scripts = parser.add_mutually_exclusive_group()
    scripts.add_argument("--trust-scripts", action="store_true",
                         help="run the .blend's crowd script (scene.crowd.show.script) in "
                              "this command even where Blender does not trust scripts in "
                              ".blend files; nothing stays trusted after it")
    scripts.add_argument("--ignore-scripts", action="store_true",
                         help="go on without the .blend's crowd script: it does not run in "
                              "this command, trusted or not (without this, a script that "
                              "is not trusted here stops the command with exit code 3)")
    parser.add_argument("--strict", action="store_true",
                        help="with --blend: a bake report with warnings (poses between "
                             "frames that miss the action's, vertices with more than 8 "
                             "bone influences, LOD levels refused) is an error, exit code "
                             "2, nothing written (for farms); the notes are printed on "
                             "stderr either way")


def _frames_joined(argv) -> list:
    """``argv`` with a negative frame range after ``--frames`` (``--frames -5-3``, or
    an abbreviation of the option) joined to it as ``--frames=-5-3``: argparse takes a
    word that starts with ``-`` and is not a plain negative number for an option, so
    it would stop with "expected one argument". Nothing after ``--`` is touched."""
    words = list(argv)
    joined = []
    while words:
        word = words.pop(0)
        if word == "--":
            return joined + [word] + words
        if (word.startswith("--f") and "--frames".startswith(word) and words
                and words[0].startswith("-") and _FRAME_RANGE.fullmatch(words[0])):
            word = f"{word}={words.pop(0)}"
        joined.append(word)
    return joined


def parse_command(parser, argv):
    """``(args, None)`` for ``argv`` (None: ``sys.argv[1:]``) parsed by ``parser`` (with
    subcommands in ``command``), or ``(None, exit code)`` when there is nothing to run:
    ``--help`` (0), a usage error argparse has printed (2), no command (help printed,
    2). A negative ``--frames`` value may follow the option as its own word
    (``--frames -5-3``), as with ``=``."""
    try:
        args = parser.parse_args(_frames_joined(sys.argv[1:] if argv is None else argv))
    except SystemExit as exc:
        return None, exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    if args.command is None:
        parser.print_help(sys.stderr)
        return None, 2
    return args, None
