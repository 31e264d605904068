"""`facecast bench adapt`'s s1-as-a-new-voice measurement on a small GRID copy (real clips, MediaPipe)."""

from __future__ import annotations

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.system]  # MediaPipe on a real GRID clip


def test_s1_as_a_new_voice_measures_only_the_lips_it_scores(grid_copy, tmp_path, monkeypatch) -> None:
    """Enrolment is audio only: of three train and two val sentences, with --val-sentences 1 only that one val
    clip's lips are measured (one face track in an empty cache). The whole train split went through MediaPipe
    (716 clips on an empty cache, ~1 s each) for the audio of the first 16."""
    from assets.modelfile import load_model
    from benchmarks.adaptation import s1_as_new_voice

    cache = tmp_path / "cache"
    monkeypatch.setenv("FACECAST_CACHE", str(cache))
    root = grid_copy(["bbaf2n", "bbaf4p", "bbal6n", "bbaf5a", "bbal8p"])  # train x3, then val x2
    rows = s1_as_new_voice(
        load_model(), [8.0], root, enrol_seconds=4.0, n_val=1, progress=lambda it, **_: it, speed=1.2
    )
    assert len(list(cache.rglob("*.npz"))) == 1
    (row,) = rows
    # two 3 s sentences played x1.2 reach 4 s: 5.0 s of enrolment from two files; one val clip of ~75 frames
    assert row["enrol_files"] == 2 and 4.0 <= row["enrol_seconds"] < 6.0
    assert 60 <= row["frames"] <= 90 and -1 <= row["after"] <= 1
