"""Reading back the PNGs the preview writes (crowd_addon.gpu.png: 8-bit RGB, filter 0
rows), independently of the writer, for tests that look at pixels."""

import zlib
from pathlib import Path

import numpy as np


def read_png(path):
    """(H, W, 3) uint8 pixels of an 8-bit RGB PNG whose rows all use filter 0."""
    data = Path(path).read_bytes()
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h = int.from_bytes(body[:4], "big"), int.from_bytes(body[4:8], "big")
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + 3 * w)
    assert (raw[:, 0] == 0).all(), "unexpected PNG filter"
    return raw[:, 1:].reshape(h, w, 3)
