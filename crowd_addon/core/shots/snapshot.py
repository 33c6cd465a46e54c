"""Exact snapshots of a running crowd: saved and restored bit for bit, in memory or
in a file.

A :class:`Snapshot` holds everything a :class:`~.crowd.Crowd` carries from one frame
to the next: the pose history ring, the uniques and their clocks, the sub-frame
samples, the transition slots with their StartP and the queue, what every agent
plays and where it stands, the controller trees' state (state machines, fades, clip
players, parameters, triggers not yet consumed), the event log the offsets still
read, and the show's progress (homes, holds, returns and reactions due, the tracks'
last values, the counts). Restored into a crowd built from the same configuration,
every later frame's poses and events equal those of the run it was taken from.

Not kept: callbacks (registered functions are the caller's: register them on the
restored crowd as on any new one) and anything a callback keeps in its own Python
objects; the skinning rows, which the crowd's skinning mode rebuilds from the local
poses, so a snapshot taken with either mode restores into either.

The arrays are kept packed, in memory and in the file (:mod:`.packed`: repeated pose
rows once, unchanging columns once, integers in the narrowest type; exact): at the
paper's scale a snapshot is about a sixth of its arrays' size.

The file (``.npz``, see docs/snapshots.md) is a NumPy zip archive: the parts of each
packed state array, and ``snapshot.json``, a UTF-8 JSON header (as uint8 bytes) with
the format name and version, the frame, the configuration's digest, the samples per
frame, the small values (counts, parameters, triggers) and the name, dtype, shape,
codec, parts and SHA-256 digest (of the unpacked bytes) of every array, all checked
on load: every header field and count against its bounds, every part against its
listed form and every array against its digest, so a damaged file is refused with
its name. Version 2 files (arrays whole) are read too. Files are written through a temporary name and renamed, so a failed write
leaves no partial file. A crowd's state is taken, checked and restored by
:mod:`.crowd_state`; snapshots are kept for scrubbing and chunks by
:mod:`.snapshot_store`.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field

import numpy as np

from ..base.errors import CrowdError
from ..base.files import npz_bytes, write_atomic
from .packed import PARTS, Packed, pack
from .snapshot_checks import MAX_COUNT, check_header, check_values

__all__ = ["Snapshot", "FORMAT", "VERSION", "READS", "load_snapshot", "flatten_state",
           "value_kind", "check_values", "MAX_COUNT"]

FORMAT = "crowd-snapshot"
#: 2: each array's SHA-256 in the header (version 1 files, without it, are refused);
#: 3: arrays packed (:mod:`.packed`: a codec and its parts per array)
VERSION = 3
#: the versions :func:`load_snapshot` reads (a version 2 file's arrays are all raw)
READS = (2, 3)
HEADER = "snapshot.json"


def flatten_state(state, prefix="", arrays=None, values=None):
    """A nested state as ``(arrays, values)``: ``{"a.b.c": array}`` and
    ``{"a.b.d": plain value}`` (dots join the keys)."""
    arrays = {} if arrays is None else arrays
    values = {} if values is None else values
    for k, v in state.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict) and v and not _is_value_dict(name):
            flatten_state(v, name + ".", arrays, values)
        elif isinstance(v, np.ndarray):
            arrays[name] = v
        else:
            values[name] = v
    return arrays, values


def _is_value_dict(name) -> bool:
    """Dicts kept whole as one plain value (their keys are names, not parts)."""
    return name.rsplit(".", 1)[-1] in ("fired", "calls", "stats", "reactions")


def _nested(arrays, values) -> dict:
    out = {}
    for flat in (arrays, values):
        for name, v in flat.items():
            d = out
            *parents, leaf = name.split(".")
            for p in parents:
                d = d.setdefault(p, {})
            d[leaf] = v
    return out


def value_kind(v) -> str:
    if v is None or isinstance(v, (bool, int, float, str)):
        return "scalar"
    return type(v).__name__


@dataclass(frozen=True, eq=False)
class Snapshot:
    """One crowd's state at ``frame``: take one with :meth:`Crowd.snapshot
    <.crowd.Crowd.snapshot>`, restore it with :meth:`Crowd.restore
    <.crowd.Crowd.restore>`.

    Attributes
    ----------
    frame : the crowd's frame when it was taken (the last evaluated frame).
    config_digest : the digest of the configuration it belongs to
        (:func:`~.config_io.config_digest`); a crowd of any other refuses it.
    substeps : samples per frame the crowd kept (a crowd must keep as many).
    packed : ``{"part.name": Packed}`` the state arrays in their compact exact forms
        (:mod:`.packed`); made from plain arrays (copied and packed) or packed ones.
    values : ``{"part.name": value}`` the small plain values (JSON types).
    """

    frame: int
    config_digest: str
    substeps: int
    packed: dict = field(repr=False)
    values: dict = field(repr=False)

    def __post_init__(self):
        object.__setattr__(self, "packed", {k: v if isinstance(v, Packed) else pack(v)
                                            for k, v in self.packed.items()})

    @property
    def arrays(self) -> dict:
        """``{"part.name": array}``: the state arrays unpacked (new arrays each time)."""
        return {k: p.unpack() for k, p in self.packed.items()}

    @property
    def nbytes(self) -> int:
        """Bytes of the packed arrays (what it costs in memory, about what its file
        takes)."""
        return int(sum(p.nbytes for p in self.packed.values()))

    def state(self) -> dict:
        """The nested state the crowd's parts restore from (they copy it in, and keep
        no reference): raw arrays as kept (read-only), narrowed integers widened, and
        the packed pose arrays as they are (``np.asarray`` unpacks one;
        :func:`~..base.state.assign` unpacks it into its place)."""
        return _nested({k: _view(p.parts["data"]) if p.codec == "raw"
                        else p if p.codec == "rows" and p.ndim >= 3 else p.unpack()
                        for k, p in self.packed.items()}, self.values)

    def header(self) -> dict:
        """The file's header (docs/snapshots.md): each array's dtype, shape, the digest
        of its unpacked bytes, and its codec with the parts' dtypes and shapes."""
        arrays = {}
        for k, p in self.packed.items():
            arrays[k] = {"dtype": p.dtype.str, "shape": list(p.shape),
                         "sha256": array_digest(p.unpack()), "codec": p.codec,
                         "parts": {n: {"dtype": a.dtype.str, "shape": list(a.shape)}
                                   for n, a in p.parts.items()}}
        return {"format": FORMAT, "version": VERSION, "frame": self.frame,
                "config_digest": self.config_digest, "substeps": self.substeps,
                "values": self.values, "arrays": arrays}

    def save(self, path) -> None:
        """Write the snapshot to ``path`` (a ``.npz`` file; atomic: a temporary name
        renamed into place, removed on error, which is raised as CrowdError)."""
        path = os.fspath(path)
        if not path.lower().endswith(".npz"):
            raise CrowdError(f"{path}: a crowd snapshot file name ends in .npz")
        directory = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(directory):
            raise CrowdError(f"{path}: directory {directory} does not exist")
        head = np.frombuffer(json.dumps(self.header()).encode("utf-8"), np.uint8)
        data = npz_bytes({HEADER: head, **{_member(k, n): a for k, p in self.packed.items()
                                           for n, a in p.parts.items()}})
        write_atomic(path, lambda f: f.write(data), "the crowd snapshot")


def _view(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


def array_digest(a: np.ndarray) -> str:
    """SHA-256 hex of an array's bytes in C order (its dtype and shape are listed
    beside it in the header)."""
    return hashlib.sha256(np.ascontiguousarray(a).reshape(-1).view(np.uint8)).hexdigest()


def load_snapshot(path) -> Snapshot:
    """Read a snapshot written by :meth:`Snapshot.save`. Anything wrong (not a
    snapshot, another format version, a header field or count out of its bounds, a
    missing, extra, mis-shaped or damaged array, a damaged archive) raises CrowdError
    naming the file and what is wrong."""
    path = os.fspath(path)
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise CrowdError(f"{path}: not a crowd snapshot (one array, not an archive)")
        with z:
            names = set(z.files)
            if HEADER not in names:
                raise CrowdError(f"{path}: not a crowd snapshot (no {HEADER})")
            raw = z[HEADER]
            if not isinstance(raw, np.ndarray) or raw.dtype != np.uint8 or raw.ndim != 1:
                raise CrowdError(f"{path}: {HEADER} is damaged (not the header's bytes)")
            try:
                head = json.loads(raw.tobytes().decode("utf-8"))
            except (UnicodeDecodeError, ValueError, RecursionError) as e:
                raise CrowdError(f"{path}: {HEADER} is not valid JSON: {e}") from None
            check_header(path, head, FORMAT, VERSION, READS, HEADER)
            listed = head["arrays"]
            members = {_member(name, part): (name, part) for name, spec in listed.items()
                       for part in PARTS[spec.get("codec", "raw")]}
            extra = sorted(names - set(members) - {HEADER})
            missing = sorted(set(members) - names)
            if missing or extra:
                raise CrowdError(f"{path}: arrays do not match the header (missing: "
                                 f"{missing[:5]}, unexpected: {extra[:5]})")
            packed = {}
            for name, spec in listed.items():
                codec = spec.get("codec", "raw")
                parts = {}
                for part in PARTS[codec]:
                    a = z[_member(name, part)]
                    want = spec["parts"][part] if "parts" in spec else spec
                    if not isinstance(a, np.ndarray):
                        raise CrowdError(f"{path}: array {name!r} is damaged (not a NumPy "
                                         "array)")
                    if a.dtype.str != want["dtype"] or list(a.shape) != list(want["shape"]):
                        raise CrowdError(f"{path}: array {_member(name, part)!r} is "
                                         f"{a.dtype.str} {list(a.shape)}, the header says "
                                         f"{want['dtype']} {want['shape']}")
                    parts[part] = a
                try:
                    p = Packed.from_parts(codec, spec["dtype"], spec["shape"], parts)
                except ValueError as e:
                    raise CrowdError(f"{path}: array {name!r} ({codec}) is damaged: {e}") \
                        from None
                if array_digest(p.unpack()) != spec["sha256"]:
                    raise CrowdError(f"{path}: array {name!r} does not match its digest in "
                                     f"the header: the file is damaged")
                packed[name] = p
    except CrowdError:
        raise
    except FileNotFoundError:
        raise CrowdError(f"{path}: no such file") from None
    except (OSError, zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, ValueError,
            EOFError, KeyError, NotImplementedError, RuntimeError) as e:
        raise CrowdError(f"{path}: not a readable crowd snapshot: {e}") from None
    return Snapshot(int(head["frame"]), head["config_digest"], int(head["substeps"]),
                    packed, head["values"])


def _member(name: str, part: str) -> str:
    """The archive member holding part ``part`` of array ``name`` (a raw or integer
    array's data under the array's own name, as in version 2 files)."""
    return name if part == "data" else f"{name}:{part}"
