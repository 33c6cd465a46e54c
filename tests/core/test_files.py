"""``core.files.folders_made``: an output folder a command creates is gone again when
the command fails, and folders that were there are never touched."""

import pytest

from crowd_addon.core.base.errors import CrowdError
from crowd_addon.core.base.files import folders_made


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
