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

The file (``.npz``, see docs/snapshots.md) is a NumPy zip archive: one array per
state array, and ``snapshot.json``, a UTF-8 JSON header (as uint8 bytes) with the
format name and version, the frame, the configuration's digest, the samples per
frame, the small values (counts, parameters, triggers) and the name, dtype, shape and
SHA-256 digest of every array, all checked on load: every header field and count
against its bounds, every array against its digest, so a damaged file is refused with
its name. Files are written through a temporary name and renamed, so a failed write
leaves no partial file. A crowd's state is taken, checked and restored by
:mod:`.crowd_state`; snapshots are kept for scrubbing and chunks by
:mod:`.snapshot_store`.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, field

import numpy as np

from ..base.errors import CrowdError
from ..base.files import file_mode

__all__ = ["Snapshot", "FORMAT", "VERSION", "load_snapshot", "flatten_state", "value_kind",
           "check_values"]

FORMAT = "crowd-snapshot"
#: 2: each array's SHA-256 in the header (version 1 files, without it, are refused)
VERSION = 2
HEADER = "snapshot.json"
#: The largest count a snapshot may hold (events fired, slots served, tickets issued,
#: steps...): whole numbers up to 2**53 are exact in every JSON reader.
MAX_COUNT = 2**53


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
    arrays : ``{"part.name": array}`` copies of the state arrays.
    values : ``{"part.name": value}`` the small plain values (JSON types).
    """

    frame: int
    config_digest: str
    substeps: int
    arrays: dict = field(repr=False)
    values: dict = field(repr=False)

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays (what it costs in memory, about what its file takes)."""
        return int(sum(a.nbytes for a in self.arrays.values()))

    def state(self) -> dict:
        """The nested state (views of :attr:`arrays`) the crowd's parts restore from."""
        return _nested(self.arrays, self.values)

    def header(self) -> dict:
        """The file's header (docs/snapshots.md): the digests of the arrays included."""
        return {"format": FORMAT, "version": VERSION, "frame": self.frame,
                "config_digest": self.config_digest, "substeps": self.substeps,
                "values": self.values,
                "arrays": {k: {"dtype": a.dtype.str, "shape": list(a.shape),
                               "sha256": array_digest(a)}
                           for k, a in self.arrays.items()}}

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
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp",
                                       dir=directory)
            with os.fdopen(fd, "wb") as f:
                np.savez(f, **{HEADER: head}, **self.arrays)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, file_mode(path))
            os.replace(tmp, path)
            tmp = None
        except OSError as e:
            raise CrowdError(f"{path}: cannot write the crowd snapshot: {e}") from e
        finally:
            if tmp is not None:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass


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
            _check_header(path, head)
            listed = head["arrays"]
            extra = sorted(names - set(listed) - {HEADER})
            missing = sorted(set(listed) - names)
            if missing or extra:
                raise CrowdError(f"{path}: arrays do not match the header (missing: "
                                 f"{missing[:5]}, unexpected: {extra[:5]})")
            arrays = {}
            for name, spec in listed.items():
                a = z[name]
                if not isinstance(a, np.ndarray):
                    raise CrowdError(f"{path}: array {name!r} is damaged (not a NumPy "
                                     "array)")
                if a.dtype.str != spec["dtype"] or list(a.shape) != list(spec["shape"]):
                    raise CrowdError(f"{path}: array {name!r} is {a.dtype.str} "
                                     f"{list(a.shape)}, the header says {spec['dtype']} "
                                     f"{spec['shape']}")
                if array_digest(a) != spec["sha256"]:
                    raise CrowdError(f"{path}: array {name!r} does not match its digest in "
                                     f"the header: the file is damaged")
                arrays[name] = a
    except CrowdError:
        raise
    except FileNotFoundError:
        raise CrowdError(f"{path}: no such file") from None
    except (OSError, zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, ValueError,
            EOFError, KeyError, NotImplementedError, RuntimeError) as e:
        raise CrowdError(f"{path}: not a readable crowd snapshot: {e}") from None
    return Snapshot(int(head["frame"]), head["config_digest"], int(head["substeps"]),
                    arrays, head["values"])


def _check_header(path, head):
    """Every field of the header against its type and bounds (CrowdError naming the
    file and the field)."""
    from ..base.bounds import MAX_FRAME
    from ..authoring.config import MAX_SUBSTEPS
    if not isinstance(head, dict) or head.get("format") != FORMAT:
        raise CrowdError(f"{path}: not a crowd snapshot (format "
                         f"{head.get('format') if isinstance(head, dict) else head!r})")
    if head.get("version") == 1:
        raise CrowdError(f"{path}: snapshot format version 1 (its arrays carry no "
                         f"digest), this crowd reads version {VERSION}: write it again "
                         "(crowd snapshot, or crowd export --snapshots)")
    if head.get("version") != VERSION:
        raise CrowdError(f"{path}: snapshot format version {head.get('version')!r}, this "
                         f"crowd reads version {VERSION}")
    for key, kind, what in (("frame", int, "a whole number"), ("config_digest", str, "a string"),
                            ("substeps", int, "a whole number"), ("values", dict, "an object"),
                            ("arrays", dict, "an object")):
        if not isinstance(head.get(key), kind) or isinstance(head.get(key), bool):
            raise CrowdError(f"{path}: {HEADER}: {key!r} must be {what}")
    if abs(head["frame"]) > MAX_FRAME:
        raise CrowdError(f"{path}: {HEADER}: 'frame' {head['frame']} is past the largest "
                         f"frame number (magnitude at most {MAX_FRAME})")
    if not _is_hex(head["config_digest"]):
        raise CrowdError(f"{path}: {HEADER}: 'config_digest' must be a SHA-256 (64 hex "
                         "digits)")
    if not 1 <= head["substeps"] <= MAX_SUBSTEPS:
        raise CrowdError(f"{path}: {HEADER}: 'substeps' must be 1..{MAX_SUBSTEPS}, got "
                         f"{head['substeps']}")
    for name, spec in head["arrays"].items():
        if not (isinstance(spec, dict) and isinstance(spec.get("dtype"), str)
                and isinstance(spec.get("shape"), list) and _is_hex(spec.get("sha256"))):
            raise CrowdError(f"{path}: {HEADER}: array {name!r} needs a dtype, a shape and "
                             "a sha256")
        if not all(isinstance(n, int) and not isinstance(n, bool) and 0 <= n <= MAX_COUNT
                   for n in spec["shape"]):
            raise CrowdError(f"{path}: {HEADER}: array {name!r}: its shape must be sizes "
                             f">= 0, got {spec['shape']}")
    check_values(head["values"], head["frame"], f"{path}: {HEADER}")


def _is_hex(text) -> bool:
    return isinstance(text, str) and len(text) == 64 and \
        all(c in "0123456789abcdef" for c in text)


#: the values that are counts (whole numbers 0..MAX_COUNT), and those that hold counts
#: by name (``{name: count}``) or by name and name (``{name: {name: count}}``)
_COUNTS = ("crowd.steps", "slots.served", "slots.cuts", "slots.queue.count",
           "slots.queue.issued")
_COUNTS_BY_NAME = ("events.fired", "events.calls", "show.reactions")
_COUNTS_BY_NAMES = ("show.stats",)
#: the values that are frame numbers
_FRAMES = ("crowd.frame", "crowd.origin")
#: how deep a value may nest (lists and objects)
_DEPTH = 8


def check_values(values: dict, frame: int, what: str) -> None:
    """Each small value of a snapshot against its bounds: counts are whole numbers
    0..:data:`MAX_COUNT`, frames whole numbers within ``MAX_FRAME`` (``crowd.frame``
    the snapshot's ``frame``), the step time a finite number >= 0, parameters finite
    numbers, triggers names; any other number finite and no larger than a count.
    CrowdError naming ``what`` and the value otherwise."""
    from ..base.bounds import MAX_FRAME

    def bad(name, must):
        value = repr(values[name])
        raise CrowdError(f"{what}: value {name!r} must be {must}, got "
                         f"{value if len(value) <= 80 else value[:77] + '...'}")

    def count(v):
        return isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= MAX_COUNT

    def number(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and \
            math.isfinite(v) and abs(v) <= MAX_COUNT

    def plain(v, depth=0):
        if v is None or isinstance(v, (bool, str)):
            return True
        if isinstance(v, (int, float)):
            return number(v)
        if depth >= _DEPTH:
            return False
        if isinstance(v, list):
            return all(plain(x, depth + 1) for x in v)
        return isinstance(v, dict) and all(isinstance(k, str) and plain(x, depth + 1)
                                           for k, x in v.items())

    def by_name(v, inner):
        return isinstance(v, dict) and all(isinstance(k, str) and inner(x)
                                           for k, x in v.items())

    for name, v in values.items():
        if not isinstance(name, str):
            raise CrowdError(f"{what}: value names must be strings, got {name!r}")
        if name in _COUNTS and not count(v):
            bad(name, f"a count (a whole number 0..{MAX_COUNT})")
        elif name in _COUNTS_BY_NAME and not by_name(v, count):
            bad(name, f"counts by name (whole numbers 0..{MAX_COUNT})")
        elif name in _COUNTS_BY_NAMES and not by_name(v, lambda d: by_name(d, count)):
            bad(name, f"counts by name and name (whole numbers 0..{MAX_COUNT})")
        elif name in _FRAMES and not (isinstance(v, int) and not isinstance(v, bool)
                                      and abs(v) <= MAX_FRAME):
            bad(name, f"a frame (a whole number of magnitude at most {MAX_FRAME})")
        elif name == "crowd.ms_total" and not (number(v) and v >= 0):
            bad(name, "a finite number of milliseconds >= 0")
        elif name == "evaluator.params" and not (
                isinstance(v, list) and all(by_name(p, number) for p in v)):
            bad(name, "finite numbers by parameter name, one object per animation")
        elif name == "evaluator.triggers" and not (
                isinstance(v, list) and all(isinstance(t, list) and
                                            all(isinstance(n, str) for n in t) for t in v)):
            bad(name, "trigger names, one list per animation")
        elif not plain(v):
            bad(name, f"plain JSON: finite numbers of magnitude at most {MAX_COUNT}, "
                      f"at most {_DEPTH} levels deep")
    if "crowd.frame" in values and values["crowd.frame"] != frame:
        bad("crowd.frame", f"the snapshot's frame {frame}")
    if "crowd.origin" in values and "crowd.frame" in values and \
            values["crowd.origin"] > values["crowd.frame"]:
        bad("crowd.origin", f"a frame at or before the crowd's frame {frame}")
