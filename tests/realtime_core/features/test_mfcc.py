"""MfccStream: agreement with python_speech_features, the frame grid, chunking, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io.wavfile

from realtime_core import ConfigError, InvalidAudioError, StreamStateError
from realtime_core.features import MfccConfig, MfccStream, mfcc
from tests.chunking import assert_chunk_invariant
from tests.prerequisites import require_data, require_module


def _speech_22k() -> np.ndarray:
    rate, x = scipy.io.wavfile.read(require_data("speech/ljspeech/LJ001-0001.wav"))
    assert rate == 22050
    return x.astype(np.float64) / 32768.0


def test_agrees_with_python_speech_features_on_real_speech():
    """Same settings (22.05 kHz so the hop is an integer 735 samples, Hamming window of
    1470, 2048-point FFT, 26 HTK filters, pre-emphasis 0.97, no lifter, no energy swap):
    c1..c11 agree with python_speech_features to 1e-8 absolute on every complete frame."""
    psf = require_module("python_speech_features")
    x = _speech_22k()
    cfg = MfccConfig(sample_rate_hz=22050, n_mels=26, n_ceps=11)
    assert (cfg.window_len, cfg.n_fft) == (1470, 2048)
    ours = mfcc(x, cfg)
    ref = psf.mfcc(
        x,
        samplerate=22050,
        winlen=1470 / 22050,
        winstep=735 / 22050,
        numcep=12,
        nfilt=26,
        nfft=2048,
        lowfreq=0,
        highfreq=None,
        preemph=0.97,
        ceplifter=0,
        appendEnergy=False,
        winfunc=np.hamming,
    )[:, 1:12]
    complete = (len(x) - 1470) // 735 + 1  # frames entirely inside the audio
    assert ours.shape[0] == cfg.n_frames_for(len(x))
    np.testing.assert_allclose(ours[:complete], ref[:complete], atol=1e-8, rtol=0)


@pytest.mark.parametrize("rate", [8000, 11025, 16000, 22050, 44100, 48000])
def test_frames_start_on_the_exact_30fps_grid(rate):
    cfg = MfccConfig(sample_rate_hz=rate)
    # After one hour the grid has not drifted by a single sample.
    assert cfg.frame_start(30 * 3600) == rate * 3600
    assert cfg.frame_start(1) == (rate // 30 if rate % 30 == 0 else int(np.floor(rate / 30)))
    # A click at sample s raises c0 exactly in the frames whose window covers s.
    s = rate  # one second in
    x = np.zeros(rate * 2)
    x[s] = 0.9
    c0 = mfcc(x, MfccConfig(sample_rate_hz=rate, include_c0=True))[:, 0]
    covering = [k for k in range(len(c0)) if cfg.frame_start(k) <= s < cfg.frame_start(k) + cfg.window_len]
    loud = np.flatnonzero(c0 > c0.min() + 10)
    assert list(loud) == covering


def test_no_centre_padding_a_frame_waits_for_all_its_samples():
    cfg = MfccConfig(sample_rate_hz=16000)
    st = MfccStream(cfg)
    x = np.random.default_rng(0).standard_normal(cfg.window_len) * 0.1
    assert st.push(x[:-1]).shape == (0, 11)
    assert st.push(x[-1:]).shape == (1, 11)
    # 16 kHz: hop is 533.33 samples; frame 1 starts at 533 and needs up to 533 + window.
    need = cfg.frame_start(1)  # samples still missing for frame 1 (533 at 16 kHz)
    assert st.push(np.zeros(need - 1)).shape[0] == 0
    assert st.push(np.zeros(1)).shape[0] == 1


@pytest.mark.parametrize("rate,dtype", [(16000, np.int16), (11025, np.float32), (44100, np.float64)])
def test_same_output_whole_sample_by_sample_and_random_chunks(rate, dtype):
    rng = np.random.default_rng(rate)
    n = int(rate * 0.6) + 7
    sig = rng.standard_normal(n) * 0.2
    x = (sig * 20000).astype(np.int16) if dtype == np.int16 else sig.astype(dtype)
    cfg = MfccConfig(sample_rate_hz=rate)
    whole = assert_chunk_invariant(lambda: MfccStream(cfg), x, atol=1e-12)
    assert whole.shape == (cfg.n_frames_for(n), 11)
    np.testing.assert_allclose(whole, mfcc(x, cfg), rtol=0, atol=0)


def test_int16_equals_scaled_float():
    rng = np.random.default_rng(1)
    i16 = (rng.standard_normal(8000) * 3000).astype(np.int16)
    cfg = MfccConfig(sample_rate_hz=16000)
    np.testing.assert_allclose(mfcc(i16, cfg), mfcc(i16.astype(np.float32) / 32768.0, cfg), atol=1e-6)


@pytest.mark.parametrize(
    "samples,match",
    [
        (np.array([0.1, np.nan, 0.2] * 2000, dtype=np.float32), "NaN or inf"),
        (np.array([0.1, np.inf] * 3000), "NaN or inf"),
        (np.zeros(6000, dtype=np.int32), "dtype int32"),
        (np.zeros((6000, 2), dtype=np.float32), "1-D mono"),
        (np.zeros(0, dtype=np.float32), "too short"),
        (np.zeros(100, dtype=np.float32), "too short"),
    ],
)
def test_bad_audio_raises_a_named_error(samples, match):
    with pytest.raises(InvalidAudioError, match=match):
        mfcc(samples, MfccConfig(sample_rate_hz=16000))


def test_bad_config_and_misuse():
    for bad in (
        dict(sample_rate_hz=4000),
        dict(sample_rate_hz=96000),
        dict(sample_rate_hz=16000.5),
        dict(n_ceps=30),
        dict(preemphasis=1.5),
        dict(window_hops=0.5),
    ):
        with pytest.raises(ConfigError):
            MfccConfig(**bad)
    st = MfccStream(MfccConfig())
    st.flush()
    with pytest.raises(StreamStateError):
        st.push(np.zeros(10, dtype=np.float32))


@pytest.mark.parametrize("kernel", ["numba", "numpy"])
def test_streams_of_one_configuration_share_read_only_tables_and_no_state(kernel):
    """The filterbank, window and DCT are built once per configuration and shared (a live server
    opens a stream per session): they cannot be written, and a stream that already processed other
    audio does not change what a fresh one computes, which equals the one-shot function."""
    cfg = MfccConfig(sample_rate_hz=16000, include_c0=True)
    rng = np.random.default_rng(3)
    x, other = rng.uniform(-0.5, 0.5, 8000), rng.uniform(-0.9, 0.9, 12000)
    busy = MfccStream(cfg, kernel=kernel)
    busy.push(other)
    busy.flush()
    busy.reset()
    fresh = MfccStream(cfg, kernel=kernel)
    assert fresh._fbank is busy._fbank and not fresh._fbank.flags.writeable
    with pytest.raises(ValueError):
        fresh._dct[0, 0] = 1.0
    a = np.vstack([fresh.push(x), fresh.flush()])
    b = np.vstack([busy.push(x), busy.flush()])
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a, mfcc(x, cfg), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("warp", [0.88, 1.12])
def test_warped_filterbank_moves_a_tone_to_the_filter_of_warp_times_its_frequency(warp):
    """VTLP (MfccConfig.warp): a pure tone at f, analysed with warp w, excites the mel filters the way a
    tone at w * f does unwarped (below the warp's knee at 0.8 x Nyquist / max(w, 1))."""
    rate = 16000
    t = np.arange(rate // 2) / rate
    f = 2000.0

    def filter_energies(freq: float, w: float) -> np.ndarray:
        cfg = MfccConfig(sample_rate_hz=rate, warp=w)
        stream = MfccStream(cfg, kernel="numpy")
        x = 0.5 * np.sin(2 * np.pi * freq * t)
        frames = x[: cfg.window_len] * np.hamming(cfg.window_len)
        power = np.abs(np.fft.rfft(frames, n=cfg.n_fft)) ** 2
        return power @ stream._fbank

    warped = filter_energies(f, warp)
    moved = filter_energies(warp * f, 1.0)
    unwarped = filter_energies(f, 1.0)
    assert np.argmax(warped) == np.argmax(moved) != np.argmax(unwarped)
    # the profile across filters is the moved tone's, up to the interpolation of the filters
    assert np.corrcoef(np.log(warped + 1e-12), np.log(moved + 1e-12))[0, 1] > 0.99


@pytest.mark.parametrize("kernel", ["numba", "numpy"])
def test_warp_one_is_the_plain_filterbank_and_warped_streams_are_chunk_invariant(kernel):
    """warp 1 changes nothing; a warped stream keeps the streaming contract, and the two kernels agree."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal(16000) * 0.1
    np.testing.assert_array_equal(mfcc(x, MfccConfig(warp=1.0)), mfcc(x, MfccConfig()))
    cfg = MfccConfig(warp=1.1)
    whole = MfccStream(cfg, kernel=kernel)
    ref = np.concatenate([whole.push(x), whole.flush()])
    assert not np.allclose(ref, mfcc(x, MfccConfig()))
    whole = assert_chunk_invariant(lambda: MfccStream(cfg, kernel=kernel), x, atol=1e-12)
    np.testing.assert_allclose(whole, ref, rtol=0, atol=1e-12)
    other = MfccStream(cfg, kernel="numpy" if kernel == "numba" else "numba")
    np.testing.assert_allclose(np.concatenate([other.push(x), other.flush()]), ref, atol=1e-9)


def test_warp_outside_its_range_is_refused():
    with pytest.raises(ConfigError, match="warp"):
        MfccConfig(warp=1.4)
