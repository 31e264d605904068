"""facecast train / animate on a real (small) espeak corpus: the model loads, beats the
loudness baseline on held-out voices, and `animate` equals the live streaming path."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from assets.audio import read_wav
from assets.modelfile import load_model
from facecast.cli import main
from realtime_core.features import loudness_db
from realtime_core.features.resample import resample_audio
from realtime_core.pipeline import SpeechToParams
from training.build_corpus import BuildConfig, VoiceSampling, build_corpus
from training.corpus import load_corpus
from training.evaluation import MOUTH_OPEN, pearson

# Builds a corpus and trains a model.
pytestmark = [pytest.mark.system, pytest.mark.slow]


@pytest.fixture(scope="module")
def corpora(tmp_path_factory, espeak):
    """English only: training voices without the f5/m7 variants; held-out voices f5/m7 only."""
    root = tmp_path_factory.mktemp("corpora")
    train = root / "train"
    held = root / "held"
    build_corpus(
        BuildConfig(
            out_dir=train,
            sentences=60,
            languages=("en",),
            seed=1,
            voices=VoiceSampling(variants=(None, "m1", "m3", "f2", "f4")),
        )
    )
    build_corpus(
        BuildConfig(out_dir=held, sentences=10, languages=("en",), seed=2, voices=VoiceSampling(variants=("f5", "m7")))
    )
    return train, held


@pytest.fixture(scope="module")
def model_path(corpora, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("model") / "m.npz"
    assert main(["train", str(corpora[0]), "-o", str(out), "--states", "6", "--mix", "2", "--iters", "8"]) == 0
    return out


def test_trained_model_loads_and_beats_loudness_on_held_out_voices(model_path, corpora):
    """Held-out espeak voices: r(mouth_open) of the model must exceed the loudness
    baseline's by at least 0.05 (pooled over the utterances)."""
    from realtime_core.pipeline import speech_to_params

    model = load_model(model_path)
    assert model.metadata["recipe"]["n_states"] == 6
    assert not model_path.with_name(model_path.name + ".checkpoint.npz").exists()
    truth, est, loud = [], [], []
    for u in load_corpus(corpora[1]):
        e = speech_to_params(model, resample_audio(u.samples, u.sample_rate_hz, model.sample_rate_hz))
        T = min(len(e), len(u.params))
        truth.append(u.params[:T, MOUTH_OPEN])
        est.append(e[:T, MOUTH_OPEN])
        loud.append(loudness_db(u.samples, u.sample_rate_hz, T))
    r_model = pearson(np.concatenate(truth), np.concatenate(est))
    r_loud = pearson(np.concatenate(truth), np.concatenate(loud))
    assert r_model > r_loud + 0.05, (r_model, r_loud)


def test_animate_equals_the_live_streaming_path(model_path, corpora, tmp_path):
    wav = sorted(Path(corpora[1]).glob("*/audio.wav"))[0]
    out = tmp_path / "p.csv"
    assert main(["animate", str(wav), "--csv", str(out), "--model", str(model_path)]) == 0
    with out.open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "upper_lip_raise", "lip_stretch", "mouth_open", "lip_corner_depress"]
    table = np.array(rows[1:], dtype=float)
    np.testing.assert_allclose(table[:, 0], np.arange(len(table)) / 30.0, atol=1e-6)
    # The live path: the same model fed 10 ms blocks as a microphone would deliver them.
    model = load_model(model_path)
    samples, rate = read_wav(wav)
    x = resample_audio(samples, rate, model.sample_rate_hz)
    live = SpeechToParams(model)
    blocks = [live.push(x[i : i + 160]) for i in range(0, len(x), 160)] + [live.flush()]
    np.testing.assert_allclose(table[:, 1:], np.concatenate(blocks), atol=2e-6)  # CSV has 6 decimals


def test_train_resumes_from_its_checkpoint(corpora, tmp_path, capsys):
    out = tmp_path / "r.npz"
    assert main(["train", str(corpora[0]), "-o", str(out), "--states", "3", "--mix", "1", "--iters", "1"]) == 0
    # A checkpoint left by an interrupted run with the same recipe is picked up.
    out.rename(out.with_name(out.name + ".checkpoint.npz"))
    assert main(["train", str(corpora[0]), "-o", str(out), "--states", "3", "--mix", "1", "--iters", "2"]) == 0
    assert "resuming" in capsys.readouterr().out
    assert load_model(out).hmm.n_states == 3


def test_train_logs_its_progress_in_whole_lines_with_each_counts_own_objective(corpora, tmp_path, capsys):
    """`facecast train ... 2> log`: the bar's postfix (the objective) forced a line per Baum-Welch iteration
    whatever the log interval (4 iterations: 5 lines in under a second), each showing the objective of the
    iteration after its count. Now a run this short logs the bar's start and its final count, with that
    iteration's objective (the model's own history)."""
    out = tmp_path / "p.npz"
    assert main(["train", str(corpora[0]), "-o", str(out), "--states", "3", "--mix", "1", "--iters", "4"]) == 0
    bars = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("Baum-Welch:")]
    history = load_model(out).metadata["em_history"]
    assert len(history) == 5  # the starting model, then one per iteration
    assert len(bars) == 2 and "0/4" in bars[0] and "4/4" in bars[1], bars
    assert bars[1].endswith(f"objective={history[-1]:.4f}]"), (bars, history)


def test_continued_training_equals_an_uninterrupted_run(corpora, tmp_path):
    """A finished file renamed to the checkpoint continues to more --iters and ends where one run of
    that many iterations ends: the same HMM to the last bit and the same objective history (how the
    default model's 20 iterations were continued from its 12; docs/default_model.md)."""
    base = [str(corpora[0]), "--states", "3", "--mix", "2", "--iters"]
    whole, part = tmp_path / "whole.npz", tmp_path / "part.npz"
    assert main(["train", *base, "3", "-o", str(whole)]) == 0
    assert main(["train", *base, "1", "-o", str(part)]) == 0
    assert load_model(part).metadata["iteration"] == 1
    part.rename(part.with_name(part.name + ".checkpoint.npz"))
    assert main(["train", *base, "3", "-o", str(part)]) == 0
    a, b = load_model(whole), load_model(part)
    for name in ("startprob", "transmat", "weights", "means", "covars"):
        np.testing.assert_array_equal(getattr(b.hmm, name), getattr(a.hmm, name), err_msg=name)
    np.testing.assert_array_equal(b.cmvn_mean, a.cmvn_mean)
    assert len(a.metadata["em_history"]) == 4
    assert b.metadata["em_history"] == a.metadata["em_history"]
    assert b.metadata["iteration"] == a.metadata["iteration"] == 3


def test_level_normalised_model_animates_a_quieter_recording_identically(corpora, tmp_path):
    """`facecast train --level-norm`: the model stores the level config, and its live path gives the same
    mouth for a held-out voice played 9 dB quieter (the whole chain, inverter included, is gain-invariant)."""
    from realtime_core.pipeline import speech_to_params

    out = tmp_path / "lvl.npz"
    args = ["train", str(corpora[0]), "-o", str(out), "--states", "4", "--mix", "1", "--iters", "2", "--level-norm"]
    assert main(args) == 0
    model = load_model(out)
    assert model.frontend.level_norm is not None and model.metadata["recipe"]["level_norm"]
    u = load_corpus(corpora[1])[0]
    x = resample_audio(u.samples, u.sample_rate_hz, model.sample_rate_hz).astype(np.float64)
    x = x + 3e-3 * np.random.default_rng(0).standard_normal(x.size)  # no mel band at the energy floor
    loud = speech_to_params(model, x, model.sample_rate_hz)
    quiet = speech_to_params(model, x * 10 ** (-9 / 20), model.sample_rate_hz)
    np.testing.assert_allclose(quiet, loud, atol=1e-6)
    assert loud[:, MOUTH_OPEN].std() > 0.0  # it does move


def test_bad_files_give_one_line_errors_naming_the_file(tmp_path, capsys, model_path):
    junk = tmp_path / "junk.wav"
    junk.write_bytes(b"this is not audio at all")
    assert main(["animate", str(junk), "--csv", str(tmp_path / "o.csv"), "--model", str(model_path)]) == 2
    err = capsys.readouterr().err
    assert str(junk) in err and "Traceback" not in err
    bad_model = tmp_path / "bad.npz"
    bad_model.write_bytes(b"PK\x03\x04 truncated")
    assert main(["animate", str(junk), "--csv", str(tmp_path / "o.csv"), "--model", str(bad_model)]) == 2
    assert str(bad_model) in capsys.readouterr().err
    assert main(["train", str(tmp_path), "-o", str(tmp_path / "m.npz")]) == 2
    assert "manifest.json" in capsys.readouterr().err
