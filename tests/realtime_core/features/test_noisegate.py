"""The output noise gate: room noise alone gives no motion, speech after it moves as without the gate,
streaming equals whole, and the gate's own arithmetic on known levels."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from realtime_core import ConfigError
from realtime_core.features import NoiseGate, NoiseGateConfig
from realtime_core.pipeline import SpeechToParams, speech_to_params
from tests.chunking import assert_chunk_invariant
from tests.speech import speechlike

RATE = 16000
CFG = NoiseGateConfig()
SETTLED = CFG.warmup_frames + CFG.release_frames
"""Rows from here on are gated in steady noise (the warm-up, then the fade)."""


def _noise(kind: str, seconds: float, dbfs: float, seed: int = 0) -> np.ndarray:
    """Steady room-like noise (n,) at ``dbfs`` RMS: white, or pink (1/f by shaping the spectrum)."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(int(seconds * RATE))
    if kind == "pink":
        f = np.fft.rfftfreq(x.size, 1 / RATE)
        x = np.fft.irfft(np.fft.rfft(x) / np.sqrt(np.maximum(f, 20.0)), x.size)
    return x * 10 ** (dbfs / 20) / np.sqrt(np.mean(x**2))


@pytest.fixture(scope="module")
def shipped():
    from assets.modelfile import load_model

    return load_model(None)


@pytest.mark.parametrize(("kind", "dbfs"), [("white", -60.0), ("white", -54.0), ("pink", -54.0), ("white", -48.0)])
def test_room_noise_alone_gives_no_motion(shipped, kind: str, dbfs: float):
    """The user's case: an idle microphone in a room. Without the gate the shipped model mumbles (measured: mouth_open
    0.04-0.05 IOD on average, up to 0.10); with it every parameter is exactly the rest pose once the warm-up and the
    fade are over."""
    x = _noise(kind, 4.0, dbfs)
    off = speech_to_params(shipped, x, RATE, noise_gate=None)
    on = speech_to_params(shipped, x, RATE)
    assert off[SETTLED:, 2].max() > 0.03  # the defect, so the test can fail
    np.testing.assert_array_equal(on[SETTLED:], 0.0)
    np.testing.assert_array_equal(on[: CFG.warmup_frames], off[: CFG.warmup_frames])


def test_speech_after_noise_moves_as_without_the_gate(shipped, shared_data):
    """3 s of room noise, then a GRID s1 sentence with the same noise under it (its own leading pause included): from
    the first word to the end the rows are those without the gate bit for bit, and the noise before is at rest."""
    from assets.audio import read_audio
    from assets.grid import read_words, sentences

    s = sentences(shared_data / "video" / "grid_s1", split="train")[0]
    speech = read_audio(s.video, rate_hz=RATE)[0].astype(np.float64)
    lead = 3.0
    x = _noise("white", lead, -54.0)
    x = np.concatenate([x, speech + _noise("white", speech.size / RATE, -54.0, seed=1)])
    off = speech_to_params(shipped, x, RATE, noise_gate=None)
    on = speech_to_params(shipped, x, RATE)
    first_word = next(a for a, _, w in read_words(s.align) if w not in ("sil", "sp"))
    k = int(np.floor((lead + first_word) * 30))
    np.testing.assert_array_equal(on[k:], off[k:])
    assert off[k:, 2].max() > 0.1  # the sentence opens the mouth
    # up to the frames that look ahead into the recording (its own leading pause is over the room's floor)
    rest = int(lead * 30) - shipped.frontend.tc
    np.testing.assert_array_equal(on[SETTLED:rest], 0.0)
    assert off[SETTLED:rest, 2].max() > 0.03


def test_streaming_equals_whole_sample_by_sample_and_in_random_chunks(shipped):
    """Noise, a burst of speech-like sound and noise again: the gate closes, opens and closes in this input (its gains
    take 0, 1 and values between), and the chain gives the same rows for any chunking."""
    x = np.concatenate(
        [_noise("white", 1.5, -54.0), 0.3 * speechlike(0.6, RATE, seed=2), _noise("white", 1.8, -54.0, seed=3)]
    )
    p = SpeechToParams(shipped)
    np.concatenate([p.push(x), p.flush()])
    assert p._gate is not None
    gains = []
    p.reset()
    for i in range(0, x.size, 1600):
        p.push(x[i : i + 1600])
        gains.append(p._gate.gain)
    p.flush()
    gains.append(p._gate.gain)
    g = np.concatenate(gains)
    assert g.min() == 0.0 and g.max() == 1.0 and ((g > 0) & (g < 1)).sum() >= 6
    assert_chunk_invariant(lambda: SpeechToParams(shipped), x, max_examples=8)


def _gains(levels: np.ndarray, cfg: NoiseGateConfig = CFG, *, lookahead: int = 3, cuts=()) -> np.ndarray:
    """The gate's gains for ``levels`` (one row of ones per frame), levels and rows pushed at ``cuts``, each row
    after the levels it may look ahead to."""
    gate = NoiseGate(cfg, lookahead=lookahead)
    out = []
    edges = [0, *cuts, len(levels)]
    for a, b in itertools.pairwise(edges):
        gate.push_levels(levels[a:b])
        out.append(gate.apply(np.ones((max(b - lookahead - gate._row, 0), 1)))[:, 0])
    out.append(gate.apply(np.ones((len(levels) - gate._row, 1)))[:, 0])
    return np.concatenate(out)


def test_gate_arithmetic_on_known_levels():
    """Steady noise at -55 dB with a 5-frame sound 20 dB over it at frames 60-64 (an independent account of the
    rules): closed after the warm-up's fade, fading in over the lookahead before the sound (1/4, 2/4, 3/4), open
    through the hold after it, then fading out by 1/6 a frame."""
    lv = np.full(150, -55.0)
    lv[60:65] = -35.0
    g = _gains(lv)
    w, r = CFG.warmup_frames, CFG.release_frames
    np.testing.assert_array_equal(g[:w], 1.0)
    np.testing.assert_allclose(g[w : w + r], 1.0 - np.arange(1, r + 1) / r, atol=1e-12)
    np.testing.assert_array_equal(g[w + r : 57], 0.0)
    np.testing.assert_allclose(g[57:60], [0.25, 0.5, 0.75])
    hold_end = 64 + CFG.hold_frames
    np.testing.assert_array_equal(g[60 : hold_end + 1], 1.0)
    np.testing.assert_allclose(g[hold_end + 1 : hold_end + 1 + r], 1.0 - np.arange(1, r + 1) / r, atol=1e-12)
    np.testing.assert_array_equal(g[hold_end + r :], 0.0)
    for cuts in ([1, 2, 3], [7, 59, 61, 100], list(range(1, 150))):
        np.testing.assert_array_equal(_gains(lv, cuts=cuts), g)


def test_digital_silence_does_not_drag_the_floor_down():
    """A muted stretch (zeros: -100 dB) inside the room's noise leaves the floor where it was: the noise after it stays
    gated. Were it tracked, the floor would fall 45 dB and the noise read as sound for the seconds the floor takes to
    rise back."""
    lv = np.concatenate([np.full(60, -55.0), np.full(30, -100.0), np.full(60, -55.0)])
    g = _gains(lv)
    np.testing.assert_array_equal(g[CFG.warmup_frames + CFG.release_frames :], 0.0)


def test_digital_silence_alone_is_left_as_the_model_gives_it(shipped):
    """Silence gives no motion: a take of digital silence is the model's own rest, row for row, with the gate as
    without it; the warm-up starts at the first frame over digital silence (a stream that opens muted)."""
    silence = np.zeros(2 * RATE)
    np.testing.assert_array_equal(
        speech_to_params(shipped, silence, RATE), speech_to_params(shipped, silence, RATE, noise_gate=None)
    )
    lv = np.concatenate([np.full(20, -100.0), np.full(60, -55.0)])
    g = _gains(lv)
    w, r = 20 + CFG.warmup_frames, CFG.release_frames
    np.testing.assert_array_equal(g[:w], 1.0)
    np.testing.assert_allclose(g[w : w + r], 1.0 - np.arange(1, r + 1) / r, atol=1e-12)
    np.testing.assert_array_equal(g[w + r :], 0.0)


def test_config_is_validated_and_rows_wait_for_their_levels():
    for bad in (dict(margin_db=-1.0), dict(ramp_db=61.0), dict(hold_frames=-1), dict(release_frames=5000)):
        with pytest.raises(ConfigError):
            NoiseGateConfig(**bad)
    with pytest.raises(ConfigError):
        NoiseGate(CFG, lookahead=-1)
    gate = NoiseGate(CFG, lookahead=3)
    gate.push_levels(np.full(2, -50.0))
    with pytest.raises(ConfigError, match="before its frame's level"):
        gate.apply(np.ones((3, 4)))


@pytest.mark.parametrize("quiet_dbfs", [-64.0, -74.0])
def test_a_noise_that_steps_up_rests_within_three_seconds(shipped, quiet_dbfs: float):
    """A fan switched on: white noise steps from a quiet room up to -54 dBFS. The gate's floor (the minimum of the
    smoothed level over 1.5 s) is the new noise 1.5 s later; with the 1 s hold and the 0.2 s fade every row from 3 s
    after the step is the rest pose. Measured before (a floor rising by 0.5 % of the gap a frame): the mouth moved up
    to 0.12 IOD for 12.1 s after the step (16.1 s from -74 dBFS)."""
    step = 4.0
    x = np.concatenate([_noise("white", step, quiet_dbfs), _noise("white", 8.0, -54.0, seed=1)])
    off = speech_to_params(shipped, x, RATE, noise_gate=None)
    on = speech_to_params(shipped, x, RATE)
    k = int((step + 3.0) * 30)
    np.testing.assert_array_equal(on[k:], 0.0)
    assert off[k:, 2].max() > 0.03  # the noise moves the ungated mouth there


def test_the_floor_follows_a_step_up_on_known_levels():
    """Levels step from -65 to -55 dB at frame 60 (an independent account of the floor: the level smoothed by 0.3
    of its gap a frame, its minimum over the last 45 frames): the gain is 1 while a frame of the last second was
    over the margin, then fades by 1/6 a frame to 0; the floor never falls for a rise, only rises 45 frames on."""
    lv = np.concatenate([np.full(60, -65.0), np.full(140, -55.0)])
    cfg = CFG
    s = np.empty_like(lv)
    s[0] = lv[0]
    for i in range(1, len(lv)):
        s[i] = s[i - 1] + cfg.floor_smoothing * (lv[i] - s[i - 1])
    w = cfg.floor_window_frames
    floor = np.array([s[max(i - w + 1, 0) : i + 1].min() for i in range(len(lv))])
    openness = np.clip((lv - floor - cfg.margin_db) / cfg.ramp_db, 0.0, 1.0)
    full, last = int(np.flatnonzero(openness == 1.0)[-1]), int(np.flatnonzero(openness > 0.0)[-1])
    assert 60 + w <= last <= 60 + w + 5  # the floor catches up the window after the step
    g = _gains(lv)
    np.testing.assert_array_equal(g[60 : full + cfg.hold_frames + 1], 1.0)
    assert np.all(np.diff(g[full + cfg.hold_frames :]) <= 0.0)  # then it only falls: a fade ...
    np.testing.assert_array_equal(g[last + cfg.hold_frames + cfg.release_frames :], 0.0)  # ... to rest


def test_levels_a_rounding_apart_give_the_same_gains():
    """The front end's level of a frame differs in its last bits with the chunking (2e-14 dB measured, whole against
    sample by sample); the gate reads levels at float32, so a fractional openness does not pass that on."""
    lv = np.full(120, -55.0)
    lv[60:64] = -51.7  # openness 0.4: fractional
    g = _gains(lv)
    assert ((g > 0) & (g < 1)).any()
    np.testing.assert_array_equal(_gains(lv + 2e-14), g)


def test_continuous_read_speech_is_never_faded(shipped, shared_data):
    """106 s of read speech (LJ Speech's first 16 clips back to back, no pause longer than the clips' own),
    clean and under white noise at -54 dBFS: the gain is 1 from the warm-up to the last second (the take's end may
    fade), so every speech row is the ungated one. A floor that followed the speech's own level would close the gate
    in it (`scripts/noise_gate_check.py` measures all 32 clips, and under pink noise)."""
    from assets.audio import read_audio

    clips = sorted((shared_data / "speech" / "ljspeech").glob("*.wav"))[:16]
    x = np.concatenate([read_audio(f, rate_hz=RATE)[0].astype(np.float64) for f in clips])
    for take in (x, x + _noise("white", x.size / RATE, -54.0, seed=5)):
        fe = shipped.front_end()
        fe.push(take)
        levels = [fe.last_level_db]
        fe.flush()
        g = _gains(np.concatenate([levels[0], fe.last_level_db]), lookahead=shipped.frontend.tc)
        assert len(g) > 3000
        np.testing.assert_array_equal(g[: len(g) - 30], 1.0)


def test_an_expression_on_room_noise_holds_still_with_the_mlp_mapper():
    """Paper 002's second stage computes an expression's change from the mapper's MUPs: the gate fades them with the
    rows, towards the MUPs of digital silence, so a smile (or any expression) on room noise is one still pose; the
    ungated MUPs under the gated rows moved it (measured: 0.0015-0.0032 IOD peak to peak, smile 0.7, -54 dBFS)."""
    from assets.modelfile import load_speech_model
    from realtime_core.expressions import EXPRESSIONS
    from realtime_core.mapping.expression import express
    from realtime_core.pipeline import speech_to_params_and_mups

    model = load_speech_model("mlp")
    rest = model.rest_mups()
    _, silent = speech_to_params_and_mups(model, np.zeros(RATE), RATE)
    np.testing.assert_array_equal(silent, np.broadcast_to(rest, silent.shape))  # the chain's own MUPs of silence
    x = _noise("white", 4.0, -54.0)
    params, mups = speech_to_params_and_mups(model, x, RATE)
    _, raw = speech_to_params_and_mups(model, x, RATE, noise_gate=None)
    assert mups is not None and raw is not None
    np.testing.assert_array_equal(mups[: CFG.warmup_frames], raw[: CFG.warmup_frames])
    np.testing.assert_array_equal(mups[SETTLED:], np.broadcast_to(rest, mups[SETTLED:].shape))
    for k in range(len(EXPRESSIONS)):
        alpha = np.zeros((len(params), len(EXPRESSIONS)))
        alpha[:, k] = 0.7
        out = express(params, alpha, mups=mups, mapper=model.expressions)[SETTLED:]
        np.testing.assert_array_equal(out, np.broadcast_to(out[0], out.shape))
        before = express(params, alpha, mups=raw, mapper=model.expressions)[SETTLED:]
        assert np.ptp(before, axis=0).max() > 1e-3  # the defect, so the test can fail


def test_mups_of_speech_after_noise_are_the_ungated_ones(shared_data):
    """A GRID s1 sentence after 3 s of room noise, with the MLP mapper: from the first word on the MUPs (and rows)
    are those without the gate bit for bit."""
    from assets.audio import read_audio
    from assets.grid import read_words, sentences
    from assets.modelfile import load_speech_model
    from realtime_core.pipeline import speech_to_params_and_mups

    model = load_speech_model("mlp")
    s = sentences(shared_data / "video" / "grid_s1", split="train")[0]
    speech = read_audio(s.video, rate_hz=RATE)[0].astype(np.float64)
    x = np.concatenate([_noise("white", 3.0, -54.0), speech + _noise("white", speech.size / RATE, -54.0, seed=1)])
    on, mon = speech_to_params_and_mups(model, x, RATE)
    off, moff = speech_to_params_and_mups(model, x, RATE, noise_gate=None)
    assert mon is not None and moff is not None
    first_word = next(a for a, _, w in read_words(s.align) if w not in ("sil", "sp"))
    k = int(np.floor((3.0 + first_word) * 30))
    np.testing.assert_array_equal(on[k:], off[k:])
    np.testing.assert_array_equal(mon[k:], moff[k:])
    assert not np.array_equal(mon[SETTLED:60], moff[SETTLED:60])  # the noise before is faded


class _GateLevels:
    """The levels (k,) dB the live chain hands the noise gate after each push/flush (``SpeechToParams`` passes the
    front end's ``last_level_db``), as a streaming stage for :func:`tests.chunking.assert_chunk_invariant`."""

    def __init__(self, model, kernel: str) -> None:
        self.fe = model.front_end(kernel=kernel)

    def push(self, x: np.ndarray) -> np.ndarray:
        self.fe.push(x)
        return self.fe.last_level_db

    def flush(self) -> np.ndarray:
        self.fe.flush()
        return self.fe.last_level_db


def _frame_levels_db(x: np.ndarray, mcfg) -> np.ndarray:
    """Each analysis frame's level computed here from the samples: pre-emphasis, Hamming window, power spectrum, mel
    energies floored, then the mean of 10 log10 over the mel bands (what c0 of the orthonormal DCT measures)."""
    from realtime_core.features.mfcc import mel_filterbank

    pre = x - mcfg.preemphasis * np.concatenate([[0.0], x[:-1]])
    n, win = mcfg.n_frames_for(x.size), mcfg.window_len
    padded = np.concatenate([pre, np.zeros(win)])
    frames = np.stack([padded[mcfg.frame_start(k) : mcfg.frame_start(k) + win] for k in range(n)]) * np.hamming(win)
    power = np.abs(np.fft.rfft(frames, n=mcfg.n_fft, axis=1)) ** 2 / mcfg.n_fft
    fb = mel_filterbank(
        sample_rate_hz=mcfg.sample_rate_hz, n_fft=mcfg.n_fft, n_mels=mcfg.n_mels, fmin_hz=0.0, fmax_hz=RATE / 2
    )
    return np.mean(10.0 * np.log10(np.maximum(power @ fb, mcfg.energy_floor)), axis=1)


@pytest.mark.parametrize("kernel", ["numba", "numpy"])
def test_the_gates_levels_are_the_frames_levels_for_any_chunking(kernel, shipped, shared_data):
    """The compiled front end now hands over the levels its silence gate computed (the live path computed them a
    second time in numpy on every push): on a real GRID s1 sentence with room noise before it, fed whole, sample by
    sample and in random chunks, they are each frame's level computed independently here."""
    from assets.audio import read_audio
    from assets.grid import sentences

    assert shipped.frontend.mfcc.warp == 1.0 and shipped.frontend.mfcc.fmin_hz == 0.0  # the reference below assumes
    s = sentences(shared_data / "video" / "grid_s1", split="train")[1]
    speech = read_audio(s.video, rate_hz=RATE)[0].astype(np.float64)
    x = np.concatenate([_noise("white", 0.5, -54.0), speech])
    got = assert_chunk_invariant(lambda: _GateLevels(shipped, kernel), x, atol=1e-10, max_examples=6)
    want = _frame_levels_db(x, shipped.frontend.mfcc)
    assert got.shape == want.shape == (shipped.frontend.mfcc.n_frames_for(x.size),)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert want.max() - want[:10].mean() > 20  # the sentence stands well over the room noise
