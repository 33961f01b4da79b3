"""storage.folders: a folder replaced whole loses nothing that is not the writer's own, even when a file is put
there while the new folder is built or the swap fails."""

from __future__ import annotations

import os

import pytest

from storage import folders
from storage.folders import NotReplaceable, only_files, replaced_directory

OURS = only_files(lambda name: name.startswith("part-"))


def test_a_file_put_there_while_the_output_is_built_is_kept(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / "part-0").write_text("old")
    with pytest.raises(NotReplaceable, match="thesis.txt"):
        with replaced_directory(target, OURS, "parts") as stage:
            (stage / "part-0").write_text("new")
            (target / "thesis.txt").write_text("keep")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert (target / "thesis.txt").read_text() == "keep" and (target / "part-0").read_text() == "old"


def test_a_failed_swap_puts_the_old_folder_back(tmp_path, monkeypatch):
    target = tmp_path / "out"
    target.mkdir()
    (target / "part-0").write_text("old")
    replace = os.replace

    def failing(src, dst):
        if str(src).endswith(".tmp"):  # the stage into place: the disk is gone
            raise OSError(5, "Input/output error")
        replace(src, dst)

    monkeypatch.setattr(folders.os, "replace", failing)
    with pytest.raises(OSError, match="Input/output"):
        with replaced_directory(target, OURS, "parts") as stage:
            (stage / "part-0").write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"] and (target / "part-0").read_text() == "old"


def test_a_link_inside_is_never_the_writer_s(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / "part-0").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(NotReplaceable, match="part-0"):
        with replaced_directory(target, OURS, "parts"):
            pass
