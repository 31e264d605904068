"""Benchmarks with their own parsers (`facecast bench latency ...`) report a user's mistake in one line."""

from __future__ import annotations

from facecast.cli import main


def test_a_forwarded_benchmark_names_a_missing_model_in_one_line(tmp_path, capsys):
    # `facecast bench latency --model missing.npz` printed a ModelFileError traceback.
    missing = tmp_path / "missing.npz"
    assert main(["bench", "latency", "--model", str(missing), "--seconds", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"facecast bench: error: {missing}: model file not found (nor a shipped name: default, low-latency)"]
