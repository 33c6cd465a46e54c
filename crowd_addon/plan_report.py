"""What ``crowd plan`` shows: the candidates as a table and as a plot.

:func:`table` lists every candidate of a
:class:`~crowd_addon.core.planning.variety_plan.VarietyPlan` (M, copies, offsets, streams,
memory, metric), the default and the chosen one marked; :func:`plot` draws the metric
against M, one line per copies count and offset mode, with the chosen point and the
default marked, into an image file (matplotlib, the ``plot`` extra) whose format its
extension names (:data:`PLOT_FORMATS`; :func:`plot_target` checks the name before any
work).
"""

from __future__ import annotations

import io
import os

import numpy as np

from .core.base.errors import CrowdError
from .core.base.files import write_atomic

__all__ = ["table", "plot", "plot_target", "summary_lines", "metric_text", "PLOT_FORMATS"]

_MB = 1e6

#: The plot's file formats, by extension: matplotlib's that need no other program
#: (its ``pgf`` needs LaTeX; ``raw``/``rgba`` are bare pixels no viewer opens).
PLOT_FORMATS = ("png", "svg", "pdf", "eps", "jpg", "jpeg", "tif", "tiff")


def metric_text(v) -> str:
    """A metric value for people: four decimals, two significant digits when tiny,
    "-" for none."""
    if v is None:
        return "-"
    return f"{v:.4f}" if v >= 1e-3 or v == 0 else f"{v:.1e}"


def table(result) -> str:
    """Every candidate, one line each; ``*`` the planned one."""
    rows = [f"{'M':>5} {'copies':>6} {'offsets':>8} {'streams':>7} {'memory MB':>10} "
            f"{'repetition':>10}"]
    for c in result.candidates:
        mark = " *" if c == result.planned else ("  (over budget)" if not c.fits else "")
        rows.append(f"{c.max_offset:>5} {c.copies:>6} {c.offset_mode.lower():>8} "
                    f"{c.streams:>7} {c.bytes / _MB:>10.2f} "
                    f"{metric_text(c.repetition):>10}{mark}")
    return "\n".join(rows)


def summary_lines(result) -> list:
    """The default, the plan and what changes, for a terminal or a panel."""
    d, p = result.default, result.planned
    lines = [
        f"default: M {d.max_offset}, {d.streams} streams, offsets as placed, "
        f"{d.bytes / _MB:.2f} MB: repetition {metric_text(d.repetition)}",
        f"planned: M {p.max_offset}, {p.copies} cop{'ies' if p.copies != 1 else 'y'} of "
        f"each speed stream, {p.offset_mode.lower()} offsets, {p.streams} streams, "
        f"{p.bytes / _MB:.2f} MB: repetition {metric_text(p.repetition)}"]
    if d.repetition and p.repetition is not None:
        lines.append(f"  {d.repetition / max(p.repetition, 1e-9):,.0f}x less repetition"
                     if p.repetition < d.repetition else "  no candidate repeats less")
    lines.append(f"  budget {result.budget_bytes / _MB:,.1f} MB, at most "
                 f"{result.max_streams} streams; {result.visible:,} of {result.agents:,} "
                 f"agents in view, k = {result.settings.k}"
                 + ("" if result.settings.appearance else "; motion only"))
    return lines + [f"  note: {n}" for n in result.notes]


def plot_target(path) -> str:
    """The file a plot named ``path`` goes to: ``path`` itself when its extension is one
    of :data:`PLOT_FORMATS` (any case), ``path`` + ``.png`` when it has none. A folder,
    a name ending in a separator and another extension are CrowdErrors naming it."""
    path = os.fspath(path)
    if path.endswith(("/", os.sep)) or os.path.isdir(path):
        raise CrowdError(f"--plot {path}: is a folder (name the plot's file, e.g. "
                         f"{os.path.join(path, 'plan.png')})")
    ext = os.path.splitext(path)[1]
    if not ext:
        return plot_target(path + ".png")
    if ext[1:].lower() not in PLOT_FORMATS:
        raise CrowdError(f"--plot {path}: {ext!r} is no plot format; use "
                         f"{', '.join('.' + f for f in PLOT_FORMATS)} (none: .png)")
    return path


def plot(result, path, title: str = "") -> str:
    """Write the plot to the file :func:`plot_target` makes of ``path``, whole or not at
    all (an earlier file there stays as it was when writing fails); returns that file's
    path."""
    path = plot_target(path)
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise CrowdError("the plot needs matplotlib: pip install 'crowd_addon[plot]' (or "
                         "leave the plot out with --no-plot)") from None
    fig, ax = plt.subplots(figsize=(8, 5), dpi=120)
    copies = sorted({c.copies for c in result.candidates})
    colours = plt.get_cmap("viridis")(
        [i / max(len(copies) - 1, 1) * 0.85 for i in range(len(copies))])
    for mode, style in (("UNIFORM", "--"), ("SPREAD", "-")):
        for colour, k in zip(colours, copies):
            pts = sorted((c.max_offset, c.repetition) for c in result.candidates
                         if c.copies == k and c.offset_mode == mode and c.fits
                         and c.repetition is not None)
            if pts:
                ax.plot(*zip(*pts), style, color=colour, marker=".",
                        label=f"{k} cop{'ies' if k != 1 else 'y'}, {mode.lower()}")
    d, p = result.default, result.planned
    if d.repetition is not None:
        ax.plot([d.max_offset], [d.repetition], "o", color="black", markersize=9,
                label=f"default (M {d.max_offset}): {metric_text(d.repetition)}")
    ax.plot([p.max_offset], [p.repetition], "*", color="crimson", markersize=16,
            label=f"planned (M {p.max_offset}, {p.copies} copies, "
                  f"{p.offset_mode.lower()}): {metric_text(p.repetition)}")
    ax.set_xlabel("M, frames of pose history per stream")
    ax.set_ylabel(f"repetition (share of {result.settings.k} nearest on screen alike)")
    values = [c.repetition for c in result.candidates if c.repetition is not None]
    values += [v for v in (d.repetition, p.repetition) if v is not None]
    positive = [v for v in values if v > 0]
    if positive and max(positive) > 10 * min(positive):
        # decades, and 0 (no pair alike) still on the axis below the smallest value
        ax.set_yscale("symlog", linthresh=10.0 ** np.floor(np.log10(min(positive))))
    ax.set_ylim(bottom=0.0)
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"{result.agents:,} agents, budget "
                          f"{result.budget_bytes / _MB:,.0f} MB, at most "
                          f"{result.max_streams} streams"
                          + ("" if result.settings.appearance else ", motion only"))
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    image = io.BytesIO()
    try:
        fig.savefig(image, format=os.path.splitext(path)[1][1:].lower())
    finally:
        plt.close(fig)
    write_atomic(path, lambda f: f.write(image.getbuffer()), "the plot")
    return path
