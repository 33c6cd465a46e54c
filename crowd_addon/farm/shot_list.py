"""``crowd farm``'s shot list: a JSON file of shots read into :class:`~.cluster.FarmShot`
objects, every problem a CrowdError naming the file, the shot and the key, each shot
checked before anything runs (docs/snapshots.md).
"""

from __future__ import annotations

import contextlib
import json
import os

from ..core.base.errors import CrowdError
from ..shot_source import ShotSource
from .chunks import chunked_output
from .cluster import FarmShot

__all__ = ["load_shot_list"]


#: what a shot of a shot list may say, with its JSON type
_SHOT_KEYS = {"config": str, "blend": str, "scene": str, "trust_scripts": bool,
              "ignore_scripts": bool, "strict": bool, "out": str,
              "frames": str, "agents": int, "layout": str, "substeps": int,
              "chunk_frames": int}


def load_shot_list(path) -> list:
    """The :class:`FarmShot` list of a shot list file (docs/snapshots.md): JSON
    ``{"shots": [{"config" | "blend": ..., "frames": "FIRST-LAST", "out": ..., ...}]}``,
    paths relative to the file's folder. Every problem is a CrowdError naming the
    file, the shot and the key; each shot is checked as ``crowd export`` checks its
    shot before anything runs (:func:`.chunks.chunked_output`), its output's folder
    made (none when a shot is refused)."""
    from ..cli_args import frame_range
    from ..core.authoring.config import MAX_SUBSTEPS, USD_LAYOUTS
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise CrowdError(f"{path}: no such shot list") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise CrowdError(f"{path}: not a JSON shot list: {e}") from None
    shots = data.get("shots") if isinstance(data, dict) else None
    if not isinstance(shots, list) or not shots:
        raise CrowdError(f'{path}: needs {{"shots": [...]}} with at least one shot')
    base = os.path.dirname(os.path.abspath(path))
    out, outs = [], {}
    for i, shot in enumerate(shots):
        where = f"{path}: shot {i}"
        if not isinstance(shot, dict):
            raise CrowdError(f"{where}: must be an object")
        for key, value in shot.items():
            kind = _SHOT_KEYS.get(key)
            if kind is None:
                raise CrowdError(f"{where}: unknown key {key!r} (known: {sorted(_SHOT_KEYS)})")
            if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
                raise CrowdError(f"{where}: {key!r} must be a {kind.__name__}, got {value!r}")
        for key in ("out", "frames"):
            if key not in shot:
                raise CrowdError(f"{where}: {key!r} is required")
        if ("config" in shot) == ("blend" in shot):
            raise CrowdError(f"{where}: give one of 'config' and 'blend'")
        try:
            frames = frame_range(shot["frames"])
        except Exception as e:  # noqa: BLE001 - argparse's type error, named here
            raise CrowdError(f"{where}: 'frames': {e}") from None
        if shot.get("trust_scripts") and shot.get("ignore_scripts"):
            raise CrowdError(f"{where}: 'trust_scripts' and 'ignore_scripts' exclude each "
                             "other")
        if shot.get("layout", "instanced") not in USD_LAYOUTS:
            raise CrowdError(f"{where}: 'layout' must be one of {list(USD_LAYOUTS)}")
        if not 1 <= shot.get("substeps", 1) <= MAX_SUBSTEPS:
            raise CrowdError(f"{where}: 'substeps' must be 1..{MAX_SUBSTEPS}")
        for key in ("agents", "chunk_frames"):
            if key in shot and shot[key] < 1:
                raise CrowdError(f"{where}: {key!r} must be at least 1")
        target = os.path.normpath(os.path.join(base, shot["out"]))
        stem = os.path.splitext(target)[0]      # <stem>.layers and <stem>.chunks are its
        if stem in outs:
            j, other, other_target = outs[stem]
            if other_target == target:
                raise CrowdError(f"{where}: 'out' {shot['out']!r} is another shot's output "
                                 f"too (shot {j}'s {other!r})")
            raise CrowdError(f"{where}: 'out' {shot['out']!r} and shot {j}'s {other!r} "
                             f"differ only by extension: both would write "
                             f"{os.path.basename(stem)}.layers/ and "
                             f"{os.path.basename(stem)}.chunks/ in "
                             f"{os.path.dirname(stem)}; give them different names")
        outs[stem] = (i, shot["out"], target)

        def at(key):
            return os.path.normpath(os.path.join(base, shot[key])) if key in shot else None
        source = ShotSource(config=at("config"), blend=at("blend"), scene=shot.get("scene"),
                            trust_scripts=shot.get("trust_scripts", False),
                            ignore_scripts=shot.get("ignore_scripts", False),
                            agents=shot.get("agents"), layout=shot.get("layout", "instanced"),
                            substeps=shot.get("substeps", 1),
                            strict=shot.get("strict", False))
        out.append(FarmShot(source, target, frames, shot.get("chunk_frames")))
    with contextlib.ExitStack() as made:    # a bad shot leaves no folder made for the others
        for i, (shot, given) in enumerate(zip(out, shots)):
            try:
                made.enter_context(chunked_output(shot.source, shot.out, shot.frames))
            except CrowdError as e:
                raise CrowdError(f"{path}: shot {i} ('out' {given['out']!r}): {e}") from None
    return out
