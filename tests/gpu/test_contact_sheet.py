"""The contact sheet's layout, reduction and captions against hand-made images and
the caption font's own glyphs."""

import numpy as np
import pytest

from crowd_addon.core.base.errors import CrowdError
from crowd_addon.gpu.caption_font import GLYPHS, draw_text, text_width
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


def test_text_is_the_fonts_glyphs_side_by_side_scaled_and_clipped():
    img = np.zeros((20, 40, 3), np.uint8)
    draw_text(img, "a1", 1, 2, color=(200, 100, 50), scale=2)
    lit = (img == (200, 100, 50)).all(-1)
    assert lit.sum() == 4 * (GLYPHS["A"].sum() + GLYPHS["1"].sum())
    a = np.repeat(np.repeat(GLYPHS["A"], 2, 0), 2, 1)      # lower case drawn upper case
    assert np.array_equal(lit[2:16, 1:11], a)
    assert np.array_equal(lit[2:16, 13:23], np.repeat(np.repeat(GLYPHS["1"], 2, 0), 2, 1))
    assert not lit[:, 23:].any() and not lit[:2].any()
    assert text_width("a1", 2) == 22
    edge = np.zeros((7, 3, 3), np.uint8)                   # cut at the image's edge
    draw_text(edge, "T", 0, 0)
    assert (edge[..., 0] > 0).sum() == GLYPHS["T"][:, :3].sum()
    draw_text(edge, "~", 0, 0)                              # unknown: a space, no error


def test_each_cell_is_captioned_with_its_frame_and_beat_on_a_darkened_band():
    frames = (5, 107)
    sheet = ContactSheet(frames, columns=2, scale=1, border=0,
                         labels={107: "goal +60: the home fans up"})
    for f in frames:
        sheet.offer(f, np.full((60, 480, 3), 200, np.uint8))
    img = sheet.image()
    plain, goal = img[:, :480], img[:, 480:]
    # above the band the frames are untouched; the band is darkened, the text white,
    # one size for every cell: the longest caption fits twice as large at 480 pixels
    top = 60 - 7 * 2 - 2 * 2 * 2
    assert (plain[:top] == 200).all() and (goal[:top] == 200).all()
    assert ((plain[top:] == 70) | (plain[top:] == 255)).all()
    white = [(c[top:] == 255).all(-1) for c in (plain, goal)]
    assert 0 < white[0].sum() < white[1].sum()              # "FRAME 5" < the beat's
    expected = np.zeros((60, 480, 3), np.uint8)
    draw_text(expected, "FRAME 107  GOAL +60: THE HOME FANS UP", 4, 60 - 18, scale=2)
    assert np.array_equal((expected == 255).all(-1), (goal == 255).all(-1))
