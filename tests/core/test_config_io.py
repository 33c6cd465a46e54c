"""Saving and loading a crowd configuration (crowd.json + crowd.npz)."""

import functools
import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from crowd_addon.core import (Blend2, BlendMask, BlendSpace2D, ClipPlayer, Controller, Crowd,
                              CrowdConfig, CrowdError, Layer, StateMachine, StateTransition)
from crowd_addon.core.authoring import synthetic
from crowd_addon.core.authoring import config_codec
from crowd_addon.core.authoring.codec import register_kind, unregister_kind
from crowd_addon.core.authoring.config_io import load_config, save_config
from crowd_addon.core.authoring.show import Action, Cue, Reaction, Show, Sweep, Track

DOCS = Path(__file__).resolve().parents[2] / "docs" / "config_format.md"
ARM = ("upperarm.L", "forearm.L", "hand.L")


# --------------------------------------------------------------------------- fixtures
def make_config() -> CrowdConfig:
    """Two skeletons, five clips with events, every controller kind, a unique, 100 agents."""
    cfg = CrowdConfig(max_offset=12, transition_slots=4, fps=24.0, seed=7, when_full="cut",
                      max_texture_size=2048, start_frame=5)
    fan = cfg.add_skeleton(synthetic.humanoid("fan", bones=24))
    kid = cfg.add_skeleton(synthetic.humanoid("kid", bones=26))
    # clips keyed at the crowd's rate (a clip plays at its own fps)
    clip = functools.partial(synthetic.periodic_clip, fps=cfg.fps)
    cfg.add_clip(clip(fan, "walk", events=[("step.L", 10), ("step.R", 40)]))
    cfg.add_clip(clip(fan, "idle", frames=41, seed=2, events=[("breathe", 15.5)]))
    cfg.add_clip(clip(fan, "cheer", frames=31, seed=3, loop=False, events=[("clap", 20)]))
    cfg.add_clip(clip(fan, "wave", frames=25, seed=4, amplitude=1.0, bones=ARM,
                      events=[("wave", 5)]))
    cfg.add_clip(clip(kid, "kid_run", frames=21, seed=5, events=[("kid_step", 7.5)]))
    bones = fan.bone_names
    cfg.add_stream("walk", "fan", ClipPlayer("walk"))
    cfg.add_stream("walk_idle", "fan", Blend2(ClipPlayer("walk", speed=1.25),
                                              ClipPlayer("idle", start=3.5), weight="speed"))
    cfg.add_stream("mask", "fan", BlendMask(
        [ClipPlayer("walk"), ClipPlayer("cheer"), ClipPlayer("idle")],
        [np.linspace(0, 1, 24), {"upperarm.L": 1, "forearm.L": 0.5},
         {b: 0.25 for b in bones}]))
    cfg.add_stream("wave_over", "fan", Layer(ClipPlayer("walk"), ClipPlayer("wave"), "override",
                                             bone_weights={b: 1.0 for b in ARM}, weight=0.8))
    cfg.add_stream("wave_add", "fan", Layer(
        ClipPlayer("idle"), ClipPlayer("wave"), "additive",
        bone_weights=np.linspace(0, 1, 24).astype(np.float32), weight="wave",
        reference=("wave", 0)))
    cfg.add_stream("space", "fan", BlendSpace2D(
        [ClipPlayer("idle"), ClipPlayer("walk"),
         Blend2(ClipPlayer("cheer"), ClipPlayer("wave"), 0.3)],
        [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], x="vx", y=0.25))
    cfg.add_stream("fsm", "fan", StateMachine(
        {"idle": ClipPlayer("idle"),
         "cheer": Layer(ClipPlayer("cheer"), ClipPlayer("wave"), bone_weights=None, weight=0.5),
         "walk": ClipPlayer("walk")},
        [StateTransition("idle", "cheer", 6, trigger="goal"),
         StateTransition("cheer", "walk", 0, condition=("calm", ">=", 0.5)),
         StateTransition("*", "idle", 4.5, trigger="reset", condition=("calm", "<", 0.5))],
        initial="idle"))
    cfg.add_stream("kid", "kid", ClipPlayer("kid_run"))
    cfg.add_unique("hero", "fan", StateMachine(
        {"cheer": ClipPlayer("cheer"), "walk": ClipPlayer("walk")},
        [StateTransition("cheer", "walk", 5, trigger="go")]))
    cfg.add_agents(90, streams=np.arange(90) % 7, offsets="normal", offset_mean=5,
                   offset_std=3, positions=np.random.default_rng(1).uniform(-20, 20, (90, 3)),
                   headings=np.linspace(0, 6, 90))
    cfg.add_agents(6, streams="kid")
    cfg.add_agents(4, streams=0)
    cfg.add_mesh(synthetic.humanoid_mesh(fan, sides=5, rings=3))
    cfg.lod_distances = (12.5, 40.0)
    cfg.agent_stream[-4:] = -1
    cfg.agent_unique[-4:] = 0
    cfg.show = Show(
        (Cue("goal", 8, Action("stream", "walk", 4, offset=2, hold=10), agents=np.arange(0, 90, 3)),
         Cue("wave", 9, Action("stream", "wave_over", 2, offset="random", when_full="cut",
                               hold=6), sweep=Sweep((1.0, 2.0, 0.0), "angle", -2.5, 0.5, 2),
             seed=4),
         Cue("stand", 12, Action("stream", "walk_idle", 0), agents=np.arange(30, 40), spread=5,
             interrupt=True, muted=True),
         Cue("hop", 0, Action("unique", "hero", 3, hold=20), agents=np.array([5]),
             timeline=False),
         Cue("go", 20, Action("trigger", "fsm", name="goal")),
         Cue("calm", 22, Action("parameter", "fsm", name="calm", value=0.75))),
        (Reaction("jump", "clap", "hop", source="mask", radius=3.5),),
        (Track("space", "vx", 5, np.linspace(0, 1, 11)),
         Track("hero", "go", 0, np.r_[np.zeros(15), np.ones(5)], "trigger")))
    assert cfg.agent_count == 100
    return cfg


@pytest.fixture
def saved(tmp_path):
    path = tmp_path / "crowd.json"
    save_config(make_config(), path)
    return path


def assert_same(a, b, where="config"):
    """Structural, bitwise equality (types, dtypes, shapes, order)."""
    assert type(a) is type(b), f"{where}: {type(a).__name__} != {type(b).__name__}"
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, f"{where}: {a.dtype}{a.shape} " \
                                                          f"!= {b.dtype}{b.shape}"
        assert a.tobytes() == b.tobytes(), f"{where}: values differ"
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), f"{where}: length {len(a)} != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for k in a:
            assert_same(a[k], b[k], f"{where}.{k}")
    elif hasattr(a, "__dict__"):       # "_" attributes are transient (lod_notes)
        assert_same({k: v for k, v in vars(a).items() if not k.startswith("_")},
                    {k: v for k, v in vars(b).items() if not k.startswith("_")}, where)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def drive(crowd, frames=40):
    """Step with parameters, triggers and transitions; returns rows per frame and events."""
    events, rows = [], []
    crowd.on_event("*", lambda name, frame, ids: events.append((name, frame, ids.tolist())))
    for i in range(frames):
        if i == 3:
            crowd.set_parameter("walk_idle", "speed", 0.3)
            crowd.set_parameter("space", "vx", 0.7)
            crowd.set_parameter("wave_add", "wave", 0.6)
        if i == 5:
            crowd.set_trigger("fsm", "goal")
        if i == 10:
            crowd.transition_to_unique([0, 7, 14], "hero", 6)
        if i == 12:
            crowd.set_trigger("hero", "go")
        if i == 15:
            crowd.transition_to_streamed([0, 7, 21, 28, 35], "walk", 4, offset=3)
        if i == 18:
            crowd.set_parameter("fsm", "calm", 1.0)
        if i == 25:
            crowd.set_trigger("fsm", "reset")
            crowd.set_parameter("fsm", "calm", 0.0)
        crowd.step()
        rows.append(crowd.storage.rows.copy())
    return rows, events, crowd.state_of("fsm")


# -------------------------------------------------------------------------- round trip
def test_round_trip_is_exact(saved):
    original = make_config()
    loaded = load_config(saved)
    assert_same(original, loaded)
    # derived data too (bind_model is recomputed from the stored bind pose)
    for name, sk in original.skeletons.items():
        assert sk.bind_model.tobytes() == loaded.skeletons[name].bind_model.tobytes()


def test_round_trip_keeps_float32_quaternions_bit_for_bit(tmp_path):
    """Unit float32 rotations are not renormalised (which would move some values by an
    ulp), so rebuilding and loading keep the stored bits."""
    from crowd_addon.core import Clip, Skeleton, identity_pose
    from crowd_addon.core.base.quaternion import normalize
    rng = np.random.default_rng(3)
    bind = identity_pose(200).astype(np.float64)
    bind[:, 3:7] = normalize(rng.normal(size=(200, 4)))
    bind[:, 7:10] = rng.uniform(-0.2, 0.2, (200, 3))
    sk = Skeleton("chain", [f"b{i}" for i in range(200)], np.arange(200) - 1, bind)
    keys = np.repeat(bind[None], 3, axis=0)
    keys[..., 3:7] = normalize(rng.normal(size=(3, 200, 4)))
    clip = Clip("spin", keys)
    assert np.array_equal(Skeleton("c", sk.bone_names, sk.parents, sk.bind_pose).bind_pose,
                          sk.bind_pose)
    assert np.array_equal(Clip("s", clip.keys).keys, clip.keys)
    cfg = CrowdConfig()
    cfg.add_skeleton(sk)
    cfg.add_clip(clip)
    cfg.add_stream("spin", "chain", ClipPlayer("spin"))
    save_config(cfg, tmp_path / "chain.json")
    loaded = load_config(tmp_path / "chain.json")
    assert_same(cfg, loaded)
    assert loaded.skeletons["chain"].bind_model.tobytes() == sk.bind_model.tobytes()


def test_round_trip_twice_gives_identical_files(saved, tmp_path):
    again = tmp_path / "again.json"
    save_config(load_config(saved), again)
    a, b = json.loads(saved.read_text()), json.loads(again.read_text())
    assert a.pop("arrays")["sha256"] == b.pop("arrays")["sha256"]
    assert a == b


def test_loaded_crowd_animates_identically(saved):
    rows_a, events_a, state_a = drive(Crowd(make_config()))
    rows_b, events_b, state_b = drive(Crowd(load_config(saved)))
    assert len(events_a) > 10 and {e[0] for e in events_a} >= {"step.L", "breathe", "kid_step"}
    assert events_a == events_b
    assert state_a == state_b
    for f, (a, b) in enumerate(zip(rows_a, rows_b)):
        assert a.tobytes() == b.tobytes(), f"pose texture differs at step {f}"


def test_manifest_is_readable_json(saved):
    m = json.loads(saved.read_text())
    assert m["format"] == config_codec.FORMAT and m["version"] == "1.4"
    assert m["arrays"]["uri"] == "crowd.npz"
    assert m["settings"] == {"max_offset": 12, "transition_slots": 4, "fps": 24.0, "seed": 7,
                             "when_full": "cut", "max_texture_size": 2048, "start_frame": 5}
    kinds = set()

    def walk(node):
        if isinstance(node, dict):
            if "kind" in node:
                kinds.add(node["kind"])
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)
    walk(m["streams"] + m["uniques"])
    assert kinds == {"clip", "blend2", "mask", "layer", "blend_space_2d", "state_machine"}
    assert m["clips"][0]["events"] == [["step.L", 10.0], ["step.R", 40.0]]
    with np.load(saved.with_suffix(".npz"), allow_pickle=False) as z:
        assert z["clips[0].keys"].shape == (61, 24, 10)
        assert "streams[2].root.masks[0]" in z.files


def test_docs_example_is_a_valid_manifest():
    text = DOCS.read_text(encoding="utf-8")
    blocks = re.findall(r"```json\n(.*?)```", text, re.S)
    assert blocks, "docs/config_format.md has no ```json example"
    m = json.loads(blocks[0])
    assert m["format"] == config_codec.FORMAT
    assert m["version"].split(".")[0] == str(config_codec.VERSION[0])


# --------------------------------------------------------- clips bound by bone name
def test_clip_stored_in_another_bone_order_animates_identically(saved):
    """A file whose clip lists the skeleton's bones in another order (its key columns
    following) plays that clip by name: the crowd animates bit for bit as before."""
    order = np.random.default_rng(5).permutation(24)

    def manifest(m):
        clip = m["clips"][0]
        assert clip["name"] == "walk"
        clip["bone_names"] = [clip["bone_names"][i] for i in order]

    rewrite(saved, manifest=manifest,
            arrays=lambda a: a.update({"clips[0].keys": a["clips[0].keys"][:, order]}))
    loaded = load_config(saved)
    assert loaded.clips["walk"].bone_names != loaded.skeletons["fan"].bone_names
    rows_a, events_a, state_a = drive(Crowd(make_config()))
    rows_b, events_b, state_b = drive(Crowd(loaded))
    assert events_a == events_b and state_a == state_b
    for f, (a, b) in enumerate(zip(rows_a, rows_b)):
        assert a.tobytes() == b.tobytes(), f"pose texture differs at step {f}"


def test_clip_naming_bones_its_skeleton_lacks_is_named(saved):
    """Accepted before (the keys were played by index): a clip whose bone names are not
    its skeleton's is refused before the crowd runs, naming clip, skeleton and bones."""
    rewrite(saved, manifest=lambda m: m["clips"][1]["bone_names"].__setitem__(5, "tail"))
    cfg = load_config(saved)
    with pytest.raises(CrowdError, match=r"stream 'walk_idle': clip 'idle' \(24 bones\) does "
                                         r"not match skeleton 'fan' \(24 bones\): it names "
                                         r"bones the skeleton lacks "
                                         r"\['tail'\] and lacks bones the skeleton has "
                                         r"\['neck'\]"):
        Crowd(cfg)


# ------------------------------------------------------------------ extensibility
class Mirror(Controller):
    def __init__(self, source, axis="x"):
        self.source, self.axis = source, axis

    def children(self):
        return (self.source,)


def test_new_kind_registers_its_own_codec(tmp_path):
    cfg = make_config()
    cfg.streams[0].root = Mirror(ClipPlayer("walk"), "y")
    with pytest.raises(CrowdError, match=r"streams\[0\]\.root: controller type Mirror has no "
                                         "registered kind"):
        save_config(cfg, tmp_path / "c.json")
    assert list(tmp_path.iterdir()) == []
    register_kind("mirror", Mirror,
                  lambda n, enc: {"source": enc.controller(n.source, "source"), "axis": n.axis},
                  lambda d, dec: Mirror(dec.controller(d, "source"), dec.get(d, "axis", "str")))
    try:
        with pytest.raises(CrowdError, match="already registered"):
            register_kind("mirror", Mirror, None, None)
        save_config(cfg, tmp_path / "c.json")
        assert_same(cfg, load_config(tmp_path / "c.json"))
    finally:
        unregister_kind("mirror")
    with pytest.raises(CrowdError, match=r"streams\[0\]\.root: unknown controller kind "
                                         "'mirror'"):
        load_config(tmp_path / "c.json")


# -------------------------------------------------------------------------- errors
def rewrite(path, manifest=None, arrays=None, rehash=True):
    """Edit a saved configuration in place (keeping the checksum valid unless told)."""
    m = json.loads(path.read_text())
    npz = path.with_suffix(".npz")
    if manifest:
        manifest(m)
    if arrays:
        with np.load(npz) as z:
            a = dict(z)
        arrays(a)
        np.savez(npz, **a)
    if rehash:
        m["arrays"]["sha256"] = hashlib.sha256(npz.read_bytes()).hexdigest()
    path.write_text(json.dumps(m))


def _set(obj, keys, value):
    for k in keys[:-1]:
        obj = obj[k]
    if value is _DEL:
        del obj[keys[-1]]
    else:
        obj[keys[-1]] = value


_DEL = object()

MANIFEST_ERRORS = [
    (("format",), "crowd.scene", r"crowd\.json: format: not a crowd configuration"),
    (("version",), "2.0", r"crowd\.json: version: unsupported version '2\.0'"),
    (("version",), _DEL, r"crowd\.json: missing field 'version'"),
    (("settings", "fps"), _DEL, r"crowd\.json: settings: missing field 'fps'"),
    (("settings", "when_full"), "wait", r"settings\.when_full: must be one of"),
    (("streams", 1, "root", "a"), _DEL, r"crowd\.json: streams\[1\]\.root: missing field 'a'"),
    (("streams", 2, "root", "children", 1, "kind"), "foo",
     r"crowd\.json: streams\[2\]\.root\.children\[1\]: unknown controller kind 'foo'"),
    (("uniques", 0, "root", "states", 1, "controller", "kind"), "foo",
     r"uniques\[0\]\.root\.states\[1\]\.controller: unknown controller kind 'foo'"),
    (("clips", 0, "fps"), "thirty", r"crowd\.json: clips\[0\]\.fps: must be a finite number"),
    # numbers are bounded where they are read (each raised a raw error downstream)
    (("clips", 0, "fps"), 1e30, r"clips\[0\]\.fps: must be a finite number of magnitude at "
                                 r"most 1e9, got 1e\+30"),
    (("settings", "start_frame"), 10**30, r"settings\.start_frame: must be an integer of "
                                          r"magnitude at most 2147483647"),
    (("streams", 0, "root", "speed"), 1e308, r"streams\[0\]\.root\.speed: must be a finite"),
    (("clips", 1, "name"), "walk", r"clips\[1\]\.name: duplicate clip name 'walk'"),
    (("streams", 7, "skeleton"), "giant", r"streams\[7\]\.skeleton: unknown skeleton 'giant'"),
    (("streams", 6, "root", "initial"), "nope",
     r"streams\[6\]\.root: state machine: unknown initial state 'nope'"),
    (("streams", 6, "root", "transitions", 1, "condition", "op"), "~",
     r"streams\[6\]\.root\.transitions\[1\]: .*condition must be"),
    (("streams", 2, "root", "masks", 1, "bones", "hand.L"), "lots",
     r"streams\[2\]\.root\.masks\[1\]\.bones\.hand\.L: bone weight must be a number"),
    (("arrays", "uri"), "elsewhere.npz", r"arrays\.uri: array file .*elsewhere\.npz does not "
                                         "exist"),
    # accepted before: a folder outside the manifest's, LOD distances that do not grow
    (("arrays", "uri"), "../crowd.npz", r"arrays\.uri: must name a file beside the "
                                        r"manifest, got '\.\./crowd\.npz'"),
    (("lod_distances",), [30.0, 20.0, 150.0], r"lod_distances: must be strictly "
                                              r"increasing metres > 0"),
    (("lod_distances",), [], r"lod_distances: must name 1 to 8 thresholds"),
    (("lod_distances",), [0.0] * 100, r"lod_distances: must name 1 to 8 thresholds"),
    (("lod_pixels",), [0.0, 0.0], r"lod_pixels: must be strictly decreasing pixels > 0"),
    # accepted before: empty names (an unnamed stream, state or mesh level could not be
    # addressed), and a second mesh for a skeleton silently replaced the first
    (("streams", 0, "name"), "", r"streams\[0\]\.name: must be a non-empty name"),
    (("skeletons", 0, "name"), "", r"skeletons\[0\]\.name: must be a non-empty name"),
    (("clips", 0, "name"), " ", r"clips\[0\]\.name: must be a non-empty name"),
    (("streams", 6, "root", "states", 0, "name"), "",
     r"streams\[6\]\.root\.states\[0\]\.name: must be a non-empty name"),
    (("meshes", 0, "levels", 0, "name"), "", r"meshes\[0\]\.levels\[0\]\.name: must be a "
                                             r"non-empty name"),
]


def test_second_mesh_for_a_skeleton_is_named(saved):
    # accepted before: the second entry silently replaced the first
    rewrite(saved, manifest=lambda m: m["meshes"].append(json.loads(json.dumps(m["meshes"][0]))))
    with pytest.raises(CrowdError, match=r"meshes\[1\]\.skeleton: a second mesh for skeleton "
                                         r"'fan' \(the first is meshes\[0\]\)"):
        load_config(saved)


@pytest.mark.parametrize("keys, value, message", MANIFEST_ERRORS,
                         ids=[".".join(map(str, e[0])) for e in MANIFEST_ERRORS])
def test_bad_manifest_is_named(saved, keys, value, message):
    rewrite(saved, manifest=lambda m: _set(m, keys, value))
    with pytest.raises(CrowdError, match=message):
        load_config(saved)


def test_missing_files(tmp_path, saved):
    with pytest.raises(CrowdError, match=r"nope\.json: no such file"):
        load_config(tmp_path / "nope.json")
    saved.with_suffix(".npz").unlink()
    with pytest.raises(CrowdError, match=r"crowd\.json: arrays\.uri: array file .*crowd\.npz "
                                         "does not exist"):
        load_config(saved)


def test_not_json(saved):
    saved.write_text("{ not json")
    with pytest.raises(CrowdError, match=r"crowd\.json: cannot read the manifest"):
        load_config(saved)
    saved.write_text('{"format": NaN}')
    with pytest.raises(CrowdError, match=r"crowd\.json: cannot read the manifest"):
        load_config(saved)


@pytest.mark.parametrize("opener, closer", [("[", "]"), ('{"a": ', "}")])
def test_json_nested_too_deep_is_named(saved, opener, closer):
    # raised a bare RecursionError from the json parser (found by tests/test_fuzz.py)
    m = json.loads(saved.read_text())
    m["settings"]["seed"] = "@"
    saved.write_text(json.dumps(m).replace('"@"', opener * 100_000 + "1" + closer * 100_000))
    with pytest.raises(CrowdError, match=r"crowd\.json: cannot read the manifest: JSON "
                                         r"nested too deeply"):
        load_config(saved)


def test_array_missing_from_npz(saved):
    rewrite(saved, arrays=lambda a: a.pop("clips[1].keys"))
    with pytest.raises(CrowdError, match=r"crowd\.npz: clips\[1\]\.keys: array "
                                         r"'clips\[1\]\.keys' is missing"):
        load_config(saved)


def test_array_shape_differs_from_manifest(saved):
    rewrite(saved, arrays=lambda a: a.update({"agents.offset": a["agents.offset"][:50]}))
    with pytest.raises(CrowdError, match=r"crowd\.npz: agents\.offset: .* is int32 \(50,\), "
                                         r"the manifest says int32 \(100,\)"):
        load_config(saved)


def test_array_shape_wrong_for_its_field(saved):
    def arrays(a):
        a["skeletons[0].bind_pose"] = a["skeletons[0].bind_pose"][:23]

    rewrite(saved, arrays=arrays,
            manifest=lambda m: _set(m, ("skeletons", 0, "bind_pose", "shape"), [23, 10]))
    with pytest.raises(CrowdError, match=r"crowd\.npz: skeletons\[0\]\.bind_pose: .* has shape "
                                         r"\(23, 10\), expected \(24, 10\)"):
        load_config(saved)


def test_mask_array_must_match_skeleton(saved):
    rewrite(saved, arrays=lambda a: a.update({"streams[2].root.masks[0]": np.ones(5)}),
            manifest=lambda m: _set(m, ("streams", 2, "root", "masks", 0, "shape"), [5]))
    with pytest.raises(CrowdError, match=r"streams\[2\]\.root\.masks\[0\]: .* expected \(24,\)"):
        load_config(saved)


def test_array_dtype_kind_checked(saved):
    rewrite(saved, arrays=lambda a: a.update({"agents.offset": a["agents.offset"] + 0.5}),
            manifest=lambda m: _set(m, ("agents", "offset", "dtype"), "float64"))
    with pytest.raises(CrowdError, match=r"agents\.offset: .* expected an integer dtype"):
        load_config(saved)


def test_checksum_catches_foreign_array_file(saved):
    rewrite(saved, arrays=lambda a: a.update({"agents.heading": a["agents.heading"] + 1}),
            rehash=False)
    with pytest.raises(CrowdError, match=r"arrays\.sha256: .*does not match"):
        load_config(saved)


def test_bad_keys_are_rejected_like_authoring(saved):
    def arrays(a):
        a["clips[2].keys"][4, 3] = np.nan
    rewrite(saved, arrays=arrays)
    with pytest.raises(CrowdError, match=r"clips\[2\]: clip 'cheer': non-finite key at frame 4"):
        load_config(saved)


def test_huge_array_values_are_named(saved):
    """A position of 1e30 metres is finite but overflows everything downstream."""
    def arrays(a):
        a["agents.position"][7, 2] = 1e30
    rewrite(saved, arrays=arrays)
    with pytest.raises(CrowdError, match=r"agents\.position: array 'agents\.position' holds "
                                         r"1e\+30 at \[7, 2\]: values must be at most 1e\+09"):
        load_config(saved)


def test_save_refuses_what_json_cannot_hold(tmp_path):
    cfg = make_config()
    cfg.fps = float("nan")
    with pytest.raises(CrowdError, match=r"settings\.fps: cannot save the non-finite"):
        save_config(cfg, tmp_path / "crowd.json")
    cfg = make_config()
    cfg.agent_position[3, 0] = 2e9
    with pytest.raises(CrowdError, match=r"agents\.position: cannot save 2e\+09: values must "
                                         r"be at most 1e\+09"):
        save_config(cfg, tmp_path / "crowd.json")
    cfg = make_config()
    cfg.clips["renamed"] = cfg.clips.pop("walk")
    with pytest.raises(CrowdError, match=r"clips\[4\]: stored under 'renamed' but named 'walk'"):
        save_config(cfg, tmp_path / "crowd.json")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------- atomicity
def snapshot(directory):
    return {p.name: p.read_bytes() for p in sorted(Path(directory).iterdir())}


def changed_config():
    cfg = make_config()
    cfg.seed = 99
    cfg.agent_offset = cfg.agent_offset[::-1].copy()
    return cfg


def test_failed_array_write_keeps_previous_files(saved, monkeypatch):
    before = snapshot(saved.parent)

    def boom(*a, **k):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(np, "savez", boom)
    with pytest.raises(CrowdError, match=r"crowd\.json: cannot write .*No space left"):
        save_config(changed_config(), saved)
    assert snapshot(saved.parent) == before


def test_failed_manifest_write_keeps_previous_files(saved, monkeypatch):
    before = snapshot(saved.parent)

    def boom(*a, **k):
        raise RuntimeError("interrupted")
    monkeypatch.setattr(json, "dumps", boom)
    with pytest.raises(RuntimeError, match="interrupted"):
        save_config(changed_config(), saved)
    monkeypatch.undo()
    assert snapshot(saved.parent) == before
    assert_same(load_config(saved), make_config())


def test_failed_write_into_empty_directory_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(np, "savez", lambda *a, **k: (_ for _ in ()).throw(OSError("full")))
    with pytest.raises(CrowdError, match="full"):
        save_config(make_config(), tmp_path / "crowd.json")
    assert list(tmp_path.iterdir()) == []


def test_crash_between_renames_is_detected(saved, monkeypatch):
    real, calls = os.replace, []

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError("power cut")
        real(src, dst)
    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(CrowdError, match="power cut"):
        save_config(changed_config(), saved)
    monkeypatch.undo()
    assert [os.path.basename(c) for c in calls] == ["crowd.npz", "crowd.json"]
    assert sorted(p.name for p in saved.parent.iterdir()) == ["crowd.json", "crowd.npz"]
    with pytest.raises(CrowdError, match=r"arrays\.sha256: .*does not match"):
        load_config(saved)


def test_save_into_missing_directory(tmp_path):
    with pytest.raises(CrowdError, match=r"directory .*missing does not exist"):
        save_config(make_config(), tmp_path / "missing" / "crowd.json")


def test_manifest_name_must_not_be_the_array_file(tmp_path):
    with pytest.raises(CrowdError, match="needs a name like"):
        save_config(make_config(), tmp_path / "crowd.npz")


def test_overwrite_keeps_file_mode(saved):
    os.chmod(saved, 0o640)
    save_config(changed_config(), saved)
    assert saved.stat().st_mode & 0o777 == 0o640
    assert load_config(saved).seed == 99


def test_controllers_nested_too_deep_are_named(saved):
    """Regression: 400 nested controllers raised a RecursionError."""
    from crowd_addon.core.authoring.config import MAX_TREE_DEPTH

    def nest(m):
        leaf = m["streams"][0]["root"]
        node = leaf
        for _ in range(400):
            node = {"kind": "blend2", "a": node, "b": leaf, "weight": 0.5}
        m["streams"][0]["root"] = node
    rewrite(saved, manifest=nest)
    with pytest.raises(CrowdError, match=f"nested deeper than {MAX_TREE_DEPTH} levels"):
        load_config(saved)


def test_a_deep_tree_built_in_python_is_named():
    from crowd_addon.core.authoring.config import MAX_TREE_DEPTH
    cfg = make_config()
    root = cfg.streams[0].root
    for _ in range(MAX_TREE_DEPTH + 1):
        root = Blend2(root, cfg.streams[0].root, weight=0.5)
    cfg.streams[0].root = root
    with pytest.raises(CrowdError, match="nested deeper than"):
        Crowd(cfg)
