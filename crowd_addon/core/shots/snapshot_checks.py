"""The bounds a snapshot is checked against on load (:mod:`.snapshot`): every field of
its header and every small value, each refused with its name (docs/snapshots.md,
*The file*).
"""

from __future__ import annotations

import math

from ..base.errors import CrowdError
from .packed import PARTS

__all__ = ["check_header", "check_values", "MAX_COUNT"]

#: The largest count a snapshot may hold (events fired, slots served, tickets issued,
#: steps...): whole numbers up to 2**53 are exact in every JSON reader.
MAX_COUNT = 2**53


def check_header(path, head, fmt: str, version: int, reads: tuple, header: str):
    """Every field of the header against its type and bounds (CrowdError naming the
    file and the field)."""
    from ..base.bounds import MAX_FRAME
    from ..authoring.config import MAX_SUBSTEPS
    if not isinstance(head, dict) or head.get("format") != fmt:
        raise CrowdError(f"{path}: not a crowd snapshot (format "
                         f"{head.get('format') if isinstance(head, dict) else head!r})")
    if head.get("version") == 1:
        raise CrowdError(f"{path}: snapshot format version 1 (its arrays carry no "
                         f"digest), this crowd reads version {version}: write it again "
                         "(crowd snapshot, or crowd export --snapshots)")
    if head.get("version") not in reads:
        raise CrowdError(f"{path}: snapshot format version {head.get('version')!r}, this "
                         f"crowd reads versions {', '.join(map(str, reads))}")
    for key, kind, what in (("frame", int, "a whole number"), ("config_digest", str, "a string"),
                            ("substeps", int, "a whole number"), ("values", dict, "an object"),
                            ("arrays", dict, "an object")):
        if not isinstance(head.get(key), kind) or isinstance(head.get(key), bool):
            raise CrowdError(f"{path}: {header}: {key!r} must be {what}")
    if abs(head["frame"]) > MAX_FRAME:
        raise CrowdError(f"{path}: {header}: 'frame' {head['frame']} is past the largest "
                         f"frame number (magnitude at most {MAX_FRAME})")
    if not _is_hex(head["config_digest"]):
        raise CrowdError(f"{path}: {header}: 'config_digest' must be a SHA-256 (64 hex "
                         "digits)")
    if not 1 <= head["substeps"] <= MAX_SUBSTEPS:
        raise CrowdError(f"{path}: {header}: 'substeps' must be 1..{MAX_SUBSTEPS}, got "
                         f"{head['substeps']}")
    for name, spec in head["arrays"].items():
        if not (isinstance(spec, dict) and isinstance(spec.get("dtype"), str)
                and isinstance(spec.get("shape"), list) and _is_hex(spec.get("sha256"))):
            raise CrowdError(f"{path}: {header}: array {name!r} needs a dtype, a shape and "
                             "a sha256")
        if not _sizes(spec["shape"]):
            raise CrowdError(f"{path}: {header}: array {name!r}: its shape must be sizes "
                             f">= 0, got {spec['shape']}")
        if head["version"] < 3:
            if "codec" in spec or "parts" in spec:
                raise CrowdError(f"{path}: {header}: array {name!r}: a version 2 file "
                                 "keeps arrays whole (no codec)")
            continue
        codec, parts = spec.get("codec"), spec.get("parts")
        if codec not in PARTS or not isinstance(parts, dict) \
                or set(parts) != set(PARTS[codec]):
            raise CrowdError(f"{path}: {header}: array {name!r} needs a codec "
                             f"({', '.join(PARTS)}) and its parts")
        for part, p in parts.items():
            if not (isinstance(p, dict) and isinstance(p.get("dtype"), str)
                    and isinstance(p.get("shape"), list) and _sizes(p["shape"])):
                raise CrowdError(f"{path}: {header}: array {name!r}: part {part!r} needs a "
                                 "dtype and a shape of sizes >= 0")
    check_values(head["values"], head["frame"], f"{path}: {header}")


def _sizes(shape) -> bool:
    return all(isinstance(n, int) and not isinstance(n, bool) and 0 <= n <= MAX_COUNT
               for n in shape)


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
