"""The extension zip builds with Blender's own tool and installs into the bpy module.

Oracle: Blender's extension machinery (``blender_ext.py build`` validates the manifest
and wheels; ``bpy.ops.extensions.package_install_files`` installs and enables it).
Runs in a subprocess with Blender's user directories in a temporary folder, so the
machine's own Blender configuration is never touched.
"""

import json
import os
import subprocess
import sys
import textwrap
import zipfile

import pytest

from crowd_addon import packaging

pytest.importorskip("bpy", reason="the bpy module is needed to build the extension")


@pytest.fixture(scope="module")
def extension_zip(tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    return packaging.build_extension(out, progress=lambda *_: None)[0]


def test_zip_carries_sources_shaders_and_wheels_for_every_platform(extension_zip):
    names = zipfile.ZipFile(extension_zip).namelist()
    assert "blender_manifest.toml" in names and "__init__.py" in names
    assert "crowd_addon/core/shots/crowd.py" in names
    assert not any(n.startswith(("tests/", "benchmarks/", ".venv/")) for n in names)
    wheels = [n for n in names if n.startswith("wheels/")]
    for py in ("cp311", "cp313"):
        for plat in ("manylinux", "win_amd64", "macosx_11_0_arm64"):
            for pkg in ("moderngl-", "glcontext-"):
                assert any(pkg in w and py in w and plat in w for w in wheels), (pkg, py, plat)
    manifest = zipfile.ZipFile(extension_zip).read("blender_manifest.toml").decode()
    assert 'platforms = ["linux-x64", "windows-x64", "macos-arm64"]' in manifest


def test_manifest_must_not_list_wheels_itself():
    with pytest.raises(Exception, match="leave 'wheels'"):
        packaging._manifest_with_wheels('wheels = ["x.whl"]\n', [])


INSTALL = textwrap.dedent("""
    import json, sys
    import bpy
    zip_path = sys.argv[1]
    result = bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True)
    name = "bl_ext.user_default.crowd_animation"
    mod = sys.modules.get(name)
    print(json.dumps({"result": sorted(result), "enabled": name in bpy.context.preferences.addons,
                      "file": getattr(mod, "__file__", None)}))
""")


def test_installs_and_enables_in_blender(extension_zip, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    run = subprocess.run([sys.executable, "-c", INSTALL, extension_zip], env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    info = json.loads(run.stdout.strip().splitlines()[-1])
    assert info["result"] == ["FINISHED"] and info["enabled"]
    assert info["file"].startswith(str(tmp_path / "blender_user"))


def test_out_naming_an_existing_file_is_refused(tmp_path):
    """Regression: `crowd build-extension --out FILE` ended in a raw traceback."""
    target = tmp_path / "dist"
    target.write_text("mine")
    run = subprocess.run([sys.executable, "-m", "crowd_addon", "build-extension", "--out",
                          str(target)], capture_output=True, text=True, timeout=300,
                         cwd=os.path.dirname(os.path.dirname(os.path.dirname(
                             os.path.abspath(__file__)))))
    assert run.returncode == 2, run.stderr[-2000:]
    assert "exists and is not a folder" in run.stderr and "Traceback" not in run.stderr
    assert target.read_text() == "mine"


def test_wheels_folder_builds_without_network(extension_zip, tmp_path, monkeypatch):
    """--wheels DIR: the wheels come from the folder alone (pip is never run), and a
    folder missing one names the wheel, platform and Python."""
    import shutil
    import zipfile

    from crowd_addon.core.base.errors import CrowdError

    cache = os.path.join(packaging.REPO_ROOT, "build", "wheels")   # filled by extension_zip
    local = tmp_path / "wheels"
    shutil.copytree(cache, local)
    real_run = subprocess.run

    def no_pip(cmd, *a, **kw):
        assert "pip" not in cmd, "a --wheels build must not download"
        return real_run(cmd, *a, **kw)
    monkeypatch.setattr(packaging.subprocess, "run", no_pip)
    (built,) = packaging.build_extension(tmp_path / "dist", wheel_cache=str(local),
                                         offline=True, progress=lambda *_: None)
    with zipfile.ZipFile(built) as z, zipfile.ZipFile(extension_zip) as ref:
        assert sorted(n for n in z.namelist() if n.startswith("wheels/")) == \
            sorted(n for n in ref.namelist() if n.startswith("wheels/"))
    for w in local.glob("moderngl-*cp313*win_amd64.whl"):
        w.unlink()
    with pytest.raises(CrowdError, match=r"no moderngl==5\.13\.0 wheel for windows-x64 / "
                                         r"Python 3\.13"):
        packaging.build_extension(tmp_path / "dist2", wheel_cache=str(local), offline=True,
                                  progress=lambda *_: None)


def test_a_failed_build_leaves_no_output_folder_it_made(tmp_path):
    """Regression: `crowd build-extension --out newdist --wheels /nonexistent` named the
    missing folder but left an empty newdist/ (and its missing parents) behind."""
    from crowd_addon.core.base.errors import CrowdError

    with pytest.raises(CrowdError, match="no such folder"):
        packaging.build_extension(tmp_path / "new" / "dist", wheel_cache=str(tmp_path / "no"),
                                  offline=True, progress=lambda *_: None)
    assert os.listdir(tmp_path) == []


def test_a_full_disk_keeps_the_earlier_zip_and_leaves_no_temporary(extension_zip, tmp_path,
                                                                   monkeypatch):
    """Regression: a full disk while the zip was copied out raised a raw OSError (exit 1,
    a traceback) and left a partial crowd_animation-0.1.0.zip.tmp beside the zip."""
    import shutil

    from crowd_addon.core.base.errors import CrowdError

    out = tmp_path / "dist"
    out.mkdir()
    earlier = out / os.path.basename(extension_zip)
    earlier.write_bytes(b"the earlier zip")
    real_copy = shutil.copyfileobj

    def full_disk_for_zips(src, dst, *a):
        if not str(getattr(src, "name", "")).endswith(".zip"):
            return real_copy(src, dst, *a)
        dst.write(src.read(65536))
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(shutil, "copyfileobj", full_disk_for_zips)
    cache = os.path.join(packaging.REPO_ROOT, "build", "wheels")   # filled by extension_zip
    with pytest.raises(CrowdError, match=rf"{earlier.name}: cannot write the extension zip: "
                                         r"No space left on device"):
        packaging.build_extension(out, wheel_cache=cache, offline=True,
                                  progress=lambda *_: None)
    assert os.listdir(out) == [earlier.name]
    assert earlier.read_bytes() == b"the earlier zip"
