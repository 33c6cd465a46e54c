"""The contact sheet's layout and reduction against hand-made images."""

import numpy as np
import pytest

from crowd_addon.core.base.errors import CrowdError
from crowd_addon.gpu.contact_sheet import ContactSheet, sheet_frames


def test_frames_spread_over_the_shot_with_both_ends():
    assert sheet_frames(1, 240, 6) == [1, 49, 97, 144, 192, 240]
    assert sheet_frames(5, 7, 6) == [5, 6, 7]              # a short shot: fewer cells
    with pytest.raises(CrowdError, match="bad frames"):
        sheet_frames(10, 9, 6)


def test_cells_are_box_filtered_frames_in_order_row_by_row():
    sheet = ContactSheet([3, 1, 2], columns=2, scale=2, border=1)
    images = {f: np.full((4, 6, 3), 10 * f, np.uint8) for f in (1, 2, 3)}
    images[1][0, 0] = (50, 50, 50)                          # one bright pixel: a mean
    for f in (2, 9, 1, 3, 1):                               # 9 is not a sheet frame
        sheet.offer(f, images.get(f, np.zeros((4, 6, 3), np.uint8)))
    img = sheet.image()
    assert img.shape == (2 * 3 + 1, 2 * 4 + 1, 3)
    assert tuple(img[1, 1]) == (20, 20, 20)                 # (50 + 3 x 10) / 4
    assert (img[1:3, 5:8] == 20).all() and (img[4:6, 1:4] == 30).all()
    assert (img[4:6, 5:8] == 24).all()                      # the empty cell: border colour
    assert (img[0] == 24).all()
    with pytest.raises(CrowdError, match="no frames"):
        ContactSheet([1]).image()
