"""The built extension zip installs into Blender and registers/unregisters cleanly.

Built with ``packaging.build_extension`` (Blender's own extension tool) and installed
with ``bpy.ops.extensions.package_install_files`` in a subprocess whose Blender user
directories live in a temporary folder (as tests/packaging does). There the
extension is disabled and enabled twice with a preview running each time; Blender's
registries are the oracle for what is left: ``bpy.types``, ``bpy.app.handlers``,
``Scene.crowd``, and ``draw_handler_remove`` refusing the preview's draw handler.
"""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from crowd_addon import packaging

pytest.importorskip("bpy", reason="the bpy module is needed to build the extension")

SCRIPT = textwrap.dedent("""
    import json, sys
    import bpy
    import addon_utils
    zip_path, helpers = sys.argv[1], sys.argv[2]
    sys.path.insert(0, helpers)
    import crowd_scene as cs
    name = "bl_ext.user_default.crowd_animation"

    def leftovers():
        lists = [getattr(bpy.app.handlers, n) for n in dir(bpy.app.handlers)]
        return {
            "types": [n for n in dir(bpy.types) if n.startswith("CROWD_")],
            "scene_crowd": hasattr(bpy.types.Scene, "crowd"),
            "handlers": [h.__qualname__ for lst in lists if isinstance(lst, list)
                         for h in lst if getattr(h, "__module__", "").startswith(name)],
        }

    out = {"install": sorted(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True))}
    out["file"] = sys.modules[name].__file__
    out["cycles"] = []
    for cycle in range(2):
        if cycle:
            bpy.ops.preferences.addon_enable(module=name)
        enabled = leftovers()
        scene = bpy.context.scene          # (a factory reset would disable add-ons)
        s = scene.crowd
        if not cycle:                      # the scene data outlives a disable/enable
            rig = cs.make_armature()
            cs.add_character(s, rig)
            cs.add_stream(s, "walk", cs.make_action(rig, "walk"))
            src = s.agent_sources.add()
            src.object = cs.make_seats(4, 4)
        enabled["streams"] = len(s.characters[0].streams)
        baked = sorted(bpy.ops.crowd.bake())
        preview = sys.modules[name + ".crowd_addon.blender.preview"]
        handle = preview.draw_handle()
        agents = preview.get(scene).crowd.agents.count
        bpy.ops.preferences.addon_disable(module=name)
        try:
            bpy.types.SpaceView3D.draw_handler_remove(handle, "WINDOW")
            draw_handler_left = True
        except ValueError:
            draw_handler_left = False
        out["cycles"].append({"enabled": enabled, "baked": baked, "agents": agents,
                              "had_draw_handler": handle is not None,
                              "after_disable": leftovers(),
                              "draw_handler_left": draw_handler_left,
                              "addon_listed": name in bpy.context.preferences.addons})
    print(json.dumps(out))
""")


@pytest.fixture(scope="module")
def extension_zip(tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    return packaging.build_extension(out, progress=lambda *_: None)[0]


def test_installed_extension_registers_and_unregisters_twice_cleanly(extension_zip,
                                                                      tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    run = subprocess.run([sys.executable, "-c", SCRIPT, extension_zip,
                          os.path.dirname(__file__)],
                         env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["install"] == ["FINISHED"]
    assert out["file"].startswith(str(tmp_path / "blender_user"))
    assert len(out["cycles"]) == 2
    for cycle in out["cycles"]:
        on = cycle["enabled"]
        assert on["scene_crowd"] and "CROWD_OT_bake" in on["types"] and on["streams"] == 1
        assert {"on_frame_change", "on_load_post", "on_undo"} <= set(on["handlers"])
        assert cycle["baked"] == ["FINISHED"] and cycle["agents"] == 16
        assert cycle["had_draw_handler"]
        assert cycle["after_disable"] == {"types": [], "scene_crowd": False, "handlers": []}
        assert not cycle["draw_handler_left"] and not cycle["addon_listed"]


def test_package_and_api_import_without_blender():
    """``import crowd_addon`` (the extension's entry) and the headless API never need
    bpy: the Blender modules load only inside ``register()``."""
    code = textwrap.dedent("""
        import sys
        sys.modules["bpy"] = None                      # any 'import bpy' now fails
        import crowd_addon
        from crowd_addon import api
        from crowd_addon.core.synthetic import humanoid, periodic_clip
        from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig
        sk = humanoid(bones=24)
        cfg = CrowdConfig(max_offset=4)
        cfg.add_skeleton(sk)
        cfg.add_clip(periodic_clip(sk, "walk", frames=9, events=[("step", 2.0)]))
        cfg.add_stream("walk", sk.name, ClipPlayer("walk"))
        cfg.add_agents(5)
        sim = api.wrap(Crowd(cfg))
        got = []
        sim.on_event("step", lambda n, f, ids: got.append(f))
        sim.advance_to(20)
        assert got and not [m for m in sys.modules if m.startswith("crowd_addon.blender")]
        try:
            crowd_addon.register()
        except ImportError:
            print("ok")
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr[-2000:]
