"""The run-time input gain stage: streaming, gain tracking, noise alone, and the live path with it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from realtime_core import ConfigError
from realtime_core.avmodel import frontend_from_json, frontend_to_json
from realtime_core.features import FrontEndConfig, InputGain, InputGainConfig
from tests.chunking import assert_chunk_invariant
from tests.speech import speechlike

CFG = InputGainConfig()
RATE = 16000


def _talk(seconds: float, seed: int) -> np.ndarray:
    """Speech-like audio with pauses over a quiet noise floor, speech near the reference level."""
    rng = np.random.default_rng(seed)
    parts = []
    for i in range(int(seconds // 2)):
        parts += [np.zeros(RATE // 2), speechlike(1.5, RATE, seed=seed + i)]
    x = np.concatenate(parts)
    return x + 1e-3 * rng.standard_normal(x.size)


def _gains(x: np.ndarray, cfg: InputGainConfig = CFG) -> np.ndarray:
    """The gain (dB) after each block, pushing block by block."""
    st = InputGain(cfg, sample_rate_hz=RATE)
    out = []
    for i in range(0, x.size - st.block_len + 1, st.block_len):
        st.push(x[i : i + st.block_len])
        out.append(st.gain_db)
    return np.asarray(out)


def test_streaming_equals_whole_sample_by_sample_and_in_random_chunks():
    x = _talk(4.0, seed=3) * 0.2  # quieter than the reference: the gain moves
    assert _gains(x)[-1] > 3.0
    assert_chunk_invariant(lambda: InputGain(CFG, sample_rate_hz=RATE), x, max_examples=15)


def test_quiet_speech_is_brought_to_the_level_a_louder_copy_gets():
    """Independent check: the gain of a copy g dB quieter converges to the original's gain + g."""
    x = _talk(20.0, seed=5)
    g0 = _gains(x)
    for g in (-12.0, 6.0):
        d = _gains(x * 10 ** (g / 20)) - g0 + g
        settled = int(10.0 * RATE / CFG.block_len(RATE))
        assert np.abs(d[settled:]).max() < 0.5, g
        assert abs(d[0]) == pytest.approx(abs(g))  # the first block is left alone: no lookahead


def test_the_gain_is_limited():
    x = _talk(10.0, seed=7) * 10 ** (-40 / 20)
    g = _gains(x)
    assert g.max() == pytest.approx(CFG.max_gain_db)


@pytest.mark.parametrize("dbfs", [-70.0, -50.0, -40.0, -20.0])
def test_noise_alone_and_silence_pass_unchanged(dbfs: float):
    """Steady noise is never speech (never the floor margin over the floor): gain exactly 0 dB."""
    x = np.random.default_rng(0).standard_normal(3 * RATE) * 10 ** (dbfs / 20)
    st = InputGain(CFG, sample_rate_hz=RATE)
    np.testing.assert_array_equal(np.concatenate([st.push(x), st.flush()]), x)
    np.testing.assert_array_equal(InputGain(CFG, sample_rate_hz=RATE).push(np.zeros(RATE)), np.zeros(RATE))


def test_config_is_validated_and_round_trips_through_the_model_file():
    for bad in (dict(max_gain_db=-1.0), dict(reference_db=3.0), dict(prior_blocks=200), dict(block_ms=0.5)):
        with pytest.raises(ConfigError):
            InputGainConfig(**bad)
    fe = FrontEndConfig(input_gain=InputGainConfig(max_gain_db=12.0))
    assert frontend_from_json(frontend_to_json(fe)) == fe
    assert "input_gain" not in frontend_to_json(FrontEndConfig())  # older files read as before


def test_live_path_on_s1_at_minus_12_db_gives_the_0_db_output(shared_data):
    """The shipped model with the stage on: s1 sentences back to back, once as recorded and once
    12 dB quieter. Once the speech level has settled (15 s; measured: gain within 0.13 dB, mouth
    within 0.006 IOD) the mouth is the same; without the stage it is not."""
    from assets.audio import read_audio
    from assets.grid import sentences
    from assets.modelfile import load_model
    from realtime_core.pipeline import speech_to_params

    root = shared_data / "video" / "grid_s1"
    x = np.concatenate([read_audio(s.video, rate_hz=RATE)[0] for s in sentences(root, split="train")[:10]])
    x = x.astype(np.float64)
    quiet = x * 10 ** (-12 / 20)
    shipped = load_model(None)
    on = replace(shipped, frontend=replace(shipped.frontend, input_gain=CFG))
    k = 15 * 30
    diff_on = np.abs(speech_to_params(on, x, RATE)[k:] - speech_to_params(on, quiet, RATE)[k:]).max()
    diff_off = np.abs(speech_to_params(shipped, x, RATE)[k:] - speech_to_params(shipped, quiet, RATE)[k:]).max()
    assert diff_on < 0.01 < diff_off, (diff_on, diff_off)


def test_noise_alone_moves_the_live_path_exactly_as_without_the_stage():
    from assets.modelfile import load_model
    from realtime_core.pipeline import speech_to_params

    shipped = load_model(None)
    on = replace(shipped, frontend=replace(shipped.frontend, input_gain=CFG))
    x = np.random.default_rng(1).standard_normal(2 * RATE) * 10 ** (-50 / 20)
    np.testing.assert_array_equal(speech_to_params(on, x, RATE), speech_to_params(shipped, x, RATE))


def test_speech_level_is_the_speech_blocks_level_and_moves_with_a_gain():
    """speech_level_db on bursts of a 500 Hz tone at amplitude 0.1 (whole periods in every 32 ms block, the bursts on
    block boundaries), pauses of noise at -60 dBFS: the bursts' own RMS level, 20 log10(0.1 / sqrt 2) dBFS; a gain
    of g dB moves it by exactly g (the floor tracker is equivariant), what makes it a measure of the recording's gain;
    silence and noise alone have no speech level."""
    from realtime_core.features.gain import speech_level_db

    b = CFG.block_len(RATE)
    assert b == 512  # 16 periods of 500 Hz
    rng = np.random.default_rng(5)
    burst = 0.1 * np.sin(2 * np.pi * 500.0 * np.arange(20 * b) / RATE)
    x = np.concatenate([np.zeros(15 * b), burst, np.zeros(10 * b), burst, np.zeros(10 * b)])
    x = x + 1e-3 * rng.standard_normal(x.size)
    level = speech_level_db(x, RATE)
    assert level == pytest.approx(20.0 * np.log10(0.1 / np.sqrt(2.0)), abs=0.01)
    # Digital silence around it (a file's padding) changes nothing: it took the floor to -120 dB, and the bursts'
    # edges and the noise for speech.
    assert speech_level_db(np.concatenate([np.zeros(40 * b), x, np.zeros(40 * b)]), RATE) == level
    for g in (-20.0, 6.0):
        assert speech_level_db(x * 10.0 ** (g / 20.0), RATE) == pytest.approx(level + g, abs=1e-6)
    assert speech_level_db(np.zeros(RATE), RATE) is None
    assert speech_level_db(1e-3 * rng.standard_normal(3 * RATE), RATE) is None
    assert speech_level_db(x[: b - 1], RATE) is None
