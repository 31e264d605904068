"""The shared data folder: one rule for commands, benchmarks, scripts and tests."""

from __future__ import annotations

from pathlib import Path

from assets.grid import default_root
from assets.shared import ENV, shared_data_root


def test_the_environment_variable_names_the_folder(monkeypatch, tmp_path):
    monkeypatch.setenv(ENV, str(tmp_path))
    assert shared_data_root() == tmp_path
    assert default_root() == tmp_path / "video" / "grid_s1"


def test_unset_or_empty_it_is_shared_data_beside_the_checkout(monkeypatch):
    beside = Path(__file__).resolve().parents[2].parent / "shared" / "data"
    monkeypatch.delenv(ENV, raising=False)
    assert shared_data_root() == beside
    monkeypatch.setenv(ENV, "")
    assert shared_data_root() == beside
