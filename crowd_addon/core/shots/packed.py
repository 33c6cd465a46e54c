"""Exact compact forms of a snapshot's state arrays (:class:`Packed`, :func:`pack`).

A crowd's state is mostly poses, and most of them repeat: streams of one template
playing the same clip show the same pose at the same time, a pose's scale and most
bones' translations never change, idle transition slots hold the same start pose.
:func:`pack` keeps each array in the smallest of three forms, every one bit for bit
(floats are compared and copied as their bit patterns, so NaN payloads and -0.0
survive):

* ``raw``: the array itself (``data``);
* ``ints``: an integer array in the narrowest integer type that holds its smallest
  and largest values (``data``), widened back on unpack;
* ``rows``: a float array as rows (a pose: the last two axes of an array of three or
  more, else everything after the first axis): the distinct rows, only in the columns
  where they differ (``rows``, ``(U, len(columns))``), which row each row is
  (``index``), those columns (``columns``) and one row for the other columns
  (``fill``).

Distinct rows are found by hashing a sample of each row's columns, then every row is
compared whole with the row it was matched to; the rows the sample matched wrongly
are told apart exactly among themselves (sorted by all their bits), so the hash only
decides how fast packing is, never whether the result is exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Packed", "pack", "CODECS", "PARTS"]

#: each codec's parts, in the order a file lists them
PARTS = {"raw": ("data",), "ints": ("data",), "rows": ("rows", "index", "columns", "fill")}
CODECS = tuple(PARTS)
#: arrays smaller than this stay raw (a packed form's bookkeeping outweighs them)
MIN_BYTES = 4096
#: columns of a row the hash reads (evenly spaced)
HASH_COLUMNS = 64
#: rows :meth:`Packed.unpack_into` gathers at a time (a few MB: kept in cache)
_BLOCK = 256
_MULTIPLIERS = (np.random.default_rng(0x5EED).integers(1, 2 ** 63, HASH_COLUMNS,
                                                       dtype=np.uint64) | np.uint64(1))


@dataclass(frozen=True, eq=False)
class Packed:
    """One state array in a compact exact form: ``codec`` (:data:`CODECS`), the
    array's ``dtype`` and ``shape``, and the codec's ``parts`` (:data:`PARTS`).
    ``np.asarray(packed)`` is the array."""

    codec: str
    dtype: np.dtype
    shape: tuple
    parts: dict

    @property
    def nbytes(self) -> int:
        """Bytes of the parts (what the packed array costs)."""
        return int(sum(p.nbytes for p in self.parts.values()))

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def unpack(self) -> np.ndarray:
        """The array (a new one)."""
        p = self.parts
        if self.codec == "raw":
            return np.array(p["data"], copy=True)
        if self.codec == "ints":
            return p["data"].astype(self.dtype)
        fill, columns, rows, index = p["fill"], p["columns"], p["rows"], p["index"]
        distinct = np.repeat(fill[None], rows.shape[0], axis=0)
        distinct[:, columns] = rows
        return distinct[index].reshape(self.shape)

    def unpack_into(self, dest: np.ndarray) -> None:
        """``dest[...] = self.unpack()`` without the whole array made first (rows are
        gathered into ``dest`` a block at a time). ValueError when ``dest`` is not of
        this shape and dtype."""
        if dest.shape != self.shape or dest.dtype != self.dtype:
            raise ValueError(f"{self.dtype.str} {list(self.shape)} cannot go into "
                             f"{dest.dtype.str} {list(dest.shape)}")
        if self.codec != "rows" or dest.ndim < 3 or dest.strides[-1] != dest.itemsize:
            dest[...] = self.unpack()
            return
        p = self.parts
        fill, columns, packed, index = p["fill"], p["columns"], p["rows"], p["index"]
        rows = dest.reshape(-1, *dest.shape[-2:])           # a view, or a copy...
        distinct = np.repeat(fill[None], packed.shape[0], axis=0)
        distinct[:, columns] = packed
        # a block of rows at a time through one buffer: gathered in cache, then written
        block = np.empty((min(_BLOCK, index.size), fill.size), fill.dtype)
        # each pose's bones copied as whole records (a padded layout's bones lie apart)
        into, whole = _records(rows), _records(block.reshape(block.shape[0], *rows.shape[1:]))
        for start in range(0, index.size, _BLOCK):
            n = min(_BLOCK, index.size - start)
            np.take(distinct, index[start:start + n], axis=0, out=block[:n])
            into[start:start + n] = whole[:n]
        if not np.shares_memory(rows, dest):                 # ...written back
            dest[...] = rows.reshape(dest.shape)

    def __array__(self, dtype=None, copy=None):
        a = self.unpack()
        return a if dtype is None else a.astype(dtype, copy=False)

    def element_values(self) -> list:
        """Arrays holding every value the array holds (and no other): what a check of
        its values (finite, in range) may read without unpacking."""
        p = self.parts
        if self.codec == "rows":
            return [p["rows"], p["fill"][np.setdiff1d(np.arange(p["fill"].size),
                                                      p["columns"])]]
        return [p["data"]]

    @classmethod
    def from_parts(cls, codec: str, dtype, shape, parts: dict) -> "Packed":
        """A packed array read back (a file): ValueError naming what does not fit
        (unknown codec or dtype, a missing or extra part, parts of the wrong type or
        shape, an index out of range). Its values are for the caller to check
        (a digest of the unpacked bytes)."""
        if codec not in PARTS:
            raise ValueError(f"unknown codec {codec!r} (known: {', '.join(CODECS)})")
        try:
            dtype = np.dtype(dtype)
        except (TypeError, ValueError):
            raise ValueError(f"dtype {dtype!r} is not a NumPy dtype") from None
        if dtype.kind not in "biuf" or dtype.hasobject:
            raise ValueError(f"dtype {dtype.str} is not a number type")
        shape = tuple(int(n) for n in shape)
        if set(parts) != set(PARTS[codec]):
            raise ValueError(f"codec {codec!r} has parts {', '.join(PARTS[codec])}, the "
                             f"file has {', '.join(sorted(parts)) or 'none'}")
        size = int(np.prod(shape, dtype=np.int64))
        if codec == "raw":
            d = parts["data"]
            if d.dtype != dtype or d.shape != shape:
                raise ValueError(f"its data is {d.dtype.str} {list(d.shape)}")
        elif codec == "ints":
            d = parts["data"]
            if dtype.kind not in "biu" or d.dtype.kind not in "biu" or d.shape != shape:
                raise ValueError(f"its data is {d.dtype.str} {list(d.shape)}, not "
                                 f"integers of shape {list(shape)}")
        else:
            rows, index, columns, fill = (parts[k] for k in PARTS["rows"])
            width = fill.size
            if dtype.kind != "f" or rows.dtype != dtype or fill.dtype != dtype \
                    or fill.ndim != 1 or rows.ndim != 2:
                raise ValueError(f"its rows and fill must be {dtype.str} (2-D and 1-D)")
            if index.dtype.kind != "u" or columns.dtype.kind != "u" or index.ndim != 1 \
                    or columns.ndim != 1:
                raise ValueError("its index and columns must be 1-D unsigned integers")
            if width != _row_width(shape) or index.size * width != size or (
                    index.size and index.max() >= rows.shape[0]):
                raise ValueError(f"its index does not pick {size} values from "
                                 f"{rows.shape[0]} rows of {width}")
            if rows.shape[1] != columns.size or (columns.size and (
                    columns.max() >= width or (np.diff(columns.astype(np.int64)) <= 0).any())):
                raise ValueError("its columns are not increasing columns of its rows")
        return cls(codec, dtype, shape, dict(parts))


def _records(a: np.ndarray) -> np.ndarray:
    """``a`` (its last axis contiguous) as one record per last-axis row, a view."""
    return a.view(np.uint8).view(np.dtype((np.void, a.shape[-1] * a.itemsize)))[..., 0]


def pack(a: np.ndarray) -> Packed:
    """``a`` in its smallest exact form (a copy: later changes to ``a`` do not reach
    it)."""
    a = np.asarray(a)
    shape = tuple(a.shape)
    if a.nbytes >= MIN_BYTES and a.dtype.kind in "iu" and a.size:
        lo, hi = int(a.min()), int(a.max())
        narrow = next(t for t in ((np.int8, np.int16, np.int32, np.int64) if lo < 0 else
                                  (np.uint8, np.uint16, np.uint32, np.uint64))
                      if np.iinfo(t).min <= lo and hi <= np.iinfo(t).max)
        if np.dtype(narrow).itemsize < a.dtype.itemsize:
            return Packed("ints", a.dtype, shape, {"data": a.astype(narrow)})
    if a.nbytes >= MIN_BYTES and a.dtype.kind == "f" and a.size:
        packed = _pack_rows(a)
        if packed is not None:
            return packed
    return Packed("raw", a.dtype, shape, {"data": np.array(a, copy=True)})


def _row_width(shape) -> int:
    """Values in one row of an array of ``shape`` (:func:`_row_view`)."""
    shape = tuple(shape)
    if len(shape) >= 3:
        return shape[-2] * shape[-1]
    return int(np.prod(shape[1:], dtype=np.int64)) if len(shape) == 2 else 1


def _row_view(a: np.ndarray) -> np.ndarray:
    """``a`` as rows: ``(R, B, C)`` (a pose: the last two axes) for arrays of three
    axes or more, else ``(R, C)`` (everything after the first axis); a view where the
    leading axes merge (the crowd's history ring inside its pose storage), else a copy.
    The last axis is made contiguous (its bits are read as integers)."""
    rows = a.reshape(-1, *a.shape[-2:]) if a.ndim >= 3 else \
        (a.reshape(a.shape[0], -1) if a.ndim == 2 else a.reshape(-1, 1))
    return rows if rows.strides[-1] == rows.itemsize else np.ascontiguousarray(rows)


def _pack_rows(a: np.ndarray) -> Packed | None:
    """The ``rows`` form of float array ``a``, or None when it saves nothing."""
    values = _row_view(a)
    bits = values.view(f"u{a.dtype.itemsize}")
    n, inner = bits.shape[0], bits.shape[1:]
    width = int(np.prod(inner))
    sample = np.unique(np.linspace(0, width - 1, min(width, HASH_COLUMNS)).astype(np.int64))
    picked = bits[(slice(None), *np.unravel_index(sample, inner))]
    h = (picked.astype(np.uint64) * _MULTIPLIERS[:sample.size]).sum(axis=1, dtype=np.uint64)
    _, first, index = np.unique(h, return_index=True, return_inverse=True)
    index = index.reshape(-1)
    some = bits[first[:256]].reshape(-1, width)        # columns that vary at least
    least = max(int((some != some[:1]).any(axis=0).sum()), 1)
    if first.size * least * a.itemsize >= a.nbytes * 0.9:
        return None                         # it could not pay (what the sample says)
    axes = tuple(range(1, bits.ndim))
    match = first[index]
    wrong = np.concatenate([start + np.flatnonzero(
        (bits[start:start + _BLOCK] != bits[match[start:start + _BLOCK]]).any(axis=axes))
        for start in range(0, n, _BLOCK)])
    if wrong.size:                          # matched by the sample only: sorted out
        flat = np.ascontiguousarray(bits[wrong]).reshape(wrong.size, width)
        _, own, again = np.unique(flat, axis=0, return_index=True, return_inverse=True)
        index[wrong] = first.size + again.reshape(-1)      # exactly, among themselves
        first = np.concatenate([first, wrong[own]])
    distinct = values[first].reshape(first.size, width)
    dbits = distinct.view(bits.dtype)
    varying = np.flatnonzero((dbits != dbits[:1]).any(axis=0))
    packed = Packed("rows", a.dtype, tuple(a.shape),
                    {"rows": np.ascontiguousarray(distinct[:, varying]),
                     "index": index.astype(np.min_scalar_type(max(first.size - 1, 0))),
                     "columns": varying.astype(np.min_scalar_type(max(width - 1, 0))),
                     "fill": distinct[0].copy()})
    return packed if packed.nbytes < a.nbytes else None
