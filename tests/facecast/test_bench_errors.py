"""Benchmarks with their own parsers (`facecast bench latency ...`) report a user's mistake in one line."""

from __future__ import annotations

from facecast.cli import main


def test_a_forwarded_benchmark_names_a_missing_model_in_one_line(tmp_path, capsys):
    # `facecast bench latency --model missing.npz` printed a ModelFileError traceback.
    missing = tmp_path / "missing.npz"
    assert main(["bench", "latency", "--model", str(missing), "--seconds", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"facecast bench: error: {missing}: model file not found (nor a shipped name: default, low-latency)"]


def test_bench_adapt_names_a_missing_or_empty_clips_folder_before_any_work(tmp_path, capsys):
    # `facecast bench adapt --clips missing` ended in a FileNotFoundError traceback; a missing --grid-s1 was refused
    # only after the other talkers had been measured (MediaPipe on each clip). Each is one line, exit 2, up front.
    missing = tmp_path / "missing"
    assert main(["bench", "adapt", "--clips", str(missing), "--no-s1"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"facecast bench: error: --clips {missing}: folder not found"
    ]
    (tmp_path / "notes.txt").write_text("no clips here\n")
    assert main(["bench", "adapt", "--clips", str(tmp_path), "--no-s1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"facecast bench: error: --clips {tmp_path}: no talking-face clips there (.mpg or .mp4)"], err
    (tmp_path / "clip.mp4").write_bytes(b"")  # a clip is there: the missing GRID s1 folder is named before it is read
    assert main(["bench", "adapt", "--clips", str(tmp_path), "--grid-s1", str(missing)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"facecast bench: error: {missing}: no GRID s1 sentences"), err
