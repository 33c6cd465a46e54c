"""A contact sheet: a few frames of a shot side by side in one image, so a shot can be
judged at a glance (``crowd demo`` writes ``contact_sheet.png``).

:class:`ContactSheet` keeps a reduced copy of the frames it is offered that fall on
its chosen frames (evenly spread over the shot) and lays them out in a grid with a
thin border; nothing but numpy.
"""

from __future__ import annotations

import numpy as np

from ..core.base.errors import CrowdError

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
    row, ``border`` pixels apart."""

    def __init__(self, frames, columns: int = 3, scale: int = 2, border: int = 4):
        if columns < 1 or scale < 1 or border < 0:
            raise CrowdError(f"contact sheet: columns {columns}, scale {scale} and border "
                             f"{border} must be positive")
        self.frames = list(frames)
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
        for i, cell in enumerate(cells):
            y, x = b + (i // cols) * (ch + b), b + (i % cols) * (cw + b)
            sheet[y:y + ch, x:x + cw] = cell
        return sheet
