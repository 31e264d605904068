"""`facecast eval --video-dir DIR`: the section is named after what DIR is, and measuring its clips shows progress."""

from __future__ import annotations

import shutil

import pytest

from realtime_core import VISUAL_PARAMS

# Real GRID clips, ffmpeg and MediaPipe.
pytestmark = pytest.mark.system


@pytest.mark.skipif(__import__("importlib").util.find_spec("mediapipe") is None, reason="mediapipe not installed")
def test_clips_section_is_titled_by_its_folder_with_progress(shared_data, tmp_path, ffmpeg, capsys, monkeypatch):
    import facecast.commands.eval as eval_command
    from assets.modelfile import load_model
    from assets.progress import Progress
    from training.errors import ConfigError

    folder = tmp_path / "my clips"
    folder.mkdir()
    shutil.copy(shared_data / "video" / "grid" / "lbax4n.mpg", folder)
    model = load_model(None)
    md, scores = eval_command.clips_section(
        model, folder, cache_dir=tmp_path / "cache", plot_dir=tmp_path, stem="acc", progress=Progress
    )
    assert md.startswith(f"## 2. Real lips: clips in {folder}\n") and "other talkers" not in md
    assert f"1 clips from {folder}/" in md and all(f"| {p} |" in md for p in VISUAL_PARAMS)
    assert (tmp_path / "acc_clips_my_clips.png").is_file() and "acc_clips_my_clips.png" in md
    assert len(scores.per_clip) == 1
    err = capsys.readouterr().err
    assert f"clips in {folder}" in err and "1/1" in err  # tqdm's bar over the clips, as `facecast extract` shows

    # The default folder (GRID's other talkers) keeps its title (here: the same clip, its track from the cache).
    monkeypatch.setattr(eval_command, "OTHER_TALKERS", folder)
    md, _ = eval_command.clips_section(model, folder, cache_dir=tmp_path / "cache")
    assert md.startswith("## 2. Real lips: other talkers (never used for any choice)\n")

    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no clips here\n")
    with pytest.raises(ConfigError, match="no talking-face clips"):
        eval_command.clips_section(model, empty)


@pytest.mark.skipif(__import__("importlib").util.find_spec("mediapipe") is None, reason="mediapipe not installed")
def test_video_dir_scores_only_its_clips(shared_data, tmp_path, ffmpeg, capsys):
    """`eval --video-dir DIR` for a user's own clips also built the synthetic corpus (espeak, 80 utterances) and scored
    GRID s1's 90 test sentences and the shared speech besides: 3 clips took 90 s on a first run. Now the clips alone
    (their extraction and scoring with progress), the other sections only when named."""
    from facecast.cli import main

    folder = tmp_path / "mine"
    folder.mkdir()
    shutil.copy(shared_data / "video" / "grid" / "lbax4n.mpg", folder)
    assert (shared_data / "video" / "grid_s1").is_dir()  # the default s1 section would have run
    capsys.readouterr()
    assert main(["eval", "--video-dir", str(folder), "--cache-dir", str(tmp_path / "cache")]) == 0
    out, err = capsys.readouterr()
    headings = [line for line in out.splitlines() if line.startswith("## ")]
    assert headings == [f"## 2. Real lips: clips in {folder}"], headings
    assert "GRID s1" not in err and "skipping" not in err  # nothing else measured, nothing said to be skipped
    assert f"clips in {folder}" in err and "scoring" in err and "1/1" in err  # extraction, then scoring, with progress
    assert f"Produced by `facecast eval --video-dir {folder}`" in out
