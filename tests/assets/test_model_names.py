"""Shipped models by name: `--model low-latency` resolves in one place and loads everywhere."""

from __future__ import annotations

import numpy as np
import pytest

from assets.modelfile import (
    DEFAULT_MODEL,
    LOW_LATENCY_MODEL,
    ModelFileError,
    load_model,
    resolve_model,
)
from facecast.cli import main
from tests.speech import speechlike

pytestmark = pytest.mark.slow  # loads and runs the shipped models


def test_names_resolve_to_the_shipped_files_and_paths_stay_paths(tmp_path):
    assert resolve_model(None) == DEFAULT_MODEL
    assert resolve_model("default") == DEFAULT_MODEL
    assert resolve_model("low-latency") == LOW_LATENCY_MODEL
    assert resolve_model(tmp_path / "m.npz") == tmp_path / "m.npz"
    assert resolve_model("./low-latency").name == "low-latency"  # a file of that name, written as a path
    with pytest.raises(ModelFileError, match="low-latencyy: model file not found"):
        load_model("low-latencyy")
    # a mistyped name says which names there are (it read as a missing file only)
    with pytest.raises(
        ModelFileError, match=r"low_latency: model file not found \(nor a shipped name: default, low-latency\)"
    ):
        load_model("low_latency")


def test_a_shipped_hmm_name_given_to_the_mlp_mapper_is_named_as_such():
    # `--mapper mlp --model low-latency` said "model file not found (nor a shipped name: default, low-latency)".
    from assets.modelfile import load_speech_model

    for name in ("low-latency", "default"):
        with pytest.raises(ModelFileError, match=r"this is an HMM model .* use --mapper hmm"):
            load_speech_model("mlp", name)


def test_low_latency_model_loads_is_under_80_ms_and_differs_from_the_default():
    low, default = load_model("low-latency"), load_model("default")
    assert low.algorithmic_delay_ms() <= 80.0 < default.algorithmic_delay_ms()
    assert default.algorithmic_delay_ms() == pytest.approx(166.6875)
    assert low.metadata["recipe"]["tc"] == low.frontend.tc == 1
    assert low.closure_band > 0 and low.metadata["grid_s1"]["split"] == "train"


def test_animate_and_eval_accept_the_name(tmp_path, capsys):
    from assets.audio import write_wav
    from assets.tracks import decode_csv

    wav = tmp_path / "s.wav"
    write_wav(wav, speechlike(1.0, 16000), 16000)
    outs = {}
    for name in ("low-latency", "default"):
        outs[name] = tmp_path / f"{name}.csv"
        assert main(["animate", str(wav), "--model", name, "--csv", str(outs[name])]) == 0
    assert "algorithmic delay 78.3 ms" in capsys.readouterr().out
    low, default = (decode_csv(outs[n].read_bytes()).values for n in ("low-latency", "default"))
    assert low.shape == default.shape == (30, 4) and not np.allclose(low, default)
