"""docs/scripting.md: its generated tables are what the extension registers, and its
worked script builds the crowd and show it describes."""

import os
import re
import sys
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview, reference  # noqa: E402

DOC = Path(__file__).resolve().parents[2] / "docs" / "scripting.md"


extension = cs.extension_fixture()


def test_the_reference_is_what_is_registered():
    text = DOC.read_text(encoding="utf-8")
    generated = text[text.index(reference.BEGIN):text.index(reference.END)
                     + len(reference.END)] + "\n"
    assert generated == reference.reference(), \
        "docs/scripting.md is stale: python -m crowd_addon.blender.reference docs/scripting.md"
    for name in ("CROWD_PG_settings", "CROWD_PG_character", "CROWD_PG_cue",
                 "CROWD_PG_reaction", "CROWD_PG_parameter", "bpy.ops.crowd.bake()"):
        assert name in generated
    # every operator registered is in it (issue 35: crowd.trust_script was not)
    from crowd_addon.blender.registration import CLASSES
    ops = [c.bl_idname for c in CLASSES if issubclass(c, bpy.types.Operator)]
    assert "crowd.trust_script" in ops and "crowd.import_usd" in ops
    for op in ops:
        assert f"`bpy.ops.{op}()`" in generated, op


def test_the_worked_script_builds_its_crowd_and_show(capsys):
    preview.stop_all()
    cs.reset()
    script = re.search(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S).group(1)
    exec(compile(script, str(DOC), "exec"), {"__name__": "__main__"})
    printed = capsys.readouterr().out
    counts = eval(printed.strip().splitlines()[-1])          # the script's last print
    assert counts == {"wave": 60, "front row": 5, "answer": 60}
