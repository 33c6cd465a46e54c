"""Argument converters and progress printing shared by the two command lines: the
headless ``crowd`` program (:mod:`crowd_addon.cli`) and Blender's ``-c crowd``
command (:mod:`crowd_addon.blender.cli_commands`). A leaf module: it imports nothing
else of this project, so both may use it without a cycle."""

from __future__ import annotations

import argparse
import math
import re
import sys

__all__ = ["int_at_least", "positive_float", "frame_range", "progress_printer"]


def int_at_least(minimum: int):
    """An argparse type: an integer ``>= minimum``."""
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
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


def frame_range(text: str) -> tuple:
    """An argparse type: ``"FIRST-LAST"`` (e.g. ``1-300``, ``-10-20``) or ``"N"`` ->
    ``(first, last)`` ints, ``first <= last``."""
    m = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?", text)
    if m is None:
        raise argparse.ArgumentTypeError(f"must be FIRST-LAST or a frame, got {text!r}")
    first = int(m.group(1))
    last = first if m.group(2) is None else int(m.group(2))
    if last < first:
        raise argparse.ArgumentTypeError(f"last frame {last} is before first frame {first}")
    return first, last


positive_float.__name__ = "number"
frame_range.__name__ = "frame range"


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
