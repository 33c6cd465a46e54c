"""The pose texture (paper Fig. 2) as a CPU mirror, and the blocks to upload per frame.

Layout (docs/architecture.md, in *logical rows*: stream rows ``slice * S + stream`` for
``slice = F mod M``, then ``U`` unique rows, then ``NT`` transition-slot rows. A row
is one pose: ``B_max`` bones x 3 texels (RGBA32F), the top three rows of each
bone's skinning matrix, bone-major (texel ``3 * bone + r``).

Logical row ``r`` lives in the texture at texel ``x = (r // H) * 3 * B_max``,
``y = r % H`` where ``H = min(rows, max_texture_size)``: when the rows do not fit
the texture's height they wrap into column blocks side by side. The shader's row
lookup (gpu_shaders/) mirrors :meth:`PoseStorage.texel_of_row`.

With GPU skinning (``Crowd(config, gpu_skinning=True)``) the CPU keeps a
*local-pose* texture of the same geometry instead: each bone's three texels hold
its local SQT ``(sx, sy, sz, qw), (qx, qy, qz, tx), (ty, tz, 0, 0)``, so the
history is a strided view of the mirror (:meth:`PoseStorage.sqt_view`) and the
GPU turns rows into skinning matrices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import CrowdError

__all__ = ["PoseStorage", "PoseLayout", "TextureRegion", "LOCAL_IDENTITY", "LOCAL_FLOATS",
           "block_layout"]

#: A local-pose texture keeps a bone's SQT in the first ten of its twelve texel floats.
LOCAL_FLOATS = 10

#: A local-pose texture row entry of the identity SQT: the ten SQT floats
#: ``(sx, sy, sz, qw, qx, qy, qz, tx, ty, tz)`` then two zeros, as three RGBA texels.
LOCAL_IDENTITY = np.array([[1, 1, 1, 1], [0, 0, 0, 0], [0, 0, 0, 0]], np.float32)


@dataclass(frozen=True)
class TextureRegion:
    """Texels ``x .. x + width``, ``y .. y + height`` of a texture to write.

    ``data`` is a C-contiguous ``(height, width, channels)`` array (float32 or int32;
    for the pose texture a view of the mirror); ``rows`` the logical row range
    ``(first, end)`` it holds in a block-laid texture (``(0, 0)`` otherwise).
    """

    x: int
    y: int
    width: int
    height: int
    data: np.ndarray
    rows: tuple = (0, 0)

    @property
    def nbytes(self) -> int:
        return int(self.data.nbytes)


def block_layout(rows: int, row_texels: int, max_texture_size: int, what: str) -> tuple:
    """``(height, blocks, width)`` of ``rows`` logical rows of ``row_texels`` texels
    laid out in column blocks: row ``r`` starts at texel ``((r // height) *
    row_texels, r % height)`` (``block_layout.glsl``). The pose textures, the agent
    texture and the looks texture all use it; CrowdError names ``what`` cannot fit
    in ``max_texture_size``."""
    limit = int(max_texture_size)
    if row_texels > limit:
        raise CrowdError(f"{what} cannot fit: a row of {row_texels} texels, max texture "
                         f"size is {limit}")
    height = max(1, min(rows, limit))
    blocks = max(1, -(-rows // height))
    width = blocks * row_texels
    if width > limit:
        raise CrowdError(f"{what} cannot fit: {rows} rows of {row_texels} texels need "
                         f"{blocks} column blocks ({width} x {height} texels), max "
                         f"texture size is {limit}")
    return height, blocks, width


@dataclass(frozen=True)
class PoseLayout:
    """The pose texture's geometry, in logical rows (see the module docstring).

    streams S, max_offset M, uniques U, slots NT, bones B_max; row_texels = 3 * B_max;
    row_count = M * S + U + NT; height (rows a column block holds), blocks, width in
    texels; unique_base = M * S and slot_base = M * S + U, the first unique and slot
    rows.
    """

    streams: int
    max_offset: int
    uniques: int
    slots: int
    bones: int
    row_texels: int
    row_count: int
    height: int
    blocks: int
    width: int
    unique_base: int
    slot_base: int

    def texel_of_row(self, row):
        """Texel ``(x, y)`` of the first texel of logical ``row`` (arrays allowed)."""
        row = np.asarray(row)
        return (row // self.height) * self.row_texels, row % self.height


class PoseStorage:
    """CPU mirror of the pose texture with per-frame dirty row ranges.

    Parameters
    ----------
    streams, max_offset, uniques, slots : S, M, U, NT.
    bones : B_max, bones per row.
    max_texture_size : the GPU's largest texture side in texels (GL_MAX_TEXTURE_SIZE).
    fill : (3, 4) initial value of every bone's entry; default the identity matrix rows
        (a skinning-matrix texture). :data:`LOCAL_IDENTITY` for a local-pose texture.

    Attributes
    ----------
    rows : (R, B_max, 3, 4) float32 logical rows (identity matrices initially).
    width, height : texture size in texels.
    """

    def __init__(self, streams, max_offset, uniques, slots, bones, max_texture_size=16384,
                 fill=None):
        self.S, self.M, self.U, self.NT = int(streams), int(max_offset), int(uniques), int(slots)
        self.bones = int(bones)
        self.row_texels = 3 * self.bones
        self.max_texture_size = int(max_texture_size)
        n = self.M * self.S + self.U + self.NT
        self.row_count = n
        self.height, self.blocks, self.width = block_layout(
            n, self.row_texels, self.max_texture_size,
            f"pose texture ({self.bones} bones a row; lower M, streams or transition slots)")
        self.rows = np.zeros((n, self.bones, 3, 4), np.float32)
        if fill is None:
            self.rows[:, :, 0, 0] = self.rows[:, :, 1, 1] = self.rows[:, :, 2, 2] = 1
        else:
            self.rows[:] = fill
        self.unique_base = self.M * self.S
        self.slot_base = self.M * self.S + self.U
        self.layout = PoseLayout(self.S, self.M, self.U, self.NT, self.bones, self.row_texels,
                                 n, self.height, self.blocks, self.width, self.unique_base,
                                 self.slot_base)
        self._dirty = []
        #: per logical row, the count of marks (:meth:`mark_dirty`) when it was last
        #: written: a reader that keeps what it made of a row (Render Crowd's pose
        #: meshes) compares them to know what changed since
        self.version = np.zeros(n, np.int64)
        self._marks = 0

    @property
    def nbytes(self) -> int:
        return int(self.rows.nbytes)

    @property
    def row_bytes(self) -> int:
        return self.row_texels * 16

    def texel_of_row(self, row):
        """Texel ``(x, y)`` of the first texel of logical ``row`` (arrays allowed)."""
        return self.layout.texel_of_row(row)

    def stream_slice(self, slice_) -> np.ndarray:
        """View ``(S, B_max, 3, 4)`` of one history slice's rows."""
        a = slice_ * self.S
        return self.rows[a:a + self.S]

    def unique_rows(self) -> np.ndarray:
        return self.rows[self.unique_base:self.slot_base]

    def slot_rows(self) -> np.ndarray:
        return self.rows[self.slot_base:]

    def sqt_view(self) -> np.ndarray:
        """The rows of a local-pose texture as SQT poses ``(R, B_max, 10)``: a strided
        view (writes land in the texture mirror), the first ten of each bone's twelve
        floats."""
        return self.rows.reshape(self.row_count, self.bones, 12)[..., :LOCAL_FLOATS]

    # dirty tracking -----------------------------------------------------------
    def mark_dirty(self, start, count):
        """Mark ``count`` logical rows from ``start`` as changed (to upload)."""
        if count > 0:
            self._dirty.append((int(start), int(count)))
            self._marks += 1
            self.version[int(start):int(start) + int(count)] = self._marks

    def mark_rows_dirty(self, rows: np.ndarray):
        """Mark arbitrary rows, merged into contiguous runs."""
        rows = np.unique(np.asarray(rows, np.int64))
        if rows.size == 0:
            return
        first = np.flatnonzero(np.r_[True, np.diff(rows) != 1])
        counts = np.diff(np.r_[first, rows.size])
        self._dirty.extend(zip(rows[first].tolist(), counts.tolist()))
        self._marks += 1
        self.version[rows] = self._marks

    def mark(self) -> int:
        """A bookmark for :meth:`bytes_since`."""
        return len(self._dirty)

    def bytes_since(self, mark: int) -> int:
        """Bytes of the rows marked dirty after ``mark`` (overlaps counted once)."""
        return sum(c for _, c in self.merged(self._dirty[mark:])) * self.row_bytes

    def dirty_ranges(self) -> list:
        """Changed ``(start, count)`` row ranges since the last take, merged and sorted."""
        return self.merged(self._dirty)

    @staticmethod
    def merged(ranges) -> list:
        out = []
        for start, count in sorted(ranges):
            if out and start <= out[-1][0] + out[-1][1]:
                s0, c0 = out[-1]
                out[-1] = (s0, max(c0, start + count - s0))
            else:
                out.append((start, count))
        return out

    def dirty_bytes(self) -> int:
        return sum(c for _, c in self.dirty_ranges()) * self.row_bytes

    def take_dirty_regions(self) -> list:
        """The texture rectangles to upload (split at column-block boundaries) for
        everything changed since the last call, which they clear."""
        out = []
        flat = self.rows.reshape(self.row_count, self.row_texels, 4)
        for start, count in self.dirty_ranges():
            r, end = start, start + count
            while r < end:
                block, y = divmod(r, self.height)
                n = min(end - r, self.height - y)
                out.append(TextureRegion(block * self.row_texels, y, self.row_texels, n,
                                        flat[r:r + n], (r, r + n)))
                r += n
        self._dirty = []
        return out

    def texture_image(self) -> np.ndarray:
        """The whole texture ``(height, width, 4)`` float32 as the GPU holds it."""
        img = np.zeros((self.height, self.width, 4), np.float32)
        flat = self.rows.reshape(self.row_count, self.row_texels, 4)
        for b in range(self.blocks):
            part = flat[b * self.height:(b + 1) * self.height]
            img[:part.shape[0], b * self.row_texels:(b + 1) * self.row_texels] = part
        return img
