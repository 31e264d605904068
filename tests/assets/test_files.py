"""Atomic writes where the file system refuses: one error naming the output, nothing left behind."""

from __future__ import annotations

import pytest

from assets.errors import CannotWriteError
from assets.files import atomic_write_bytes


def test_a_parent_that_is_a_file_is_named(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    out = tmp_path / "notes.txt" / "deeper" / "take.csv"
    with pytest.raises(CannotWriteError, match=r"take\.csv: cannot write here: .*notes\.txt is a file, not a folder"):
        atomic_write_bytes(out, b"t\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_a_name_that_is_a_folder_leaves_no_temporary_file(tmp_path):
    (tmp_path / "take.csv").mkdir()
    with pytest.raises(CannotWriteError, match=r"take\.csv: cannot write here"):
        atomic_write_bytes(tmp_path / "take.csv", b"t\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take.csv"] and not any((tmp_path / "take.csv").iterdir())


def test_an_output_folder_is_made_or_refused_by_name(tmp_path):
    """`mu -o DIR`, `corpus DIR`, `perceptual build -o DIR`: the folder made with its parents and written to, or one
    line naming it (`mu -o /proc/d` was a FileNotFoundError traceback)."""
    from assets.files import check_writable_folder

    made = check_writable_folder(tmp_path / "a" / "b")
    assert made.is_dir() and list(made.iterdir()) == []  # the probe file removed
    assert check_writable_folder(made) == made  # an existing folder is fine
    (tmp_path / "notes.txt").write_text("hello")
    for folder in (tmp_path / "notes.txt", tmp_path / "notes.txt" / "d"):
        with pytest.raises(CannotWriteError, match=r"cannot write here: .*notes\.txt is a file, not a folder"):
            check_writable_folder(folder)
    with pytest.raises(CannotWriteError, match=r"^/proc/d: cannot write here: folder /proc/d is missing and cannot be"):
        check_writable_folder("/proc/d")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "notes.txt"]
