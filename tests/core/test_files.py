"""``core.files.folders_made``: an output folder a command creates is gone again when
the command fails, and folders that were there are never touched. ``write_atomic``:
a file is replaced whole or not at all."""

import os

import pytest

from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.base.files import (folders_made, remove_stale_staging, staging,
                                         write_atomic)


def test_the_folders_stay_when_the_block_succeeds(tmp_path):
    with folders_made(tmp_path / "a" / "b") as folder:
        (folder / "shot.usdc").write_bytes(b"x")
    assert (tmp_path / "a" / "b" / "shot.usdc").is_file()


def test_a_failing_block_removes_only_the_folders_it_made(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "keep.txt").write_text("mine")
    with pytest.raises(KeyError):
        with folders_made(tmp_path / "a" / "b" / "c") as folder:
            assert folder.is_dir()
            raise KeyError("the export failed")
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["keep.txt"]


def test_an_existing_folder_is_left_alone_on_failure(tmp_path):
    with pytest.raises(CrowdError):
        with folders_made(tmp_path):
            raise CrowdError("bad input")
    assert tmp_path.is_dir()


def test_a_folder_under_a_file_is_a_named_error(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(CrowdError, match=r"output folder .*file/sub: cannot create it"):
        with folders_made(tmp_path / "file" / "sub"):
            pass
    assert [p.name for p in tmp_path.iterdir()] == ["file"]


def test_write_atomic_replaces_the_file_whole_keeping_its_permissions(tmp_path):
    path = tmp_path / "summary.json"
    path.write_bytes(b"old")
    os.chmod(path, 0o640)
    write_atomic(path, lambda f: f.write(b"new"), "the summary")
    assert path.read_bytes() == b"new"
    assert os.stat(path).st_mode & 0o777 == 0o640
    assert os.listdir(tmp_path) == ["summary.json"]


@pytest.mark.parametrize("sync", [True, False])
def test_write_atomic_that_fails_part_way_leaves_the_old_file_and_no_temporary(tmp_path,
                                                                               sync):
    path = tmp_path / "summary.json"
    path.write_bytes(b"old")

    def half_then_full_disk(f):
        f.write(b"half")
        raise OSError(28, "No space left on device")
    with pytest.raises(CrowdError, match=r"summary.json: cannot write the summary: No "
                                         r"space left on device"):
        write_atomic(path, half_then_full_disk, "the summary", sync=sync)
    assert path.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["summary.json"]


def test_write_atomic_into_a_missing_folder_is_a_named_error(tmp_path):
    with pytest.raises(CrowdError, match=r"gone/x.png: cannot write the PNG"):
        write_atomic(tmp_path / "gone" / "x.png", lambda f: f.write(b"x"), "the PNG")
    assert os.listdir(tmp_path) == []


def test_stale_staging_of_a_gone_process_is_removed_a_live_ones_and_others_kept(tmp_path):
    """A run killed outright leaves its staging; the next run removes it, but never a
    live run's (here: this process's and its parent's), another host's or a file not
    named so."""
    import subprocess
    import sys
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    mine = staging(tmp_path, "frames.partial")
    host = mine.name[len(".frames.partial-"):].rsplit("-", 1)[0]
    dead = tmp_path / f".frames.partial-{host}-{gone}"
    for d in (mine, dead, tmp_path / f".frames.partial-{host}-{os.getppid()}",
              tmp_path / f".frames.partial-otherhost-{gone}", tmp_path / "frames.partial-1"):
        d.mkdir()
        (d / "frame_0000.png").write_bytes(b"x")
    (tmp_path / f".stadium.partial-{host}-{gone}.blend").write_bytes(b"x")
    remove_stale_staging(tmp_path, "frames.partial")
    remove_stale_staging(tmp_path, "stadium.partial", ".blend")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [mine.name, f".frames.partial-{host}-{os.getppid()}", f".frames.partial-otherhost-{gone}",
         "frames.partial-1"])
