"""Text + recording: the audio-driven model's motion mixed into unit-selection output."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from realtime_core import VISUAL_PARAMS
from realtime_core.errors import ConfigError
from realtime_core.synthesis.corpus import FPS, MotionCorpus
from realtime_core.synthesis.recording import (
    RecordingBlend,
    blend_recording,
    param_to_coefficient_map,
    region_weights,
)
from realtime_core.synthesis.synthesizer import UnitSynthesizer
from realtime_core.synthesis.visemes import VISEME_ID
from tests.realtime_core.synthesis.test_units import tiny_corpus

K = 3


def linear_corpus(rng: np.random.Generator) -> tuple[MotionCorpus, np.ndarray]:
    """A tiny corpus whose K coefficients are an exact linear function of its four parameters:
    (corpus, the (4, K) slopes)."""
    sents = [["sil", "PBM", "AA", "IY", "sil"], ["sil", "FV", "AA", "PBM", "sil"], ["sil", "PBM", "IY", "AA", "sil"]]
    base = tiny_corpus(rng, sents, d=4)  # 5 smooth channels; the first 4 become the parameters
    params = np.asarray(base.frames)[:, :4]
    slopes = rng.normal(size=(4, K))
    coeffs = params @ slopes + rng.normal(size=K)
    corpus = dataclasses.replace(
        base,
        frames=np.concatenate([coeffs, params], axis=1),
        n_coefficients=K,
        dim_names=(*(f"pc{k}" for k in range(K)), *VISUAL_PARAMS),
    )
    return corpus, slopes


def test_the_map_recovers_the_corpus_linear_relation_from_parameters_to_coefficients():
    corpus, slopes = linear_corpus(np.random.default_rng(0))
    np.testing.assert_allclose(param_to_coefficient_map(corpus), slopes, atol=1e-8)
    other = dataclasses.replace(corpus, dim_names=(*corpus.dim_names[:-1], "jaw"))
    with pytest.raises(ConfigError):
        param_to_coefficient_map(other)


def test_region_weights_follow_the_pauses_and_speech():
    sil, aa = VISEME_ID["sil"], VISEME_ID["AA"]
    vis = np.array([sil, aa, sil, aa, sil])  # an inner pause belongs to speech
    starts = np.array([0.0, 0.5, 0.8, 0.9, 1.5])
    ends = np.array([0.5, 0.8, 0.9, 1.5, 2.0])
    cfg = RecordingBlend(lead=0.9, speech=0.2, trail=0.5, ramp_s=0.0)
    w = region_weights(vis, starts, ends, 60, cfg)
    t = np.arange(60) / FPS
    np.testing.assert_array_equal(w, np.where(t < 0.5, 0.9, np.where(t < 1.5, 0.2, 0.5)))
    smooth = region_weights(vis, starts, ends, 60, dataclasses.replace(cfg, ramp_s=0.2))
    far = (np.abs(t - 0.5) > 0.11) & (np.abs(t - 1.5) > 0.11)
    np.testing.assert_allclose(smooth[far], w[far])  # only the boundaries are smoothed
    assert np.all(np.diff(smooth[t < 1.0]) <= 1e-12) and np.all(np.diff(smooth[t > 1.0]) >= -1e-12)
    assert 0.2 < smooth[15] < 0.9  # the frame at the onset lies between the two weights
    pause_only = region_weights(np.array([sil]), np.array([0.0]), np.array([1.0]), 30, cfg)
    np.testing.assert_array_equal(pause_only, 0.9)


def test_blend_moves_parameters_by_the_weight_and_coefficients_with_them():
    rng = np.random.default_rng(1)
    n = 20
    frames = rng.normal(size=(n, K + 4))
    audio = rng.normal(size=(n - 5, 4))  # shorter than the motion: its last frame is held
    cmap = rng.normal(size=(4, K))
    w = np.linspace(0.0, 1.0, n)
    out = blend_recording(frames, audio, w, cmap)
    held = np.concatenate([audio, np.repeat(audio[-1:], 5, axis=0)])
    expect_p = (1 - w[:, None]) * frames[:, K:] + w[:, None] * held
    np.testing.assert_allclose(out[:, K:], expect_p)
    np.testing.assert_allclose(out[:, :K] - frames[:, :K], (expect_p - frames[:, K:]) @ cmap)
    np.testing.assert_array_equal(out[0], frames[0])  # weight 0: unit selection unchanged
    with pytest.raises(ConfigError):
        blend_recording(frames, audio[:, :3], w, cmap)
    with pytest.raises(ConfigError):
        blend_recording(frames, audio, w[:-1], cmap)


def test_with_recording_takes_the_recording_in_the_leading_pause_and_keeps_the_text_output():
    corpus, slopes = linear_corpus(np.random.default_rng(2))
    # closure=None: the /p b m/ rule would pull the frame before the /p/ back from the recording's 0.3
    synth = UnitSynthesizer(corpus, closure=None)
    phones = [("sil", 0.0, 0.4), ("p", 0.4, 0.5), ("aa", 0.5, 0.7), ("iy", 0.7, 0.8), ("sil", 0.8, 1.2)]
    res = synth.synthesize(phones, "arpabet", n_frames=36)
    before = res.frames.copy()
    audio = np.full((36, 4), 0.3)
    cfg = RecordingBlend(lead=1.0, speech=0.0, trail=0.0, ramp_s=0.0)
    out = synth.with_recording(res, audio, cfg)
    np.testing.assert_array_equal(res.frames, before)  # the pure text result is not modified
    lead = np.arange(36) / FPS < 0.4
    np.testing.assert_allclose(out[lead, K:], 0.3)
    np.testing.assert_array_equal(out[~lead], before[~lead])
    # the corpus's coefficients are exactly linear in its parameters, so the moved coefficients are
    # those of the new parameters under the same relation
    np.testing.assert_allclose(out[lead, :K] - before[lead, :K], (0.3 - before[lead, K:]) @ slopes, atol=1e-8)


def test_blend_config_is_validated():
    with pytest.raises(ConfigError):
        RecordingBlend(lead=1.5)
    with pytest.raises(ConfigError):
        RecordingBlend(ramp_s=-0.1)
