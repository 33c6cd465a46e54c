"""Fuzz: seeded, time-bounded mutations of crowd configuration files and of ``crowd
export`` / ``crowd preview`` command lines (docs/testing.md, "The fuzz test").

Every outcome must be a success or a *named* error, and nothing may be left behind:

- **config**: a valid configuration (every controller kind, two skeletons with
  meshes, a unique) is saved, then its manifest (deleted keys, other types, huge,
  negative, NaN and infinite numbers, empty and foreign strings, wrong and deep
  nesting, duplicated items, bad array references and URIs, damaged JSON text) or
  its ``.npz`` (truncated, corrupted, other dtypes and shapes, odd values, missing
  members) is mutated and loaded in-process. A loaded config then builds a
  ``Crowd`` and steps it; either must succeed or raise ``CrowdError`` with a message.
- **export** / **preview**: ``crowd_addon.cli.main`` runs in-process with mutated
  arguments (frame ranges, agent counts, sizes, missing, odd or read-only paths,
  existing files, the mutated configs above). Exit 0 with the complete output, or
  exit 2 with one ``crowd <command>: error: <message>`` line last on stderr and no
  traceback, and the sandbox exactly as it was (no temporaries, no partial files).
- **process**: a few of those command lines through ``python -m crowd_addon`` in a
  subprocess, for what only a real process shows (exit status, stderr).
- **snapshot**: a valid crowd snapshot file with its JSON header (keys deleted or
  given other types), its small values (other types, NaN, nested junk), its arrays
  (other dtypes and shapes, NaN, huge or negative values, missing, with the header
  lying to match) or its bytes damaged, then loaded and restored into a running
  crowd: success (and three steps), or a named error that leaves the crowd as it was.

Each case draws from its own ``random.Random(f"{seed}:{part}:{case}")``, so a failure
names the seed, part, case and mutations and replays alone with ``CROWD_FUZZ_SEED`` and
``CROWD_FUZZ_CASE=part:case``. ``CROWD_FUZZ_SECONDS`` is the time for the three
time-bounded parts together (default 24 s; cases run until their part's share is
spent, so a slower machine runs a prefix of the same sequence). The counts are printed
in the terminal summary (tests/conftest.py) whether the tests pass or not.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import io
import json
import os
import random
import re
import resource
import shutil
import signal
import stat
import subprocess
import sys
import time
import traceback
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from crowd_addon.cli import main as crowd_main
from crowd_addon.core import (Blend2, BlendMask, BlendSpace2D, ClipPlayer, Crowd, CrowdConfig,
                              CrowdError, Layer, StateMachine, StateTransition)
from crowd_addon.core.authoring import synthetic as sy
from crowd_addon.core.authoring.config_io import load_config, save_config

SEED = int(os.environ.get("CROWD_FUZZ_SEED", "1711"))
SECONDS = float(os.environ.get("CROWD_FUZZ_SECONDS", "24"))
CASE = os.environ.get("CROWD_FUZZ_CASE", "")        # "part:case" replays one case
#: Share of CROWD_FUZZ_SECONDS per time-bounded part.
SHARE = {"config": 0.35, "export": 0.25, "preview": 0.25, "snapshot": 0.15}
#: A single case taking longer than this is a failure (a hang), not a slow success.
CASE_LIMIT_S = 20.0
#: ... and so is one allocating more than this much address space.
CASE_MEMORY = 3 * 2**30

NAN, INF = float("nan"), float("inf")
ARM = ("upperarm.L", "forearm.L", "hand.L")


# ------------------------------------------------------------------- the valid start
def base_config() -> CrowdConfig:
    """Small but complete: two skeletons with meshes (one with an LOD), five clips with
    events, every controller kind, a unique, nine agents."""
    cfg = CrowdConfig(max_offset=4, transition_slots=2, fps=24.0, seed=3)
    fan = cfg.add_skeleton(sy.humanoid("fan", bones=24))
    kid = cfg.add_skeleton(sy.humanoid("kid", bones=25))
    cfg.add_clip(sy.periodic_clip(fan, "walk", frames=9, events=[("step", 2)]))
    cfg.add_clip(sy.periodic_clip(fan, "idle", frames=7, seed=2, events=[("breathe", 1.5)]))
    cfg.add_clip(sy.periodic_clip(fan, "cheer", frames=7, seed=3, loop=False,
                                  events=[("clap", 4)]))
    cfg.add_clip(sy.periodic_clip(fan, "wave", frames=5, seed=4, bones=ARM))
    cfg.add_clip(sy.periodic_clip(kid, "run", frames=5, seed=5, events=[("jump", 1)]))
    cfg.add_stream("walk", "fan", ClipPlayer("walk", speed=1.5, start=1.0))
    cfg.add_stream("mix", "fan", Blend2(ClipPlayer("walk"), ClipPlayer("idle"), weight="w"))
    cfg.add_stream("mask", "fan", BlendMask(
        [ClipPlayer("walk"), ClipPlayer("cheer")],
        [np.linspace(0.1, 1, 24), {"upperarm.L": 1.0, "forearm.L": 0.5}]))
    cfg.add_stream("layer", "fan", Layer(
        ClipPlayer("idle"), ClipPlayer("wave"), "additive",
        bone_weights=np.linspace(0, 1, 24).astype(np.float32), weight=0.7,
        reference=("wave", 0)))
    cfg.add_stream("space", "fan", BlendSpace2D(
        [ClipPlayer("idle"), ClipPlayer("walk"), ClipPlayer("cheer")],
        [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], x="vx", y=0.25))
    cfg.add_stream("fsm", "fan", StateMachine(
        {"idle": ClipPlayer("idle"),
         "cheer": Layer(ClipPlayer("idle"), ClipPlayer("cheer"), bone_weights={"head": 1.0}),
         "walk": ClipPlayer("walk")},
        [StateTransition("idle", "cheer", 2, trigger="goal"),
         StateTransition("cheer", "walk", 0, condition=("calm", ">=", 0.5)),
         StateTransition("*", "idle", 1.5, trigger="reset", condition=("calm", "<", 0.5))],
        initial="idle"))
    cfg.add_stream("kid", "kid", ClipPlayer("run"))
    cfg.add_unique("hero", "fan", StateMachine(
        {"cheer": ClipPlayer("cheer"), "walk": ClipPlayer("walk")},
        [StateTransition("cheer", "walk", 2, trigger="go")]))
    cfg.add_agents(7, streams=np.arange(7) % 6, offsets=np.arange(7) % 4,
                   positions=np.c_[np.arange(7.0), np.zeros(7), np.zeros(7)],
                   headings=np.linspace(0, 3, 7))
    cfg.add_agents(2, streams="kid", offsets=[1, 3], positions=[[0, 2, 0], [1, 2, 0]])
    cfg.agent_stream[0], cfg.agent_unique[0] = -1, 0
    cfg.add_mesh(sy.humanoid_mesh(fan, sides=4, rings=2), lods=(0.5,))
    cfg.add_mesh(sy.humanoid_mesh(kid, sides=4, rings=2), lods=())
    cfg.lod_distances = (20.0,)
    return cfg


class Pristine:
    """The valid configuration on disk: manifest dict, ``.npz`` bytes and arrays."""

    def __init__(self, directory: Path):
        directory.mkdir(parents=True, exist_ok=True)
        self.json = directory / "crowd.json"
        save_config(base_config(), self.json)
        self.manifest = json.loads(self.json.read_text())
        self.npz_bytes = self.json.with_suffix(".npz").read_bytes()
        with np.load(self.json.with_suffix(".npz")) as z:
            self.arrays = {k: z[k] for k in z.files}
        self.strings = sorted({s for _, s in _walk(self.manifest) if isinstance(s, str)})

    def copy_to(self, directory: Path, stem="crowd") -> Path:
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"{stem}.json"
        m = copy.deepcopy(self.manifest)
        m["arrays"]["uri"] = f"{stem}.npz"
        path.with_suffix(".npz").write_bytes(self.npz_bytes)
        path.write_text(json.dumps(m))
        return path


# ------------------------------------------------------------------ manifest mutations
def _walk(obj, path=()):
    yield path, obj
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _walk(v, path + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _walk(v, path + (i,))


def _get(obj, path):
    for k in path:
        obj = obj[k]
    return obj


def _weird(rng, pristine):
    """A value of the wrong kind, size or sign for most fields."""
    return copy.deepcopy(rng.choice([
        None, True, False, 0, 1, -1, 2, 0.5, -0.5, 1e-300, 2**31 - 1, 2**31, -2**31 - 1,
        2**63, 10**30, 1e9, 1e9 + 1, -1e9, 1e308, NAN, INF, -INF, "", " ", "x", "-1", "1e3",
        "\u2603", "\x00", "*", "a" * 5000, [], [0], [[]], [None], [1, 2, 3], {}, {"x": 1},
        {"kind": "clip"}, {"kind": "clip", "clip": "walk"}, {"bones": {}},
        {"bones": {"head": -1.0}}, {"array": "agents.offset", "dtype": "int32", "shape": [9]},
        {"name": "x"}, rng.choice(pristine.strings)]))


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number_variant(rng, v):
    return rng.choice([
        v + 1, v - 1, -v, v * 2, v * 2**31, v + 0.5, v - 0.5, 0, -1, 2**31 - 1, 2**31,
        -2**31, 1e9, 1e9 + 1, 1e-9, 1e308, NAN, INF, -INF, str(v), bool(v)])


def _string_variant(rng, v, pristine):
    return rng.choice([
        "", " ", v + "x", v.upper(), v * 3, v[:1], "\x00", "\u00e9\u2603", "a" * 5000, "*",
        "../" + v, "/" + v, rng.choice(pristine.strings), rng.choice(pristine.strings), 0,
        None, [v]])


DEEP = "__fuzz_deep__"


def mutate_manifest(rng, m, pristine, notes):
    """One structural mutation of manifest ``m`` in place; appends what to ``notes``."""
    nodes = [(p, v) for p, v in _walk(m) if p]
    op = rng.choice(["delete", "delete", "replace", "replace", "number", "number", "string",
                     "string", "retype", "duplicate", "swap", "nest", "ref", "ref", "deep",
                     "deep_tree", "rename_dup"])
    pick = {
        "number": [n for n in nodes if _is_number(n[1])],
        "string": [n for n in nodes if isinstance(n[1], str)],
        "duplicate": [n for n in nodes if isinstance(n[0][-1], int)],
        "swap": [n for n in nodes if isinstance(n[1], list) and len(n[1]) >= 2],
        "ref": [n for n in nodes if isinstance(n[1], dict) and "array" in n[1]],
        "deep_tree": [n for n in nodes if isinstance(n[1], dict) and "kind" in n[1]],
        "rename_dup": [n for n in nodes if isinstance(n[1], list) and len(n[1]) >= 2
                       and all(isinstance(x, dict) and "name" in x for x in n[1])],
    }.get(op, nodes)
    if not pick:
        op, pick = "replace", nodes
    path, value = rng.choice(pick)
    parent, key = _get(m, path[:-1]), path[-1]
    where = ".".join(map(str, path))
    if op == "delete":
        del parent[key]
    elif op == "replace":
        parent[key] = _weird(rng, pristine)
    elif op == "number":
        parent[key] = _number_variant(rng, value)
    elif op == "string":
        parent[key] = _string_variant(rng, value, pristine)
    elif op == "retype":
        parent[key] = ({str(i): v for i, v in enumerate(value)} if isinstance(value, list)
                       else list(value.values()) if isinstance(value, dict)
                       else str(value) if not isinstance(value, str) else [value])
    elif op == "duplicate":
        parent.insert(rng.randrange(len(parent) + 1), copy.deepcopy(value))
    elif op == "swap":
        i, j = rng.sample(range(len(value)), 2)
        value[i], value[j] = value[j], value[i]
    elif op == "nest":
        parent[key] = rng.choice([[value], {"value": value}, [value, value]])
    elif op == "ref":
        field = rng.choice(["array", "array", "dtype", "shape", "shape", "extra"])
        if field == "array":
            value["array"] = rng.choice([*pristine.arrays, "nope", "", "../x"])
        elif field == "dtype":
            value["dtype"] = rng.choice(["float16", "float32", "float64", "int32", "int64",
                                         "uint8", "bool", "object", "<U3", "complex64", "x"])
        elif field == "shape":
            shape = value.get("shape")
            value["shape"] = rng.choice([[], [0], [-1], [2**31 - 1], [1.5], None, "3",
                                         (shape or [])[:-1], (shape or []) + [1],
                                         [s + 1 for s in shape or [] if _is_number(s)]])
        else:
            value.pop(rng.choice(["array", "dtype", "shape"]), None)
        where += f".{field}"
    elif op == "deep":
        parent[key] = DEEP
    elif op == "deep_tree":
        depth = rng.choice([60, 63, 64, 65, 70, 300])
        node = value
        for _ in range(depth):
            node = rng.choice([{"kind": "blend2", "a": node, "b": {"kind": "clip",
                                                                   "clip": "idle"}},
                               {"kind": "layer", "base": {"kind": "clip", "clip": "walk"},
                                "layer": node}])
        parent[key] = node
        op = f"deep_tree({depth})"
    elif op == "rename_dup":
        i, j = rng.sample(range(len(value)), 2)
        value[i]["name"] = value[j]["name"]
    notes.append(f"{op} {where}")


def manifest_text(rng, m, notes) -> bytes:
    text = json.dumps(m)                                      # NaN/Infinity written raw
    if DEEP in text:
        depth = rng.choice([50, 900, 3000, 100_000])
        opener = rng.choice(["[", '{"a":'])
        closer = "]" if opener == "[" else "}"
        text = text.replace(json.dumps(DEEP), opener * depth + "1" + closer * depth, 1)
        notes.append(f"deep json nesting {depth} ({opener})")
    data = text.encode()
    if rng.random() < 0.12:
        op = rng.choice(["truncate", "cut", "insert", "bom", "replace", "latin1"])
        n = len(data)
        if op == "truncate":
            data = data[:rng.randrange(n)]
        elif op == "cut":
            i = rng.randrange(n)
            data = data[:i] + data[i + rng.randrange(1, 40):]
        elif op == "insert":
            i = rng.randrange(n)
            data = data[:i] + rng.choice([b"\xff\xfe", b"\x00", b"{", b"]", b",", b'"',
                                          b"\xc3", b"NaN", b"1" * 5000]) + data[i:]
        elif op == "bom":
            data = b"\xef\xbb\xbf" + data
        elif op == "replace":
            data = rng.choice([b"", b"null", b"[]", b"{}", b"1e999", b'"crowd"', b"1" * 5000,
                               bytes(rng.randrange(256) for _ in range(64))])
        else:
            data = text.replace("walk", "w\u00e4lk").encode("latin-1", "replace")
        notes.append(f"json text {op}")
    return data


# ---------------------------------------------------------------------- npz mutations
def _ref_paths(m, name):
    return [p for p, v in _walk(m) if isinstance(v, dict) and v.get("array") == name]


def mutate_arrays(rng, m, arrays, notes):
    """One mutation of the arrays (dict, in place); sometimes the manifest's references
    follow, so the mutation reaches the checks behind the reference check."""
    name = rng.choice(sorted(arrays))
    a = arrays[name]
    op = rng.choice(["values", "values", "values", "dtype", "shape", "delete", "rename",
                     "object", "fortran", "bigendian"])
    follow = rng.random() < 0.7
    if op == "values" and a.dtype.kind not in "fiu":    # mutated before to bool, str, ...
        op = "delete"
    if op == "values":
        a = a.copy()
        flat, idx = a.reshape(-1), None
        if flat.size:
            idx = rng.randrange(flat.size) if rng.random() < 0.6 else slice(None)
            if a.dtype.kind == "f":
                flat[idx] = rng.choice([NAN, INF, -INF, 0.0, -1.0, 1e30, -1e30, 1e-30, 2.0])
            else:
                info = np.iinfo(a.dtype)
                flat[idx] = rng.choice([v for v in (-1, -2, 0, 1, 7, 24, 25, 100, 2**15, 2**31 - 1,
                                                    info.max, info.min)
                                        if info.min <= v <= info.max])
        op = f"values {'one' if isinstance(idx, int) else 'all'}"
    elif op == "dtype":
        dt = rng.choice(["float16", "float32", "float64", "int8", "int16", "int32", "int64",
                         "uint8", "uint16", "uint32", "uint64", "bool", "complex64", "<U3"])
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")               # NaN to int, complex to real
            a = a.astype(dt)
        op = f"dtype {dt}"
    elif op == "shape":
        kind = rng.choice(["drop", "add", "flat", "empty", "scalar", "transpose", "expand"])
        a = {"drop": lambda x: x[:-1], "add": lambda x: np.concatenate([x, x[:1]]),
             "flat": lambda x: x.reshape(-1), "empty": lambda x: x[:0],
             "scalar": lambda x: np.array(x.reshape(-1)[0] if x.size else 0, x.dtype),
             "transpose": lambda x: np.ascontiguousarray(x.T),
             "expand": lambda x: x[None]}[kind](a)
        op = f"shape {kind} -> {a.shape}"
    elif op == "delete":
        del arrays[name]
        notes.append(f"npz delete {name}")
        return
    elif op == "rename":
        arrays[name + "x"] = arrays.pop(name)
        notes.append(f"npz rename {name}")
        return
    elif op == "object":
        a = np.array([object()] * max(1, a.shape[0] if a.ndim else 1), dtype=object)
        a[:] = [None] * a.shape[0]
    elif op == "fortran":
        a = np.asfortranarray(a)
    elif op == "bigendian":
        a = a.astype(a.dtype.newbyteorder(">"))
    arrays[name] = a
    if follow:
        for p in _ref_paths(m, name):
            ref = _get(m, p)
            ref["dtype"], ref["shape"] = a.dtype.name, list(a.shape)
    notes.append(f"npz {op} {name}{' (manifest follows)' if follow else ''}")


def npz_bytes(rng, data: bytes, notes) -> bytes:
    """Damage the archive's bytes."""
    op = rng.choice(["truncate", "flip", "zero", "garbage", "npy", "empty_zip", "header"])
    n = len(data)
    if op == "truncate":
        data = data[:rng.randrange(n)]
    elif op == "flip":
        b = bytearray(data)
        for _ in range(rng.choice([1, 1, 4, 64])):
            b[rng.randrange(n)] ^= 1 << rng.randrange(8)
        data = bytes(b)
    elif op == "zero":
        data = b""
    elif op == "garbage":
        data = bytes(rng.randrange(256) for _ in range(rng.choice([1, 100, 4096])))
    elif op == "npy":
        buf = io.BytesIO()
        np.save(buf, np.zeros(3))
        data = buf.getvalue()
    elif op == "empty_zip":
        buf = io.BytesIO()
        np.savez(buf)
        data = buf.getvalue()
    else:                                   # damage the header of one member
        i = data.find(b"\x93NUMPY")
        i = i if i >= 0 else 0
        data = data[:i + 10] + b"{'descr': 'x', 'fortran_order': 7, 'shape': (-1,), }" + \
            data[i + 10:]
    notes.append(f"npz bytes {op}")
    return data


#: Fields the format lets a file leave out (docs/config_format.md, section 3).
OPTIONAL = {"generator", "units", "sha256", "bytes", "events", "bone_names", "meshes",
            "lod_distances", "speed", "start", "weight", "initial", "transitions",
            "duration", "trigger", "condition", "mode", "reference", "bone_weights", "seed",
            "when_full", "max_texture_size", "start_frame"}
#: Numbers that may take many values: field name -> a valid value.
SOFT_NUMBERS = {
    "speed": lambda r: r.choice([0.0, -1.0, 0.001, r.uniform(-5, 5), 1e6]),
    "start": lambda r: r.choice([0.0, -3.5, r.uniform(-100, 100), 1e9]),
    "weight": lambda r: r.choice([0.0, 1.0, -2.0, 3.0, r.uniform(0, 1), "w", "other"]),
    "duration": lambda r: r.choice([0.0, 0.25, r.uniform(0, 20), 1e9]),
    "value": lambda r: r.uniform(-1, 1),
    "frame": lambda r: r.choice([0, 0.5, 4.0]),
    "fps": lambda r: r.choice([1.0, 12.5, 60.0, 1e-3, 1e9]),
    "max_offset": lambda r: r.choice([1, 2, 8]),
    "transition_slots": lambda r: r.choice([0, 1, 5]),
    "seed": lambda r: r.choice([0, -1, 2**31 - 1]),
    "start_frame": lambda r: r.choice([-50, 1, 100, -2**31 + 100, 2**31 - 100]),
    "max_texture_size": lambda r: r.choice([64, 512, 1024, 2**31 - 1]),
    "when_full": lambda r: r.choice(["queue", "cut"]),
    "x": lambda r: r.choice([0.5, "vx", "speed"]),
    "y": lambda r: r.choice([-4.0, 0.0, "vy"]),
}


def soften(rng, m, arrays, notes):
    """A mutation that keeps the file valid more often than not: an optional field
    left out, another plausible number, other agent data."""
    nodes = [(p, v) for p, v in _walk(m) if p and isinstance(p[-1], str)]
    op = rng.choice(["optional", "number", "number", "agents", "agents", "lods"])
    if op == "optional":
        path = rng.choice([p for p, _ in nodes if p[-1] in OPTIONAL])
        del _get(m, path[:-1])[path[-1]]
    elif op == "number":
        path = rng.choice([p for p, _ in nodes if p[-1] in SOFT_NUMBERS])
        _get(m, path[:-1])[path[-1]] = SOFT_NUMBERS[path[-1]](rng)
    elif op == "agents":
        key = rng.choice(["agents.offset", "agents.position", "agents.heading",
                          "agents.color", "agents.stream"])
        a = arrays[key].copy()
        if key == "agents.offset":
            a[:] = [rng.randrange(4) for _ in a]
        elif key == "agents.stream":
            a[1:7] = [rng.randrange(6) for _ in range(6)]
        else:
            a[...] = np.random.default_rng(rng.randrange(2**32)).uniform(
                *rng.choice([(-1, 1), (-1e6, 1e6), (0, 0)]), a.shape)
        arrays[key] = a
        path = (key,)
    else:
        m["lod_distances"] = rng.choice([[], [0.0], [1e9], [0.0, 1.0, 2.0, 3.0], [5.5, 6]])
        path = ("lod_distances",)
    notes.append(f"soft {op} {'.'.join(map(str, path))}")


def mutated_config(rng, pristine, directory: Path, notes) -> Path:
    """Write a mutated copy of the pristine configuration into ``directory``: softly
    (often still valid), in its arrays, in the bytes of its archive or its manifest."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "crowd.json"
    npz = directory / "crowd.npz"
    m = copy.deepcopy(pristine.manifest)
    data = pristine.npz_bytes
    arrays = dict(pristine.arrays)
    r = rng.random()
    if r < 0.3:
        for _ in range(rng.choice([1, 1, 2, 3])):
            soften(rng, m, arrays, notes)
    elif r < 0.5:
        for _ in range(rng.choice([1, 1, 1, 2])):
            if arrays:
                mutate_arrays(rng, m, arrays, notes)
    elif r < 0.58:
        data = npz_bytes(rng, data, notes)
    if r >= 0.5 or rng.random() < 0.15:
        for _ in range(rng.choice([1, 1, 1, 2, 3])):
            mutate_manifest(rng, m, pristine, notes)
    if r < 0.5:
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        data = buf.getvalue()
    ad = m.get("arrays") if isinstance(m, dict) else None
    if data != pristine.npz_bytes and isinstance(ad, dict):
        sha = rng.random()
        if sha < 0.8:
            ad["sha256"] = hashlib.sha256(data).hexdigest()
        elif sha < 0.95:
            ad.pop("sha256", None)
            notes.append("no sha256")
        else:
            notes.append("stale sha256")
    npz.write_bytes(data)
    path.write_bytes(manifest_text(rng, m, notes))
    return path


# ------------------------------------------------------------------------- the checks
class Tally:
    """Outcomes of one part: ``named`` errors, ``ok`` successes, ``other`` failures."""

    def __init__(self, part):
        self.part, self.counts, self.failures = part, Counter(), []
        self.cases, self.seconds = 0, 0.0

    def add(self, case, outcome, notes, detail=""):
        self.cases += 1
        self.counts[outcome] += 1
        if outcome == "other":
            self.failures.append(f"{self.part}:{case} [{'; '.join(notes)}]\n    {detail}")

    def line(self):
        c = self.counts
        return (f"fuzz {self.part}: {self.cases} cases in {self.seconds:.1f} s (seed {SEED}): "
                f"{c['named']} named errors, {c['ok']} successes, {c['other']} other")

    def report(self):
        if not self.failures:
            return ""
        return (f"{len(self.failures)} outcome(s) neither a success nor a named error "
                f"(replay one: CROWD_FUZZ_SEED={SEED} CROWD_FUZZ_CASE=<part:case> "
                f"pytest tests/test_fuzz.py):\n" + "\n".join(self.failures[:20]))


class CaseTimeout(BaseException):
    """A case ran longer than CASE_LIMIT_S."""


@contextlib.contextmanager
def case_limits(seconds=CASE_LIMIT_S, memory=CASE_MEMORY):
    """A case may run ``seconds`` and allocate ``memory`` bytes more address space than
    the process has: beyond, it fails (CaseTimeout, MemoryError) instead of hanging the
    run or waking the machine's OOM killer."""
    def fire(*_):
        raise CaseTimeout(f"still running after {seconds:g} s")
    old = signal.signal(signal.SIGALRM, fire)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as f:
        used = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    limit = used + memory
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _cases(part):
    """Case numbers of ``part`` while its share of the time lasts (or the one to replay)."""
    if CASE:
        want_part, _, want_case = CASE.partition(":")
        if want_part == part:
            yield int(want_case)
        return
    end = time.monotonic() + SECONDS * SHARE[part]
    case = 0
    while time.monotonic() < end:
        yield case
        case += 1


def _summary(exc: BaseException) -> str:
    """The exception and where it came from; the whole traceback when replaying."""
    if CASE:
        return "".join(traceback.format_exception(exc))
    tb = traceback.extract_tb(exc.__traceback__)
    where = " <- ".join(f"{Path(f.filename).name}:{f.lineno} {f.name}" for f in tb[::-1][:4])
    return f"{type(exc).__name__}: {str(exc)[:200]} at {where}"


def snapshot(directory: Path) -> dict:
    """Every path under ``directory`` -> (kind, mode, and for files size and mtime): a
    folder's own size and mtime change when a temporary comes and goes, its entries
    tell whether one stayed."""
    out = {}
    for root, dirs, files in os.walk(directory):
        for name in dirs + files:
            p = os.path.join(root, name)
            st = os.lstat(p)
            kind = stat.S_IFMT(st.st_mode)
            out[os.path.relpath(p, directory)] = (kind, stat.S_IMODE(st.st_mode)) + (
                () if kind == stat.S_IFDIR else (st.st_size, st.st_mtime_ns))
    return out


def changes(before: dict, after: dict) -> set:
    return {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}


def _leftovers(paths) -> list:
    return sorted(p for p in paths if re.search(r"(^|/)\.[^/]*(\.tmp|partial)[^/]*$|"
                                                r"(^|/)\.[^/]*\.tmp(/|$)", p))


def _run_main(argv) -> tuple:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = crowd_main(argv)
    return code, out.getvalue(), err.getvalue()


def error_problem(command, code, err) -> str:
    """'' when ``err`` ends with one named error line of ``crowd <command>``: exit code
    2, or 3 for a crowd script refused as untrusted (README: nothing done; met when
    the command reads the .blend an earlier test left open, having no --config)."""
    if code not in (2, 3) or (code == 3 and "not trusted" not in err):
        return f"exit code {code!r}, expected 0, 2 or 3 (an untrusted script)"
    if "Traceback" in err:
        return "a traceback on stderr"
    lines = [line for line in err.splitlines() if line.strip()]
    named = [line for line in lines if re.match(rf"crowd( {command})?: error: \S", line)]
    if not lines or len(named) != 1 or named[0] != lines[-1]:
        return f"stderr does not end with one 'crowd [{command}]: error: ...' line"
    return ""


# --------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    return Pristine(tmp_path_factory.mktemp("fuzz_pristine"))


def _record(request, tally):
    """The counts, printed by tests/conftest.py's terminal summary, pass or fail."""
    request.node.user_properties.append(("summary", tally.line()))


# ------------------------------------------------------------------------ config part
def load_outcome(path: Path, steps=3) -> tuple:
    """("ok" | "named" | "other", detail) for loading ``path`` and stepping its crowd."""
    try:
        with case_limits():
            try:
                cfg = load_config(path)
            except CrowdError as e:
                return ("named", "") if str(e).strip() else ("other", "CrowdError without "
                                                                      "a message")
            try:
                crowd = Crowd(cfg)
                for _ in range(steps):
                    crowd.step()
            except CrowdError as e:
                return ("named", "") if str(e).strip() else ("other", "CrowdError without "
                                                                      "a message (Crowd)")
            return "ok", ""
    except (Exception, CaseTimeout) as e:                 # noqa: BLE001 - the finding
        return "other", _summary(e)


def test_fuzz_config_loader(pristine, tmp_path, request):
    tally = Tally("config")
    t0 = time.monotonic()
    for case in _cases("config"):
        rng = random.Random(f"{SEED}:config:{case}")
        notes = []
        directory = tmp_path / f"c{case}"
        path = mutated_config(rng, pristine, directory, notes)
        before = snapshot(directory)
        outcome, detail = load_outcome(path)
        written = changes(before, snapshot(directory))
        if written:
            outcome, detail = "other", f"loading changed files: {sorted(written)}"
        tally.add(case, outcome, notes, detail)
        shutil.rmtree(directory)
    tally.seconds = time.monotonic() - t0
    _record(request, tally)
    assert tally.counts["other"] == 0, tally.report()
    assert tally.cases or CASE, "no case ran"


# ---------------------------------------------------------------------- snapshot part
def snapshot_crowd() -> Crowd:
    """The valid configuration's crowd 8 frames in, some agents blending."""
    crowd = Crowd(base_config())
    crowd.advance_to(4)
    crowd.transition_to_streamed([0, 1, 2], 1, 6)
    crowd.advance_to(8)
    return crowd


def mutated_snapshot(rng, good: Path, path: Path, notes) -> None:
    """A snapshot file with its header, its arrays or its bytes damaged."""
    from crowd_addon.core.shots.snapshot import HEADER
    kind = rng.choice(["header", "header", "values", "values", "arrays", "bytes"])
    if kind == "bytes":
        path.write_bytes(npz_bytes(rng, good.read_bytes(), notes))
        return
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}
    head = json.loads(arrays.pop(HEADER).tobytes())
    if kind == "header":
        key = rng.choice(sorted(head))
        op = rng.choice(["delete", "weird"])
        if op == "delete":
            del head[key]
        else:
            head[key] = rng.choice([None, -1, 2**63, 1.5, "x", [], {}, NAN, True])
        notes.append(f"header {key}: {op}")
    elif kind == "values":
        key = rng.choice(sorted(head["values"]))
        value = head["values"][key]
        choices = [None, -1, 2**40, 0.5, "x", [], {}, [1, "a"], {"w": "x"}, NAN, INF, True]
        if isinstance(value, list) and value:
            value = list(value)
            value[rng.randrange(len(value))] = rng.choice(choices)
            head["values"][key] = value
        elif isinstance(value, dict) and value:
            value = dict(value)
            value[rng.choice(sorted(value))] = rng.choice(choices)
            head["values"][key] = value
        else:
            head["values"][key] = rng.choice(choices)
        notes.append(f"value {key}")
    else:
        name = rng.choice(sorted(arrays))
        a = arrays[name]
        op = rng.choice(["dtype", "shape", "nan", "huge", "negative", "missing", "codec"])
        if op == "dtype":
            arrays[name] = a.astype(rng.choice([np.float64, np.int8, np.bool_, np.float32]))
        elif op == "shape":
            arrays[name] = a.reshape(-1)[:max(0, a.size - 1)]
        elif op == "nan" and a.dtype.kind == "f":
            arrays[name] = np.full_like(a, NAN)
        elif op == "huge" and a.dtype.kind in "iu":
            arrays[name] = np.full_like(a, np.iinfo(a.dtype).max)
        elif op == "negative" and a.dtype.kind == "i":
            arrays[name] = np.full_like(a, -7)
        elif op == "missing":
            del arrays[name]
        elif op == "codec":                 # the packed form the header gives the array
            spec = head["arrays"].get(name.split(":")[0])
            if isinstance(spec, dict):
                spec["codec"] = rng.choice(["raw", "ints", "rows", "zip", None, 3])
        if name in arrays and op in ("dtype", "shape") and rng.random() < 0.5:
            head["arrays"][name] = {"dtype": arrays[name].dtype.str,
                                    "shape": list(arrays[name].shape)}   # a consistent lie
        notes.append(f"array {name}: {op}")
    with open(path, "wb") as f:
        np.savez(f, **{HEADER: np.frombuffer(json.dumps(head).encode(), np.uint8)}, **arrays)


def restore_outcome(crowd: Crowd, path: Path, steps=3) -> tuple:
    """("ok" | "named" | "other", detail) for loading and restoring ``path`` into
    ``crowd`` and stepping it; a refused snapshot must leave the crowd as it was."""
    from crowd_addon.core.shots.snapshot import load_snapshot
    before = (crowd.frame, crowd.agent_poses().copy(), crowd.agents.kind.copy())
    try:
        with case_limits():
            try:
                crowd.restore(load_snapshot(path))
            except CrowdError as e:
                after = (crowd.frame, crowd.agent_poses(), crowd.agents.kind)
                if not (before[0] == after[0]
                        and np.array_equal(before[1], after[1], equal_nan=True)
                        and np.array_equal(before[2], after[2])):
                    return "other", f"refused ({e}) but the crowd changed"
                return ("named", "") if str(e).strip() else ("other", "no message")
            try:
                for _ in range(steps):
                    crowd.step()
            except CrowdError as e:
                return ("named", "") if str(e).strip() else ("other", "no message (step)")
            return "ok", ""
    except (Exception, CaseTimeout) as e:                 # noqa: BLE001 - the finding
        return "other", _summary(e)


def test_fuzz_snapshot_loader(tmp_path, request):
    tally = Tally("snapshot")
    t0 = time.monotonic()
    good = tmp_path / "good.npz"
    snapshot_crowd().snapshot().save(good)
    crowd = Crowd(base_config())
    crowd.advance_to(3)
    for case in _cases("snapshot"):
        rng = random.Random(f"{SEED}:snapshot:{case}")
        notes = []
        path = tmp_path / f"s{case}.npz"
        mutated_snapshot(rng, good, path, notes)
        outcome, detail = restore_outcome(crowd, path)
        if outcome != "named":
            crowd = Crowd(base_config())                   # a clean crowd again
            crowd.advance_to(3)
        tally.add(case, outcome, notes, detail)
        path.unlink()
    tally.seconds = time.monotonic() - t0
    _record(request, tally)
    assert tally.counts["other"] == 0, tally.report()
    assert tally.cases or CASE, "no case ran"


# --------------------------------------------------------------------------- CLI part
def _config_arg(rng, pristine, sandbox: Path, notes) -> str:
    r = rng.random()
    if r < 0.55:
        return str(pristine.copy_to(sandbox / "cfg"))
    if r < 0.9:
        return str(mutated_config(rng, pristine, sandbox / "cfg", notes))
    odd = rng.choice(["missing", "dir", "empty", "npz", "devnull", "nul", "blank"])
    notes.append(f"config {odd}")
    if odd == "dir":
        (sandbox / "cfgdir.json").mkdir()
        return str(sandbox / "cfgdir.json")
    if odd == "empty":
        (sandbox / "empty.json").write_bytes(b"")
        return str(sandbox / "empty.json")
    if odd == "npz":
        return str(pristine.copy_to(sandbox / "cfg").with_suffix(".npz"))
    return {"missing": str(sandbox / "nope.json"), "devnull": os.devnull,
            "nul": str(sandbox / "a\x00b.json"), "blank": ""}[odd]


def _out_arg(rng, sandbox: Path, notes, kind: str) -> str:
    """A ``--out`` path; odd places are prepared in the sandbox."""
    out = sandbox / "out"
    out.mkdir()
    name = "shot.usdc" if kind == "export" else "frames"
    r = rng.random()
    if r < 0.6:
        ext = rng.choice([".usdc", ".usdc", ".usda", ".usd", ".USDA"]) if kind == "export" \
            else ""
        return str(out / f"shot{ext}" if kind == "export" else out / name)
    odd = rng.choice(["existing_file", "existing_dir", "missing_parent", "parent_is_file",
                      "read_only", "nul", "long", "unicode", "bad_ext", "no_stem",
                      "blank", "layers_is_file", "old_export"])
    notes.append(f"out {odd}")
    target = out / name
    if odd == "existing_file":
        target.write_bytes(b"not a layer")
    elif odd == "existing_dir":
        target.mkdir()
        if kind == "preview":
            (target / "frame_0001.png").write_bytes(b"old")
    elif odd == "missing_parent":
        target = out / "a" / "b" / name
    elif odd == "parent_is_file":
        (out / "file").write_bytes(b"x")
        target = out / "file" / name
    elif odd == "read_only":
        (out / "ro").mkdir()
        (out / "ro").chmod(0o555)
        target = out / "ro" / name
    elif odd == "nul":
        target = out / f"a\x00{name}"
    elif odd == "long":
        target = out / ("x" * 300 + name)
    elif odd == "unicode":
        target = out / f"\u00e9t\u00e9 \u2603 {name}"
    elif odd == "bad_ext":
        target = out / rng.choice(["shot.txt", "shot", "shot.usdz", "shot.json"])
    elif odd == "no_stem":
        target = out / ".usdc"
    elif odd == "blank":
        return ""
    elif odd == "layers_is_file":
        (out / "shot.layers").write_bytes(b"x")
    elif odd == "old_export":
        (out / "shot.layers" / "v1").mkdir(parents=True)
        (out / "shot.layers" / "v1" / "old.usdc").write_bytes(b"x")
        (out / ".shot.usdc.stale.tmp").mkdir()          # a killed export's, owner gone
        (out / ".shot.usdc.stale.tmp" / "owner").write_text("nohost 1\n")
    return str(target)


def _frames_arg(rng) -> str:
    if rng.random() < 0.75:
        a = rng.randrange(-1, 6)
        return rng.choice([f"{a}-{a + rng.randrange(0, 4)}", str(a), f" {a} - {a + 1} "])
    return rng.choice(["5-2", "", "x", "1-", "--3", "1e3", "0x10", "1.5", "2147483647",
                       "2147483646-2147483647", "99999999999999999999",
                       "-99999999999999999999-0", "0-99999999999999999999",
                       "\u0661-\u0663", "200000-200001"])


def _int_arg(rng, usual, odd) -> str:
    return str(rng.choice(usual)) if rng.random() < 0.8 else str(rng.choice(odd))


ODD_INTS = ["0", "-1", "x", "", "1.5", "1e3", "99999999999999999999", "-99999999999999999999",
            "2147483647", "-2147483647", "2147483648", "0x10"]


def _junk(rng, argv) -> list:
    """Usage errors and oddities around a command line."""
    op = rng.choice(["unknown", "dup", "drop", "help", "stray", "eq"])
    if op == "unknown":
        argv.insert(rng.randrange(1, len(argv) + 1), "--bogus")
    elif op == "dup":
        argv += argv[1:3]
    elif op == "drop":
        i = rng.randrange(1, len(argv))
        del argv[i:i + rng.choice([1, 2])]
    elif op == "help":
        argv.append("--help")
    elif op == "stray":
        argv.append("stray")
    else:
        argv[:] = [argv[0]] + [f"{a}={b}" if a.startswith("--") and not b.startswith("--")
                               else a for a, b in zip(argv[1:], argv[2:] + [""])]
    return [f"junk {op}"]


def export_argv(rng, pristine, sandbox, notes) -> tuple:
    cfg = _config_arg(rng, pristine, sandbox, notes)
    out = _out_arg(rng, sandbox, notes, "export")
    argv = ["export", "--config", cfg, "--out", out, "--frames", _frames_arg(rng)]
    if rng.random() < 0.4:
        argv += ["--agents", _int_arg(rng, [1, 3, 9], ODD_INTS + ["10", "1000"])]
    if rng.random() < 0.5:
        argv.append("--json")
    if rng.random() < 0.05:
        argv += ["--blend", "scene.blend"]              # exclusive with --config
    if rng.random() < 0.08:
        notes += _junk(rng, argv)
    return argv, out


def preview_argv(rng, pristine, sandbox, notes) -> tuple:
    cfg = _config_arg(rng, pristine, sandbox, notes)
    out = _out_arg(rng, sandbox, notes, "preview")
    argv = ["preview", "--config", cfg, "--out", out,
            "--frames", _int_arg(rng, [1, 2, 3], ["0", "-1", "x", "", "1.5"])]
    if rng.random() < 0.3:
        argv += ["--start", _int_arg(rng, [0, 5, -3], ODD_INTS)]
    for side in ("--width", "--height"):
        if rng.random() < 0.9:
            argv += [side, _int_arg(rng, [16, 24, 31, 32], ["1", "2", "0", "-4", "16385",
                                                            "99999999999999999999", "x"])]
    if rng.random() < 0.12:
        argv.append("--mp4")
    if rng.random() < 0.1:
        argv += ["--backend", rng.choice(["moderngl", "vulkan", ""])]
    if rng.random() < 0.5:
        argv.append("--json")
    if rng.random() < 0.08:
        notes += _junk(rng, argv)
    frames = _option(argv, "--frames")
    if frames is not None and frames.strip().lstrip("-").isdigit() and int(frames) > 3:
        # a junk shift made a frame count of an odd --start: a valid request that only
        # takes long (there is no upper bound), so keep it short
        argv[:] = ["--frames=3" if a == f"--frames={frames}" else a for a in argv]
        for i, a in enumerate(argv[:-1]):
            if a == "--frames" and argv[i + 1] == frames:
                argv[i + 1] = "3"
    return argv, out


def _option(argv, name):
    """The value argparse takes for option ``name`` (the last one given), or None."""
    value = None
    for i, a in enumerate(argv):
        if a == name and i + 1 < len(argv):
            value = argv[i + 1]
        elif a.startswith(name + "="):
            value = a[len(name) + 1:]
    return value


def check_export_output(sandbox, out, argv, stdout, changed) -> str:
    """'' when a successful ``crowd export`` left its complete output and nothing else."""
    if "--help" in argv:
        return f"--help changed files: {sorted(changed)}" if changed else ""
    from pxr import Usd
    main = Path(out).resolve()
    rel_main = os.path.relpath(main, sandbox)
    layers = os.path.relpath(main.parent / f"{main.stem}.layers", sandbox)
    stray = [p for p in changed if p != rel_main and p != layers and
             not p.startswith(layers + os.sep) and not Path(layers).is_relative_to(p)]
    if stray or not main.is_file():
        return f"success, but main layer {main} missing or stray changes {sorted(stray)}"
    if "--json" in argv:
        summary = json.loads(stdout)
        for rel, size in summary["files"].items():
            if (main.parent / rel).stat().st_size != size:
                return f"success, but {rel} is not {size} B"
        agents = summary["agents"]
    else:
        if f"wrote {out}" not in stdout and f"wrote {main}" not in stdout:
            return f"success, but no summary on stdout: {stdout[:200]!r}"
        agents = None
    stage = Usd.Stage.Open(str(main))
    prims = stage.GetPrimAtPath("/Crowd/Agents") if stage else None
    if not prims or (agents is not None and len(prims.GetChildren()) != agents):
        return "success, but the written stage has not the agents"
    return ""


def check_preview_output(sandbox, out, argv, stdout, changed) -> str:
    if "--help" in argv:
        return f"--help changed files: {sorted(changed)}" if changed else ""
    folder = Path(out).resolve()
    rel = os.path.relpath(folder, sandbox)
    stray = [p for p in changed if not (p == rel or p.startswith(rel + os.sep)
                                        or Path(rel).is_relative_to(p))]
    if stray:
        return f"success, but stray changes {sorted(stray)}"
    pngs = sorted(p for p in changed if re.fullmatch(r"frame_-?\d+\.png", Path(p).name))
    frames = int(_option(argv, "--frames"))
    if len(pngs) != frames:
        return f"success, but {len(pngs)} new PNGs for {frames} frames"
    for p in pngs:
        if not (sandbox / p).read_bytes().startswith(b"\x89PNG\r\n\x1a\n"):
            return f"success, but {p} is not a PNG"
    if "--mp4" in argv and (folder / "preview.mp4").stat().st_size == 0:
        return "success, but preview.mp4 is empty"
    if "--json" in argv:
        summary = json.loads(stdout)
        if {str(Path(p).resolve()) for p in summary["pngs"]} != \
                {str(sandbox / p) for p in pngs}:
            return "success, but --json lists other PNGs"
    return ""


def run_cli_case(kind, rng, pristine, sandbox, notes) -> tuple:
    argv, out = (export_argv if kind == "export" else preview_argv)(rng, pristine, sandbox,
                                                                    notes)
    before = snapshot(sandbox)
    try:
        with case_limits(), contextlib.chdir(sandbox):     # relative paths land in it too
            code, stdout, err = _run_main(argv)
    except (Exception, CaseTimeout, SystemExit) as e:      # noqa: BLE001 - the finding
        return "other", f"{argv!r}: {_summary(e)}"
    changed = changes(before, snapshot(sandbox))
    left = _leftovers(changed)
    if code == 0:
        check = check_export_output if kind == "export" else check_preview_output
        problem = check(sandbox, out, argv, stdout, changed)
        if left:
            problem = f"success, but temporaries left: {left}"
        return ("ok", "") if not problem else ("other", f"{argv!r}: {problem}")
    problem = error_problem(kind, code, err)
    if not problem and changed:
        problem = f"failed, but changed {sorted(changed)[:6]}"
    if problem:
        return "other", f"{argv!r}: {problem}; stderr: {err.strip()[-300:]!r}"
    return "named", ""


def _fuzz_cli(kind, pristine, tmp_path, request):
    # the valid command first, untimed: imports, GL context and shader compilation
    warm = tmp_path / "warm"
    code, _, err = _run_main([kind, "--config", str(pristine.copy_to(warm)), "--out",
                              str(warm / ("shot.usda" if kind == "export" else "frames")),
                              "--frames", "1", *(["--width", "16", "--height", "16"]
                                                 if kind == "preview" else [])])
    assert code == 0, err
    tally = Tally(kind)
    t0 = time.monotonic()
    for case in _cases(kind):
        rng = random.Random(f"{SEED}:{kind}:{case}")
        notes = []
        sandbox = tmp_path / f"{kind}{case}"
        sandbox.mkdir()
        outcome, detail = run_cli_case(kind, rng, pristine, sandbox, notes)
        tally.add(case, outcome, notes, detail)
        for root, dirs, _ in os.walk(sandbox):      # read-only folders, to remove them
            for d in dirs:
                os.chmod(os.path.join(root, d), 0o755)
        shutil.rmtree(sandbox)
    tally.seconds = time.monotonic() - t0
    _record(request, tally)
    assert tally.counts["other"] == 0, tally.report()
    assert tally.cases or CASE, "no case ran"


def test_fuzz_cli_export(pristine, tmp_path, request):
    pytest.importorskip("pxr", reason="usd-core (crowd_addon[usd]) not installed")
    _fuzz_cli("export", pristine, tmp_path, request)


def test_fuzz_cli_preview(pristine, tmp_path, request):
    moderngl = pytest.importorskip("moderngl", reason="moderngl (crowd_addon[gpu]) not "
                                                      "installed")
    try:
        moderngl.create_standalone_context(backend="egl", require=430).release()
    except Exception as e:                                      # noqa: BLE001
        pytest.skip(f"no headless EGL OpenGL 4.3 context on this machine: {e}")
    _fuzz_cli("preview", pristine, tmp_path, request)


# ------------------------------------------------------------------------ process part
def process_argv(case, rng, pristine, sandbox, notes) -> tuple:
    """``(argv, out)``: 0 a valid export, 1 an export of a mutated configuration, 2 a
    mutated export command line, 3 a preview of a damaged or missing configuration
    (named before any GL is needed)."""
    if case % 4 == 0:
        out = str(sandbox / "shot.usda")
        return ["export", "--config", str(pristine.copy_to(sandbox / "cfg")), "--out", out,
                "--frames", "0-2"], out
    if case % 4 == 1:
        out = str(sandbox / "shot.usdc")
        return ["export", "--config", str(mutated_config(rng, pristine, sandbox / "cfg",
                                                          notes)),
                "--out", out, "--frames", _frames_arg(rng)], out
    if case % 4 == 2:
        return export_argv(rng, pristine, sandbox, notes)
    cfg = rng.choice([str(sandbox / "nope.json"), os.devnull, str(sandbox)])
    notes.append(f"preview config {cfg}")
    return ["preview", "--config", cfg, "--out", str(sandbox / "frames"), "--frames", "1"], \
        str(sandbox / "frames")


def test_fuzz_process(pristine, tmp_path, request):
    """A few command lines through a real ``python -m crowd_addon`` process: its exit
    status and its stderr as a user sees them."""
    pytest.importorskip("pxr", reason="usd-core (crowd_addon[usd]) not installed")
    tally = Tally("process")
    t0 = time.monotonic()
    cases = [int(CASE.partition(":")[2])] if CASE.startswith("process:") else \
        [] if CASE else range(4)
    for case in cases:
        rng = random.Random(f"{SEED}:process:{case}")
        notes = []
        sandbox = tmp_path / f"process{case}"
        sandbox.mkdir()
        argv, out = process_argv(case, rng, pristine, sandbox, notes)
        if any("\x00" in a for a in argv):             # cannot be passed to a process
            argv = [a.replace("\x00", "") for a in argv]
        before = snapshot(sandbox)
        proc = subprocess.run([sys.executable, "-m", "crowd_addon", *argv], cwd=sandbox,
                              capture_output=True, text=True, timeout=120)
        changed = changes(before, snapshot(sandbox))
        if proc.returncode == 0:
            check = check_export_output if argv[0] == "export" else check_preview_output
            problem = check(sandbox, out, argv, proc.stdout, changed) or \
                (f"temporaries left: {_leftovers(changed)}" if _leftovers(changed) else "")
            outcome = "ok"
        else:
            problem = error_problem(argv[0], proc.returncode, proc.stderr) or \
                (f"failed, but changed {sorted(changed)[:6]}" if changed else "")
            outcome = "named"
        if problem:
            outcome, problem = "other", f"{argv!r}: {problem}; stderr: " \
                                        f"{proc.stderr.strip()[-300:]!r}"
        tally.add(case, outcome, notes, problem)
    tally.seconds = time.monotonic() - t0
    _record(request, tally)
    assert tally.counts["other"] == 0, tally.report()
