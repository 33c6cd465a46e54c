"""A contact sheet: a few frames of a shot side by side in one image, so a shot can be
judged at a glance (``crowd demo`` writes ``contact_sheet.png``).

:class:`ContactSheet` keeps a reduced copy of the frames it is offered that fall on
its chosen frames (evenly spread over the shot) and lays them out in a grid with a
thin border, each cell captioned with its frame and what happens there (the demo's
beats: "FRAME 107  GOAL +60: THE HOME FANS UP") in :mod:`.caption_font`; nothing but
numpy.
"""

from __future__ import annotations

import numpy as np

from ..core.base.errors import CrowdError
from .caption_font import GLYPH_H, draw_text, text_width

__all__ = ["ContactSheet", "sheet_frames"]

_BORDER = (24, 24, 24)


def sheet_frames(first: int, last: int, count: int) -> list:
    """``count`` frames spread evenly over ``first..last`` (both ends included; fewer
    when the shot is shorter)."""
    if last < first or count < 1:
        raise CrowdError(f"contact sheet: bad frames {first}..{last} or count {count}")
    return sorted({int(round(v)) for v in np.linspace(first, last, count)})


class ContactSheet:
    """Collects frames ``frames`` (crowd frame numbers) of ``(H, W, 3)`` uint8 images,
    each reduced by ``scale`` (an integer: box filter) to a cell, ``columns`` cells a
    row, ``border`` pixels apart. ``labels``: frame -> what happens there, captioned
    on the cell's bottom edge after its frame number."""

    def __init__(self, frames, columns: int = 3, scale: int = 2, border: int = 4,
                 labels=None):
        if columns < 1 or scale < 1 or border < 0:
            raise CrowdError(f"contact sheet: columns {columns}, scale {scale} and border "
                             f"{border} must be positive")
        self.frames = list(frames)
        self.labels = dict(labels or {})
        self.columns, self.scale, self.border = int(columns), int(scale), int(border)
        self.cells = {}

    def offer(self, frame: int, image: np.ndarray) -> None:
        """Keep ``image`` when ``frame`` is one of the sheet's frames."""
        if frame in self.frames and frame not in self.cells:
            s = self.scale
            h, w = (image.shape[0] // s) * s, (image.shape[1] // s) * s
            cell = image[:h, :w, :3].astype(np.float32)
            cell = cell.reshape(h // s, s, w // s, s, 3).mean((1, 3))
            self.cells[frame] = np.rint(cell).astype(np.uint8)

    def image(self) -> np.ndarray:
        """The sheet ``(H, W, 3)`` uint8, cells in frame order, row by row."""
        if not self.cells:
            raise CrowdError("contact sheet: no frames were kept")
        cells = [self.cells[f] for f in sorted(self.cells)]
        ch, cw = cells[0].shape[:2]
        cols = min(self.columns, len(cells))
        rows = -(-len(cells) // cols)
        b = self.border
        sheet = np.empty((rows * (ch + b) + b, cols * (cw + b) + b, 3), np.uint8)
        sheet[:] = _BORDER
        texts = {f: f"FRAME {f}" + (f"  {self.labels[f]}" if self.labels.get(f) else "")
                 for f in self.cells}
        # one text size for the sheet: font pixels of 1 to 3 image pixels, as large as
        # the longest caption fits; no captions on cells under four text lines tall
        longest = max(text_width(t) for t in texts.values())
        scale = min(3, (cw - 8) // max(longest, 1), ch // (4 * GLYPH_H))
        for i, (frame, cell) in enumerate(zip(sorted(self.cells), cells)):
            y, x = b + (i // cols) * (ch + b), b + (i % cols) * (cw + b)
            sheet[y:y + ch, x:x + cw] = cell
            if ch >= 4 * GLYPH_H:
                _caption(sheet[y:y + ch, x:x + cw], texts[frame], max(scale, 1))
        return sheet


def _caption(cell: np.ndarray, text: str, scale: int) -> None:
    """``text`` on a darkened band along the cell's bottom edge (cut short where it is
    too wide)."""
    h, w = cell.shape[:2]
    pad = 2 * scale
    while text and text_width(text, scale) > w - 2 * pad:
        text = text[:-1]
    band = cell[h - GLYPH_H * scale - 2 * pad:]
    band[:] = (band * 0.35).astype(np.uint8)
    draw_text(band, text, pad, pad, scale=scale)
