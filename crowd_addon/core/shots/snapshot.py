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
leaves no partial file.
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

from ..base.bounds import MAX_RUN_FRAMES, check_run, whole_frame
from ..base.errors import CrowdError
from ..base.files import file_mode

__all__ = ["Snapshot", "SnapshotCache", "SnapshotFolder", "FORMAT", "VERSION",
           "load_snapshot", "write_snapshots", "ShotSnapshots"]

FORMAT = "crowd-snapshot"
#: 2: each array's SHA-256 in the header (version 1 files, without it, are refused)
VERSION = 2
HEADER = "snapshot.json"
#: The largest count a snapshot may hold (events fired, slots served, tickets issued,
#: steps...): whole numbers up to 2**53 are exact in every JSON reader.
MAX_COUNT = 2**53


def _flatten(state, prefix="", arrays=None, values=None):
    """A nested state as ``(arrays, values)``: ``{"a.b.c": array}`` and
    ``{"a.b.d": plain value}`` (dots join the keys)."""
    arrays = {} if arrays is None else arrays
    values = {} if values is None else values
    for k, v in state.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict) and v and not _is_value_dict(name):
            _flatten(v, name + ".", arrays, values)
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


def _kind(v) -> str:
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


def take(crowd) -> Snapshot:
    """A :class:`Snapshot` of ``crowd`` now (copies)."""
    arrays, values = _flatten(crowd._state())
    return Snapshot(int(crowd.frame), crowd.config_digest, int(crowd.substeps),
                    {k: np.array(a, copy=True) for k, a in arrays.items()},
                    json.loads(json.dumps(values)))


def check(crowd, snap: Snapshot, what: str = "snapshot") -> None:
    """Raise CrowdError (naming what differs) unless ``snap`` fits ``crowd``: same
    configuration digest and samples per frame, and the same state arrays (names,
    dtypes, shapes) and values (names, kinds). Changes nothing."""
    if snap.config_digest != crowd.config_digest:
        raise CrowdError(f"{what} of frame {snap.frame} was taken of another crowd "
                         f"configuration (digest {snap.config_digest[:12]}, this crowd's "
                         f"{crowd.config_digest[:12]})")
    if snap.substeps != crowd.substeps:
        raise CrowdError(f"{what} of frame {snap.frame} keeps {snap.substeps} samples a "
                         f"frame, this crowd {crowd.substeps}")
    from ..base.bounds import MAX_FRAME
    if isinstance(snap.frame, bool) or not isinstance(snap.frame, int) or \
            abs(snap.frame) > MAX_FRAME:
        raise CrowdError(f"{what}: its frame {snap.frame!r} is not a frame number (a whole "
                         f"number of magnitude at most {MAX_FRAME})")
    check_values(snap.values, snap.frame, what)
    arrays, values = _flatten(crowd._state())
    for name in sorted(set(arrays) | set(snap.arrays)):
        a, b = arrays.get(name), snap.arrays.get(name)
        if a is None or b is None:
            raise CrowdError(f"{what}: state array {name!r} is "
                             f"{'missing' if b is None else 'unknown to this crowd'}")
        # the queue's line and the show's due lists vary in length
        if a.dtype != b.dtype or (a.shape != b.shape and not _varies(name)) \
                or a.ndim != b.ndim:
            raise CrowdError(f"{what}: state array {name!r} is {b.dtype} {b.shape}, "
                             f"this crowd's is {a.dtype} {a.shape}")
    for name, b in snap.arrays.items():
        if b.dtype.kind == "f" and not name.endswith(_NAN_ALLOWED) and \
                not np.isfinite(b).all():
            raise CrowdError(f"{what}: state array {name!r} holds values that are not "
                             "finite")
    for name in sorted(set(values) | set(snap.values)):
        if name not in values or name not in snap.values:
            raise CrowdError(f"{what}: state value {name!r} is "
                             f"{'missing' if name not in snap.values else 'unknown'}")
        if _kind(snap.values[name]) != _kind(values[name]):
            raise CrowdError(f"{what}: state value {name!r} is a "
                             f"{_kind(snap.values[name])}, expected a {_kind(values[name])}")


#: float state arrays where NaN means something (a clip player's "no last time", a
#: state machine's "not entered yet")
_NAN_ALLOWED = (".prev", ".entered")


def _varies(name) -> bool:
    return name.endswith(("queue.line", ".ids", ".counts", ".frame", ".duration",
                          ".reaction", "log_stream", "log_name", "log_frame",
                          "releases.cue", "releases.stream"))


class SnapshotCache:
    """Snapshots of one crowd's run every :attr:`every` frames, within ``max_bytes``:
    what lets a crowd jump to any frame by stepping at most ``every - 1`` frames from
    the nearest one (:meth:`Crowd.advance_to <.crowd.Crowd.advance_to>`).

    Frames ``origin + k * every`` are kept as the crowd steps past them. When the next
    one would pass ``max_bytes``, :attr:`every` doubles and the snapshots off the new
    grid are dropped, so a long shot always fits and the farthest a jump re-simulates
    grows with it. :attr:`requested` is the spacing asked for; :attr:`fits` is False
    when not even one snapshot fits in ``max_bytes`` (then none is kept).
    """

    def __init__(self, every: int = 30, max_bytes: int = 2 << 30):
        if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
            raise CrowdError(f"snapshots: every must be a whole number of frames >= 1, "
                             f"got {every!r}")
        if isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, np.integer)) \
                or max_bytes < 0:
            raise CrowdError(f"snapshots: the memory cap must be bytes >= 0, got "
                             f"{max_bytes!r}")
        self.requested = self.every = int(every)
        self.max_bytes = int(max_bytes)
        self.fits = True
        self._snaps = {}

    def __len__(self) -> int:
        return len(self._snaps)

    @property
    def frames(self) -> list:
        return sorted(self._snaps)

    @property
    def nbytes(self) -> int:
        return sum(s.nbytes for s in self._snaps.values())

    def wants(self, frame: int, origin: int) -> bool:
        """Whether the crowd at ``frame`` (of a run started at ``origin``) is one to keep."""
        return (frame - origin) % self.every == 0 and frame not in self._snaps and self.fits

    def add(self, snap: Snapshot, origin: int):
        """Keep ``snap`` (taken where :meth:`wants` said so), thinning to stay in the cap."""
        if snap.nbytes > self.max_bytes:
            self.fits = False
            return
        self._snaps[snap.frame] = snap
        while self.nbytes > self.max_bytes:
            self.every *= 2
            self._snaps = {f: s for f, s in self._snaps.items()
                           if (f - origin) % self.every == 0}

    def nearest(self, frame: int) -> Snapshot | None:
        """The kept snapshot at ``frame`` or the latest before it (None if none)."""
        before = [f for f in self._snaps if f <= frame]
        return self._snaps[max(before)] if before else None

    def drop_after(self, frame: int):
        """Forget the snapshots past ``frame`` (the run changed there)."""
        self._snaps = {f: s for f, s in self._snaps.items() if f <= frame}

    def clear(self):
        self._snaps = {}
        self.fits = True


class SnapshotFolder:
    """A folder of snapshot files, one per (crowd configuration, samples per frame,
    frame): ``snap_<digest[:16]>_s<substeps>_f<frame>.npz``, so several shots may
    share one folder. What ``crowd snapshot`` writes and ``crowd export --snapshots``
    starts from (docs/snapshots.md)."""

    def __init__(self, path, create: bool = False):
        self.path = os.fspath(path)
        if create:
            try:
                os.makedirs(self.path, exist_ok=True)
            except OSError as e:
                raise CrowdError(f"{self.path}: cannot create the snapshot folder: {e}") \
                    from None
        if not os.path.isdir(self.path):
            raise CrowdError(f"{self.path}: no such snapshot folder")

    @staticmethod
    def _stem(crowd) -> str:
        return f"snap_{crowd.config_digest[:16]}_s{crowd.substeps}_f"

    def file(self, crowd, frame: int) -> str:
        """The file of ``crowd``'s snapshot at ``frame``."""
        return os.path.join(self.path, f"{self._stem(crowd)}{int(frame)}.npz")

    def frames(self, crowd) -> list:
        """Frames of the snapshots of ``crowd``'s configuration here, ascending."""
        stem, out = self._stem(crowd), []
        for name in os.listdir(self.path):
            if name.startswith(stem) and name.endswith(".npz"):
                try:
                    out.append(int(name[len(stem):-4]))
                except ValueError:
                    continue
        return sorted(out)

    def save(self, crowd) -> str:
        """Write ``crowd``'s snapshot now; returns the file."""
        path = self.file(crowd, crowd.frame)
        crowd.snapshot().save(path)
        return path

    def start(self, crowd, first: int):
        """Restore into ``crowd`` the latest snapshot of it here before ``first`` (at
        frame ``first - 1`` or earlier) when that is ahead of the crowd; returns its
        frame, or None when there is none (the crowd is left as it was)."""
        usable = [f for f in self.frames(crowd) if crowd.frame < f < first]
        if not usable:
            return None
        crowd.restore(load_snapshot(self.file(crowd, usable[-1])))
        return usable[-1]


def write_snapshots(crowd, folder: SnapshotFolder, first: int, last: int, every: int,
                    progress=None) -> list:
    """Step ``crowd`` to ``last`` (from the latest snapshot in ``folder`` before
    ``first`` when there is one) and write a snapshot at ``first - 1`` and every
    ``every`` frames after it (the frame before each ``every``-frame chunk of
    ``first .. last``; none before the start frame, where a chunk needs none) and at
    ``last``. Returns the files written.
    ``progress(done, total)`` after each step. A pass that would step more than
    :data:`~.bounds.MAX_RUN_FRAMES` frames is refused before its first step."""
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise CrowdError(f"snapshots: every must be a whole number of frames >= 1, "
                         f"got {every!r}")
    first, last = whole_frame(first, "snapshots"), whole_frame(last, "snapshots")
    if first > last:
        raise CrowdError(f"snapshots: frames {first}-{last}: the first is after the last")
    folder.start(crowd, first)
    end = crowd.frame + MAX_RUN_FRAMES
    check_run("snapshots", crowd.frame, last,              # before the first step
              f"write them in passes of at most {MAX_RUN_FRAMES:,} frames into the same "
              f"folder, each going on from the last snapshot there (crowd snapshot "
              f"--frames {min(first, end)}-{end}, then --frames {end + 1}-{end + MAX_RUN_FRAMES}, "
              "and so on)")
    start = crowd.config.start_frame              # a new crowd is there already
    wanted = {f for f in range(first - 1, last + 1, every) if f > start} | {last}
    written, total = [], last - crowd.frame
    if crowd.frame in wanted:
        written.append(folder.save(crowd))
    while crowd.frame < last:
        crowd.step()
        if crowd.frame in wanted:
            written.append(folder.save(crowd))
        if progress is not None:
            progress(total - (last - crowd.frame), total)
    return written


class ShotSnapshots:
    """An export's use of a snapshot folder: the crowd starts from the latest snapshot
    of it there before the shot's first frame (:attr:`started_from`, None when there
    is none), and leaves one at the shot's last frame for the next chunk: taken by
    :meth:`recorded` once the shot is simulated, written by :meth:`keep` once the
    export succeeded."""

    def __init__(self, path, crowd, first: int):
        self.folder = SnapshotFolder(path, create=True)
        self.crowd = crowd
        self.started_from = self.folder.start(crowd, first)
        self._snap = None

    def recorded(self):
        self._snap = self.crowd.snapshot()

    def keep(self) -> str:
        path = self.folder.file(self.crowd, self._snap.frame)
        self._snap.save(path)
        return path
