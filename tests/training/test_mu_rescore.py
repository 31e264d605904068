"""`facecast eval --mu OUT` re-scores the models `facecast mu -o OUT` wrote on the sentences that run used."""

from __future__ import annotations

import json
import re

import pytest

from tests.prerequisites import require_module

pytestmark = [pytest.mark.slow, pytest.mark.system]  # MediaPipe on real GRID video, MLP training

# Sorted by name, the first 8 hold 6 train, 1 val and 1 test sentence (assets.grid.split_of); the last two
# are test sentences a `--limit 8` run never saw.
SENTENCES = ("bbaf2n", "bbaf3s", "bbaf4p", "bbaf5a", "bbal6n", "bbal7s", "bbal9a", "bbas1s", "bbas2p", "bbaz4n")


def test_eval_mu_rescores_the_sentences_the_run_used(grid_copy, tmp_path, capsys) -> None:
    # `eval --mu` of a `mu --limit N` run measured the faces of every sentence in the corpus (900, ~1.3 s
    # each) and scored the models on test sentences the run's report never saw.
    require_module("mediapipe", "optional extra: pip install 'facecast[video]'")
    from assets.grid import split_of
    from facecast.cli import main

    root = grid_copy(SENTENCES)
    assert [split_of(s) for s in SENTENCES[8:]] == ["test", "test"]
    out = tmp_path / "mu"
    argv = ["mu", "--root", str(root), "-o", str(out), "--limit", "8", "--classes", "4"]
    assert main([*argv, "--hmm-states", "0", "--baseline-hidden", "0"]) == 0
    test_r = json.loads((out / "report.json").read_text())["test"]["mlp"]["R"]
    capsys.readouterr()
    assert main(["eval", "--mu", str(out), "--grid-s1", str(root)]) == 0
    got = re.search(r"mlp: train R [0-9.]+, test R ([0-9.]+)", capsys.readouterr().out)
    assert got is not None and float(got.group(1)) == pytest.approx(test_r, abs=1e-4)
