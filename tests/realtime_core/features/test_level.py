"""Level normalisation: the speech-peak tracker and the gain-invariant front end."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import ConfigError, InvalidFeaturesError
from realtime_core.avmodel import frontend_from_json, frontend_to_json
from realtime_core.features import (
    CmvnConfig,
    FrontEnd,
    FrontEndConfig,
    LevelNormConfig,
    LevelTracker,
    MfccConfig,
    extract_features,
    raw_mfcc_with_level,
)
from tests.chunking import assert_chunk_invariant
from tests.speech import speechlike

LN = LevelNormConfig()
CFG = FrontEndConfig(
    mfcc=MfccConfig(sample_rate_hz=16000),
    energy=True,
    level_norm=LN,
    cmvn=CmvnConfig(gate_db=-LN.silence_below_peak_db),
)


def _voice(seed: int = 0) -> np.ndarray:
    """3 s: a pause, speech-like audio, a pause, all over a noise floor (no band at the energy floor)."""
    rng = np.random.default_rng(seed)
    x = np.concatenate([np.zeros(8000), speechlike(2.0, 16000, seed=seed), np.zeros(8000)])
    return (x + 3e-3 * rng.standard_normal(x.size)).astype(np.float64)


def _stats(x: np.ndarray, cfg: FrontEndConfig = CFG) -> dict:
    ceps, level = raw_mfcc_with_level(x, cfg)
    keep = level >= cfg.cmvn.gate_db if cfg.cmvn is not None else slice(None)
    return dict(cmvn_mean=ceps[keep].mean(0), cmvn_var=ceps[keep].var(0))


def test_tracker_is_equivariant_to_a_level_offset():
    """Every update is a step towards the frame: a gain of g dB shifts the peak by exactly g."""
    rng = np.random.default_rng(1)
    lv = np.where(rng.random(400) < 0.4, -65.0, -25.0) + 4 * rng.standard_normal(400)
    base = LevelTracker(LN).push(lv)
    for g in (-17.0, 9.5):
        np.testing.assert_allclose(LevelTracker(LN).push(lv + g), base + g, rtol=0, atol=1e-9)


def test_peak_settles_on_the_loud_speech_frames_and_holds_through_a_pause():
    rng = np.random.default_rng(2)
    speech = -30 + 6 * rng.standard_normal(300)
    tr = LevelTracker(LN)
    # starts in a pause at -70 dB: the first speech frames pull the peak down to the speech level
    p = tr.push(np.concatenate([np.full(30, -70.0), speech]))
    assert np.percentile(speech, 75) - 3 < p[-1] < speech.max()
    # a 20 s pause leaves the peak where it was (so a pause stays silence, however long)
    hold = tr.push(np.full(600, -70.0))
    assert abs(hold[-1] - p[-1]) < 1e-9
    # a stream that starts in speech (peak 30 dB too high) settles within a few seconds
    q = LevelTracker(LN).push(speech)
    assert abs(q[-1] - p[-1]) < 3.0


def test_tracker_streams_like_batch_and_validates():
    rng = np.random.default_rng(3)
    lv = -40 + 15 * rng.standard_normal(200)
    whole = LevelTracker(LN).push(lv)
    tr = LevelTracker(LN)
    parts = np.concatenate([tr.push(lv[a:b]) for a, b in ((0, 1), (1, 1), (1, 77), (77, 200))])
    np.testing.assert_array_equal(parts, whole)
    with pytest.raises(InvalidFeaturesError):
        tr.push(np.array([0.0, np.nan]))
    with pytest.raises(ConfigError, match="peak_release"):
        LevelNormConfig(peak_release=0.0)
    with pytest.raises(ConfigError, match="silence_below_peak_db"):
        LevelNormConfig(silence_below_peak_db=-3.0)


@pytest.mark.parametrize("gain_db", [-18.0, -6.0, 12.0])
def test_front_end_features_do_not_depend_on_the_recording_gain(gain_db):
    """With level normalisation a quieter or louder recording gives the same features from the first
    frame (the c0 offset, the silence gate and the CMVN gate all move with the gain); without it the
    features change."""
    x = _voice()
    g = 10 ** (gain_db / 20)
    stats = _stats(x)
    np.testing.assert_allclose(extract_features(g * x, CFG, **stats), extract_features(x, CFG, **stats), atol=1e-9)
    absolute = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000), energy=True)
    astats = _stats(x, absolute)
    changed = np.abs(extract_features(g * x, absolute, **astats) - extract_features(x, absolute, **astats)).max()
    assert changed > 0.3


def test_front_end_with_level_norm_is_chunk_invariant_on_both_kernels():
    x = _voice(4)[:24000]
    stats = _stats(x)
    whole = extract_features(x, CFG, **stats)
    for kernel in ("numba", "numpy"):
        got = assert_chunk_invariant(lambda k=kernel: FrontEnd(CFG, **stats, kernel=k), x, atol=1e-10, max_examples=8)
        np.testing.assert_allclose(got, whole, rtol=0, atol=1e-10)


def test_pauses_far_under_the_peak_are_one_fixed_silence_vector():
    """Digital silence and a quiet room after speech both become the same silence features."""
    rng = np.random.default_rng(5)
    speech = speechlike(1.0, 16000, seed=5).astype(np.float64)
    quiet = np.concatenate([speech, np.zeros(16000)])
    hiss = np.concatenate([speech, 1e-4 * rng.standard_normal(16000)])
    cfg = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000), energy=True, level_norm=LN, cmvn=None, tc=0)
    a, b = extract_features(quiet, cfg), extract_features(hiss, cfg)
    np.testing.assert_array_equal(a[-20:], np.repeat(a[-1:], 20, 0))
    np.testing.assert_array_equal(a[-20:], b[-20:])


def test_model_json_keeps_the_level_config_and_old_models_have_none():
    d = frontend_to_json(CFG)
    assert frontend_from_json(d) == CFG
    old = frontend_to_json(FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000)))
    assert "level_norm" not in old
    assert frontend_from_json(old).level_norm is None


@pytest.mark.parametrize("noise_db", [-75.0, -45.0, -20.0])
def test_steady_noise_alone_is_silence_at_any_level(noise_db):
    """A stream of room noise with no speech has no speech peak: it must give exactly the silence
    features (so the mouth stays still), whatever its level; a voice then starting is not silence."""
    rng = np.random.default_rng(6)
    noise = rng.standard_normal(48000) * 10 ** (noise_db / 20)
    cfg = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000), energy=True, level_norm=LN, cmvn=None, tc=0)
    f = extract_features(noise, cfg)
    np.testing.assert_array_equal(f, np.repeat(f[:1], len(f), 0))
    # ...and with the running CMVN: silence never moves its statistics
    normed = extract_features(noise, CFG, **_stats(_voice()))
    np.testing.assert_array_equal(normed, np.repeat(normed[:1], len(normed), 0))
    voice = np.concatenate([noise, speechlike(1.0, 16000, seed=6) * 10 ** ((noise_db + 40) / 20) / 0.8])
    g = extract_features(voice, cfg)
    assert np.abs(g[len(f) :] - f[0]).max(axis=1).mean() > 1.0
