"""A minimal PNG writer (zlib + struct, no dependency): 8-bit RGB or RGBA images."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from ..core.base.errors import CrowdError
from ..core.base.files import write_atomic

__all__ = ["encode_png", "write_png"]


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def encode_png(image: np.ndarray, level: int = 6) -> bytes:
    """PNG bytes of ``image``: ``(H, W, 3)`` or ``(H, W, 4)`` uint8, first row at the top."""
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4) \
            or 0 in img.shape[:2]:
        raise CrowdError(f"PNG image must be (H, W, 3 or 4) uint8, got {img.shape} {img.dtype}")
    h, w, c = img.shape
    rows = np.zeros((h, 1 + w * c), np.uint8)         # filter byte 0 (None) per row
    rows[:, 1:] = img.reshape(h, w * c)
    header = struct.pack(">IIBBBBB", w, h, 8, 6 if c == 4 else 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
            + _chunk(b"IDAT", zlib.compress(rows.tobytes(), level)) + _chunk(b"IEND", b""))


def write_png(path, image: np.ndarray, level: int = 6) -> Path:
    """Write ``image`` to ``path`` through a temporary file and a rename, so a failure
    never leaves a half-written file (not synced: frames are many, and made again)."""
    path = Path(path)
    data = encode_png(image, level)
    write_atomic(path, lambda f: f.write(data), "the PNG", sync=False)
    return path
