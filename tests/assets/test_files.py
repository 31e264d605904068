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
