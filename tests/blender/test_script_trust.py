"""Trusting a .blend's crowd script trusts that file's text and nothing else (issue 31).

Each scene's crowd script leaves a marker file from its module body and another from
its ``register(crowd)`` (``crowd_scene.scripted_blend``); the oracle is the file system:
a script that must not run has written neither. Every test runs with Blender's *Auto
Run Python Scripts* preference off (the bpy module's default), except the one that
checks the preference still works as documented (docs/show.md, "A crowd script").
"""

import os
import sys

import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import crowd_script, preview, scene_config  # noqa: E402
from crowd_addon.core.base.errors import ScriptNotTrusted  # noqa: E402
from crowd_addon.farm.chunks import export_chunk, write_shot_snapshots  # noqa: E402
from crowd_addon.shot_source import ShotSource  # noqa: E402

UNTRUSTED = "did not run: scripts in .blend files are not trusted"

extension = cs.extension_fixture()


def export_blend(out, frames, on_bake=None, **source):
    """``crowd export --blend``'s path: the shot opened by ShotSource, exported."""
    return export_chunk(ShotSource(**source), frames, out, on_bake=on_bake)


@pytest.fixture(autouse=True)
def auto_run_off():
    """Blender's Auto Run preference off, nothing trusted before or after the test."""
    prefs = bpy.context.preferences.filepaths
    keep = prefs.use_scripts_auto_execute
    prefs.use_scripts_auto_execute = False
    crowd_script.forget_trusted_scripts()
    yield
    preview.stop_all()
    crowd_script.forget_trusted_scripts()
    prefs.use_scripts_auto_execute = keep


def ran(markers) -> list:
    """Which of a script's markers exist (and remove them for the next check)."""
    found = [m.name for m in markers if m.exists()]
    for m in markers:
        m.unlink(missing_ok=True)
    return found


def build(scene):
    """The scene's crowd built as the preview and the exports build it: its note."""
    return scene_config.build_crowd(scene, scene_config.config_from_scene(scene))[1]


def test_trust_script_in_the_panel_then_opening_another_file_leaves_it_untrusted(tmp_path,
                                                                                monkeypatch):
    monkeypatch.setattr(preview, "_has_viewport", lambda: True)    # opened in Blender's UI
    other = tmp_path / "other.blend"
    b = cs.scripted_blend(other, tmp_path, "other")
    preview.start(bpy.context.scene)            # saved with its preview on: File > Open
    bpy.ops.wm.save_mainfile()                  # rebuilds it from on_load_post
    assert ran(b) == [] and UNTRUSTED in preview.get(bpy.context.scene).script_note
    a = cs.scripted_blend(tmp_path / "mine.blend", tmp_path, "mine")
    preview.start(bpy.context.scene)
    assert ran(a) == [] and UNTRUSTED in preview.get(bpy.context.scene).script_note
    assert bpy.ops.crowd.trust_script() == {"FINISHED"}        # the panel's button
    assert ran(a) == ["mine.body", "mine.register"]            # the preview rebuilt with it
    assert preview.get(bpy.context.scene).script_note == ""

    bpy.ops.wm.open_mainfile(filepath=str(other))              # File > Open
    scene = bpy.context.scene
    pv = preview.get(scene)
    assert pv is not None and UNTRUSTED in pv.script_note
    assert ran(b) == []
    preview.start(scene)
    assert UNTRUSTED in build(scene) and ran(b) == []

    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "mine.blend"))   # back: still trusted
    assert build(bpy.context.scene) == "" and ran(a) == ["mine.body", "mine.register"]


def test_a_changed_text_or_a_copy_of_the_file_is_untrusted_again(tmp_path):
    a = cs.scripted_blend(tmp_path / "mine.blend", tmp_path, "mine")
    scene = bpy.context.scene
    bpy.ops.crowd.trust_script()
    assert build(scene) == "" and ran(a) == ["mine.body", "mine.register"]
    text = scene.crowd.show.script
    text.write("\n# edited after it was trusted\n")
    assert UNTRUSTED in build(scene) and ran(a) == []
    bpy.ops.crowd.trust_script()                               # trusting the new text
    assert build(scene) == "" and ran(a) == ["mine.body", "mine.register"]
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "copy.blend"))
    assert UNTRUSTED in build(bpy.context.scene) and ran(a) == []     # another file


def test_export_blend_trusts_the_script_for_that_call_only(tmp_path):
    a = cs.scripted_blend(tmp_path / "mine.blend", tmp_path, "mine")
    b = cs.scripted_blend(tmp_path / "other.blend", tmp_path, "other")
    export_blend(str(tmp_path / "1" / "s.usdc"), (1, 4), blend=str(tmp_path / "mine.blend"),
                 trust_scripts=True)
    assert ran(a) == ["mine.body", "mine.register"]
    with pytest.raises(ScriptNotTrusted, match=UNTRUSTED):      # not another show
        export_blend(str(tmp_path / "2" / "s.usdc"), (1, 4),
                     blend=str(tmp_path / "other.blend"))
    assert ran(b) == [] and not (tmp_path / "2").exists()
    notes = []
    export_blend(str(tmp_path / "2" / "s.usdc"), (1, 4), blend=str(tmp_path / "other.blend"),
                 on_bake=lambda done, total, message: notes.append(message),
                 ignore_scripts=True)
    assert ran(b) == [] and "crowd script 'show.py' left out (--ignore-scripts)" in notes
    with pytest.raises(ScriptNotTrusted, match=UNTRUSTED):
        export_blend(str(tmp_path / "3" / "s.usdc"), (1, 4),
                     blend=str(tmp_path / "mine.blend"))
    assert ran(a) == []                                        # nor the file trusted before
    assert UNTRUSTED in build(bpy.context.scene) and ran(a) == []


def test_a_failing_trusted_call_leaves_nothing_trusted(tmp_path):
    a = cs.scripted_blend(tmp_path / "mine.blend", tmp_path, "mine")
    b = cs.scripted_blend(tmp_path / "other.blend", tmp_path, "other")
    with pytest.raises(Exception):
        export_blend(str(tmp_path / "1" / "s.usdc"), (1, 4), blend=str(tmp_path / "mine.blend"),
                     scene="no such scene", trust_scripts=True)
    with pytest.raises(ScriptNotTrusted):
        export_blend(str(tmp_path / "2" / "s.usdc"), (1, 4),
                     blend=str(tmp_path / "other.blend"))
    assert ran(a) == [] and ran(b) == []


def test_auto_run_python_scripts_still_runs_every_file_s_script(tmp_path):
    b = cs.scripted_blend(tmp_path / "other.blend", tmp_path, "other")
    bpy.context.preferences.filepaths.use_scripts_auto_execute = True
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "other.blend"))
    assert not bpy.app.autoexec_fail
    assert build(bpy.context.scene) == "" and ran(b) == ["other.body", "other.register"]
    # --ignore-scripts leaves it out even where it is trusted: every machine, one show
    export_blend(str(tmp_path / "1" / "s.usdc"), (1, 4), blend=str(tmp_path / "other.blend"),
                 ignore_scripts=True)
    assert ran(b) == []


def test_every_command_refuses_an_untrusted_script_with_exit_code_3(tmp_path, capsys):
    """Issue 35, item 6: ``crowd preview`` and ``crowd snapshot`` refuse before anything
    is baked, rendered or written, and Blender's own ``-c crowd export``
    (:func:`crowd_command`, on the open file) exits 3 with the reason;
    ``--ignore-scripts`` goes on without the script."""
    from crowd_addon.blender.cli_commands import crowd_command
    from crowd_addon.cli import main
    b = cs.scripted_blend(tmp_path / "other.blend", tmp_path, "other")
    blend = str(tmp_path / "other.blend")
    assert main(["preview", "--blend", blend, "--out", str(tmp_path / "frames"),
                 "--frames", "2"]) == 3
    assert UNTRUSTED in capsys.readouterr().err
    with pytest.raises(ScriptNotTrusted, match=UNTRUSTED):
        write_shot_snapshots(ShotSource(blend=blend), str(tmp_path / "snaps"), (1, 4), 2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.blend"] and ran(b) == []
    out = str(tmp_path / "cli" / "s.usdc")
    assert crowd_command(["export", "--out", out, "--frames", "1-4"]) == 3
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("crowd export: error: crowd script 'show.py' did not run")
    assert not (tmp_path / "cli").exists() and ran(b) == []
    assert crowd_command(["export", "--out", out, "--frames", "1-4",
                          "--ignore-scripts"]) == 0
    assert (tmp_path / "cli" / "s.usdc").is_file() and ran(b) == []
