"""The bake report: what a scene's bake has to tell whoever runs it.

Every way of baking a scene's crowd (the *Bake* operator, the viewport preview,
*Export Crowd USD*, ``crowd export|preview|plan|snapshot --blend``, a farm's shots
and the Python API's ``config_from_scene``) builds one :class:`BakeReport` and
carries it with the configuration it made (``config.bake_report``,
:func:`report_of`), so every path tells the same notes: the command line prints one
line per note on stderr, the operators report them (warnings as warnings), the
preview shows how many there are in its status, and ``--strict`` makes a report
with warnings an error (exit code 2) for farms.

A note is a ``str`` (its text, so code that compared the notes as strings still
does) with a ``kind`` (what it is about, e.g. ``"between_frames"``,
``"influences"``, ``"lod"``, ``"frame_set"``) and a ``severity``:
:data:`WARNING` where the result differs from what the scene shows (poses missed
between frames, a vertex's influences cut, a LOD level refused), :data:`INFO`
where the bake only says how it worked (sampled with frame_set, a loop resampled).
"""

from __future__ import annotations

from ..base.errors import CrowdError

__all__ = ["Note", "BakeReport", "BakeWarnings", "report_of", "WARNING", "INFO"]

WARNING, INFO = "warning", "info"


class Note(str):
    """One remark of a bake: its text, with ``kind`` and ``severity``."""

    kind: str
    severity: str

    def __new__(cls, text, kind: str = "remark", severity: str = WARNING):
        if severity not in (WARNING, INFO):
            raise ValueError(f"note severity must be {WARNING!r} or {INFO!r}, got "
                             f"{severity!r}")
        note = super().__new__(cls, str(text))
        note.kind = getattr(text, "kind", kind) if isinstance(text, Note) else kind
        note.severity = text.severity if isinstance(text, Note) else severity
        return note

    @property
    def line(self) -> str:
        """The note as the command line prints it: ``warning: ...`` or ``note: ...``."""
        return f"{'warning' if self.severity == WARNING else 'note'}: {self}"

    def __reduce__(self):               # pickled with its kind and severity (farms)
        return Note, (str(self), self.kind, self.severity)


class BakeWarnings(CrowdError):
    """``--strict``: the bake reported warnings (exit code 2, nothing written)."""

    exit_code = 2


class BakeReport:
    """The notes of one bake, each once, in the order they were found."""

    def __init__(self, notes=()):
        self.notes: list = []
        self.extend(notes)

    def add(self, text, kind: str = "remark", severity: str = WARNING) -> Note:
        """Add a note (a :class:`Note` keeps its own kind and severity); a text already
        reported is not added again. Returns the note."""
        note = Note(text, kind, severity)
        for old in self.notes:
            if old == note:
                return old
        self.notes.append(note)
        return note

    def extend(self, notes, kind: str = "remark", severity: str = WARNING) -> None:
        for n in notes:
            self.add(n, kind, severity)

    @property
    def warnings(self) -> tuple:
        return tuple(n for n in self.notes if n.severity == WARNING)

    def __iter__(self):
        return iter(self.notes)

    def __len__(self) -> int:
        return len(self.notes)

    def __bool__(self) -> bool:
        return bool(self.notes)

    def summary(self) -> str:
        """``"2 warnings, 1 note"`` ("" for an empty report)."""
        w = len(self.warnings)
        i = len(self.notes) - w
        parts = [f"{w} warning{'s' if w != 1 else ''}"] if w else []
        parts += [f"{i} note{'s' if i != 1 else ''}"] if i else []
        return ", ".join(parts)

    def check_strict(self, strict: bool) -> None:
        """Raise :class:`BakeWarnings` when ``strict`` and the report has warnings."""
        if strict and self.warnings:
            n = len(self.warnings)
            raise BakeWarnings(f"--strict: the bake reported {n} warning"
                               f"{'s' if n != 1 else ''} (printed above; the first: "
                               f"{self.warnings[0]}); nothing was written")


def report_of(config) -> BakeReport:
    """The bake report carried by ``config`` (an empty one for a configuration that
    was not baked from a scene, e.g. loaded from a file); the LOD levels the
    silhouette check refused (``config.lod_notes``) are in it either way."""
    report = getattr(config, "bake_report", None)
    if report is None:
        report = BakeReport()
        try:
            config.bake_report = report
        except AttributeError:
            pass
    report.extend(getattr(config, "lod_notes", ()), "lod", WARNING)
    return report
